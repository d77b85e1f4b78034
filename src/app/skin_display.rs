//! The skin as it is drawn: the smooth display surface through the simulated points
//! ([`crate::render::subdivide`]), kept outside the muscles under it.
//!
//! The simulation keeps only its grid points outside the muscles (their fat points `r − τ n̂`,
//! LEMAN eq. 6 and 13a). Between the points the drawn surface is interpolated, and where a
//! muscle bulges between grid points (the 32×32 torso's deltoids in a bent posture) the
//! interpolated surface passes through it and the muscle shows through the skin. So every
//! display point whose fat point lies inside a shape is moved out the way the simulation moves
//! its points: the fat point goes to the shape's surface (the simulation's batched sign and
//! gradient kernels, Newton steps along the gradient) and the skin point sits `τ` outside it
//! along the display surface's normal. This is for display only: the simulated state, the
//! forces and picking are untouched.
//!
//! Fat is given on the character's skin grid; the display grid takes it by the bilinear
//! interpolation the simulation uses when it resamples a skin
//! ([`crate::character::resample::resample_field`], LEMAN 6.5), so it follows the model at any
//! resolution.

use crate::character::{ShapeInstance, within_bounds};
use crate::sim::surface::forces;
use crate::sim::surface::kernels::Batch;
use glam::Vec3;

/// Gauss-Seidel rounds over the shapes: a point pushed out of one muscle into an overlapping
/// one is caught in the next round.
const ROUNDS: usize = 2;
/// Newton steps of the display projection.
const NEWTON_STEPS: usize = 2;

/// Unit outward normals of an `around × along` grid of points by the simulation's own
/// definition ([`forces::grid_normals`]: central differences, periodic around, one-sided at the
/// end rows, `∂r/∂u₂ × ∂r/∂u₁`; +Y where degenerate).
fn grid_normals(points: &[Vec3], around: usize, along: usize) -> Vec<Vec3> {
    let grid = [0, 1, 2].map(|c| points.iter().map(|p| p[c]).collect::<Vec<f32>>());
    let mut normals: [Vec<f32>; 3] = Default::default();
    forces::grid_normals(around, along, &grid, &mut normals);
    let [nx, ny, nz] = &normals;
    nx.iter()
        .zip(ny)
        .zip(nz)
        .map(|((x, y), z)| Vec3::new(*x, *y, *z))
        .collect()
}

/// Moves the display points of an `around × along` grid (periodic around) whose fat points
/// `p − τ n̂` lie inside any of `shapes` so that their fat points lie on the surface, `τ` being
/// `fat_m` per point (metres) and `n̂` the grid's own normal. The first and last rows (fixed to
/// the skeleton) stay. Returns how many points moved. Points, fat or shapes that give
/// non-finite numbers leave the point where it was, so nothing non-finite is produced.
///
/// Shape by shape (in order, `ROUNDS` times over while anything moves): the fat points in the
/// shape's bounding sphere and extent box are tested with the simulation's batched sign kernel
/// and the inside ones projected by `NEWTON_STEPS` batched Newton steps along the gradient
/// (display accuracy: a step's error is about the square of the previous one over twice the
/// curvature radius, so from 1 cm deep in a muscle of 3 cm radius two steps land within a
/// tenth of a millimetre).
pub fn keep_outside(
    points: &mut [Vec3],
    around: usize,
    along: usize,
    fat_m: &[f32],
    shapes: &[ShapeInstance],
) -> usize {
    if around < 3 || along < 3 || points.len() != around * along || fat_m.len() != points.len() {
        return 0;
    }
    let normals = grid_normals(points, around, along);
    // The interior rows' fat points (the end rows are fixed) and their offsets.
    let interior = around..around * (along - 1);
    let mut offset = Vec::with_capacity(interior.len());
    let mut q = Vec::with_capacity(interior.len());
    for k in interior.clone() {
        let (n, fat) = (normals[k], fat_m[k].max(0.0));
        let o = n * fat;
        let fat_point = points[k] - o;
        let usable = fat.is_finite() && fat_point.is_finite();
        offset.push(if usable { o } else { Vec3::NAN });
        q.push(fat_point);
    }
    let mut moved = vec![false; q.len()];
    // Which points a round tests: all usable ones first, then those the last round moved.
    let mut testing: Vec<bool> = offset.iter().map(|o| o.is_finite()).collect();
    let (mut test, mut inside) = (Batch::default(), Batch::default());
    for _ in 0..ROUNDS {
        // Each display row's box, so a shape skips the rows it cannot reach.
        let rows: Vec<(Vec3, Vec3)> = q
            .chunks_exact(around)
            .zip(testing.chunks_exact(around))
            .map(|(row, on)| {
                row.iter()
                    .zip(on)
                    .filter(|(_, on)| **on)
                    .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), (p, _)| {
                        (lo.min(*p), hi.max(*p))
                    })
            })
            .collect();
        let mut moved_now = vec![false; q.len()];
        let mut any = false;
        for s in shapes {
            let (center, r, extent) = (
                s.bound_center_world_m,
                s.bound_radius_m,
                s.geometry.extent_m(),
            );
            // The bounding ellipsoid cuts off the box's corners.
            let w = s.geometry.bounding_ellipsoid_weights();
            test.clear();
            for (j, (lo, hi)) in rows.iter().enumerate() {
                if (center - center.clamp(*lo, *hi)).length_squared() >= r * r {
                    continue;
                }
                for k in j * around..(j + 1) * around {
                    let p = q[k];
                    if !testing[k] || (p - center).length_squared() >= r * r {
                        continue;
                    }
                    let local = s.shape_from_world.transform_point3(p);
                    if within_bounds(local, extent, w) {
                        test.push(k as u32, local);
                    }
                }
            }
            if test.is_empty() {
                continue;
            }
            test.evaluate(&s.geometry, false);
            inside.assign_inside_of(&test, 0.0);
            if inside.is_empty() {
                continue;
            }
            for _ in 0..NEWTON_STEPS {
                inside.evaluate(&s.geometry, true);
                inside.newton_step();
            }
            for i in 0..inside.len() {
                let world = s.world_from_shape.transform_point3(inside.position(i));
                let k = inside.point[i] as usize;
                if world.is_finite() && world != q[k] {
                    q[k] = world;
                    moved[k] = true;
                    moved_now[k] = true;
                    any = true;
                }
            }
        }
        if !any {
            break;
        }
        testing = moved_now;
    }
    let mut count = 0;
    for (k, ((fat_point, o), m)) in q.iter().zip(&offset).zip(&moved).enumerate() {
        if *m {
            points[around + k] = *fat_point + *o;
            count += 1;
        }
    }
    count
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::character::{Primitive, ShapeGeometry};
    use crate::pose::Pose;

    /// A sphere muscle of radius `r` at `center`.
    fn sphere(center: Vec3, r: f32) -> ShapeInstance {
        let geometry = ShapeGeometry::new(Primitive::Sphere { radius_m: r }, &[]);
        ShapeInstance::new(geometry, Pose::from_translation(center))
    }

    /// `around × along` points on circles of radius `radius` about the Y axis, rows `dy` apart
    /// centred on y = 0, in the skin's order: rows up +Y, and increasing `i` turning from +X
    /// toward +Z, so that `r_u2 × r_u1` points outward.
    fn ring_grid(around: usize, along: usize, radius: impl Fn(f32) -> f32, dy: f32) -> Vec<Vec3> {
        let mut p = Vec::new();
        for j in 0..along {
            let y = (j as f32 - (along - 1) as f32 / 2.0) * dy;
            for i in 0..around {
                let a = std::f32::consts::TAU * i as f32 / around as f32;
                let r = radius(y);
                p.push(Vec3::new(r * a.cos(), y, r * a.sin()));
            }
        }
        p
    }

    #[test]
    fn normals_point_away_from_the_axis_for_the_skin_order() {
        let p = ring_grid(16, 6, |_| 0.1, 0.02);
        let n = grid_normals(&p, 16, 6);
        for (k, (p, n)) in p.iter().zip(&n).enumerate() {
            let radial = Vec3::new(p.x, 0.0, p.z).normalize();
            assert!(
                n.dot(radial) > 0.99,
                "point {k}: normal {n} radial {radial}"
            );
        }
    }

    #[test]
    fn chords_through_a_sphere_are_pushed_out_to_the_fat_offset() {
        // A coarse skin lying on a sphere of radius 0.1 with 5 mm of fat: its grid points sit
        // exactly on the fat offset (0.105 from the centre), so the display points between
        // them, on flat-ish patches, cut into the fat and the sphere.
        let (r, fat) = (0.1f32, 0.005f32);
        let (m, n) = (8usize, 9usize);
        let mut p = Vec::new();
        for j in 0..n {
            // Polar angle from +Y, falling with j so the rows go up as in the skin's order.
            let theta = 2.8 - 2.5 * j as f32 / (n - 1) as f32;
            for i in 0..m {
                let a = std::f32::consts::TAU * i as f32 / m as f32;
                let d = Vec3::new(theta.sin() * a.cos(), theta.cos(), theta.sin() * a.sin());
                p.push(d * (r + fat));
            }
        }
        // Display refinement between the points: linear here, the worst case for chords.
        let level = 4;
        let (rm, rn) = (m * level, (n - 1) * level + 1);
        let mut refined = Vec::with_capacity(rm * rn);
        for j in 0..rn {
            for i in 0..rm {
                let (u, v) = (i as f32 / level as f32, j as f32 / level as f32);
                let (i0, j0) = (u.floor() as usize % m, (v.floor() as usize).min(n - 2));
                let (tu, tv) = (u - u.floor(), v - j0 as f32);
                let at = |ii: usize, jj: usize| p[jj * m + ii % m];
                let a = at(i0, j0).lerp(at(i0 + 1, j0), tu);
                let b = at(i0, j0 + 1).lerp(at(i0 + 1, j0 + 1), tu);
                refined.push(a.lerp(b, tv));
            }
        }
        let shapes = [sphere(Vec3::ZERO, r)];
        let fat_m = vec![fat; rm * rn];
        let deepest = |pts: &[Vec3]| {
            let normals = grid_normals(pts, rm, rn);
            (rm..rm * (rn - 1))
                .map(|k| r - (pts[k] - normals[k] * fat).length())
                .fold(f32::MIN, f32::max)
        };
        let before = deepest(&refined);
        assert!(
            before > 0.005,
            "the chords must cut into the sphere: {before}"
        );
        let moved = keep_outside(&mut refined, rm, rn, &fat_m, &shapes);
        assert!(moved > rm * (rn - 2) / 2, "moved {moved}");
        // Pushing one point turns its neighbours' normals, so the fat points are re-measured
        // with the new normals: what is left is a small fraction of the chord depth.
        let after = deepest(&refined);
        assert!(after < 0.15 * before, "still {after} m deep (was {before})");
        // Every moved point's skin point ends outside the sphere by about the fat.
        for (k, q) in refined.iter().enumerate() {
            assert!(q.is_finite(), "point {k}");
            assert!(q.length() > r + 0.5 * fat, "point {k} at {}", q.length());
        }
    }

    #[test]
    fn points_clear_of_every_shape_and_the_end_rows_stay() {
        let mut p = ring_grid(12, 7, |_| 0.2, 0.03);
        let before = p.clone();
        // A sphere far from the skin and one that swallows the first row only.
        let shapes = [
            sphere(Vec3::new(2.0, 0.0, 0.0), 0.3),
            sphere(Vec3::new(0.0, -0.09, 0.0), 0.25),
        ];
        let fat = vec![0.01; p.len()];
        keep_outside(&mut p, 12, 7, &fat, &shapes[..1]);
        assert_eq!(p, before);
        keep_outside(&mut p, 12, 7, &fat, &shapes);
        assert_eq!(p[..12], before[..12], "the fixed first row moved");
        assert_eq!(p[72..], before[72..], "the fixed last row moved");
        assert_ne!(
            p[12..24],
            before[12..24],
            "the second row is inside and must move"
        );
    }

    #[test]
    fn non_finite_input_changes_nothing_and_makes_nothing_non_finite() {
        let mut p = ring_grid(8, 5, |_| 0.1, 0.02);
        p[17] = Vec3::new(f32::NAN, 0.0, 0.0);
        let mut fat = vec![0.01; p.len()];
        fat[20] = f32::INFINITY;
        let shapes = [sphere(Vec3::ZERO, 0.105)];
        keep_outside(&mut p, 8, 5, &fat, &shapes);
        for (k, q) in p.iter().enumerate() {
            // Only the NaN point itself stays non-finite.
            if k != 17 {
                assert!(q.is_finite(), "point {k}: {q}");
            }
        }
        assert!(p[17].x.is_nan());
        // Wrong sizes change nothing.
        let mut q = ring_grid(8, 5, |_| 0.1, 0.02);
        let before = q.clone();
        assert_eq!(keep_outside(&mut q, 8, 5, &fat[..3], &shapes), 0);
        assert_eq!(q, before);
    }
}
