//! Non-penetration (LEMAN 4.1.4, 4.2.3): after an accepted integration step every free skin
//! point whose fat point `r − τ n̂` (eq. 6) is inside a muscle is moved out to the muscle's
//! surface (eq. 13a) and its velocity, relative to the muscle's own surface velocity, is split
//! into a normal part reversed and scaled by k∥ and a tangential part scaled by k⊥ (eq. 13b-d;
//! the normal part is only reversed when the point moves into the muscle).
//!
//! # Acceleration structure
//! Per-point candidate lists with temporal coherence: each free point keeps the shapes whose
//! bounding sphere, grown by the point's fat and a margin, contains it. The lists are rebuilt
//! only when the points' accumulated movement (bounded by `max |v|·h` per step) plus the
//! shapes' bounding-sphere movement since the last rebuild could exceed the margin, so a shape
//! can never reach a point that does not list it. Between rebuilds a point tests only its
//! candidates (first the exact bounding sphere, then the inside/outside function).

#![allow(clippy::needless_range_loop)] // index loops over parallel SoA arrays read best as they are

use glam::Vec3;

use crate::character::{PROJECTION_TOLERANCE_M, Primitive, ShapeGeometry, ShapeInstance};

/// Most candidates a point keeps; beyond that it tests every shape.
const MAX_CANDIDATES: usize = 16;
/// Marker for "test every shape".
const ALL_SHAPES: u8 = u8::MAX;

/// Candidate lists and their validity bookkeeping.
#[derive(Debug, Clone, Default)]
pub struct Broadphase {
    cand: Vec<u8>,
    count: Vec<u8>,
    ref_centers: Vec<Vec3>,
    ref_radii: Vec<f32>,
    moved_m: f32,
    valid: bool,
    /// Per candidate slot: `F` of the last exact evaluation (NaN: none) and where (shape space).
    clear_value: Vec<f32>,
    clear_at: Vec<Vec3>,
    /// Per shape: the primitive when the slots were filled.
    ref_primitives: Vec<Primitive>,
    /// Per shape this pass: Lipschitz bound of `F` in shape space, 1/m (0: no caching).
    lipschitz_per_m: Vec<f32>,
    /// Margin, metres: larger means fewer rebuilds and more candidates.
    pub margin_m: f32,
    /// Rebuilds so far (for tests and reports).
    pub rebuilds: u64,
}

impl Broadphase {
    /// Forces a rebuild at the next pass (after a restore, a resolution or fat change).
    pub fn invalidate(&mut self) {
        self.valid = false;
    }
}

/// What a constraint pass found.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ConstraintOutcome {
    /// Largest position component correction, metres (compared with ε_c).
    pub max_component_m: f32,
    /// Largest correction length, metres.
    pub max_correction_m: f32,
    /// Points moved.
    pub corrected: u32,
    /// Free point with the largest correction, and the last shape that moved it.
    pub worst: (u32, u32),
}

/// Inputs of a constraint pass.
pub struct ConstraintInput<'a> {
    /// M.
    pub around: usize,
    /// N.
    pub along: usize,
    /// Shapes at the end of the step.
    pub shapes_end: &'a [ShapeInstance],
    /// Shapes at the start of the step (for the muscles' surface velocity).
    pub shapes_start: &'a [ShapeInstance],
    /// Step length, seconds.
    pub h_s: f32,
    /// Fat per free point, m.
    pub fat_m: &'a [f32],
    /// Largest fat, m.
    pub max_fat_m: f32,
    /// k∥.
    pub k_parallel: f32,
    /// k⊥.
    pub k_perpendicular: f32,
    /// Largest speed of any point in the candidate state (bounds its movement this step).
    pub max_speed_m_per_s: f32,
    /// Corrections longer than this mark a point's neighbourhood for a re-check, metres.
    pub recheck_m: f32,
}

impl Broadphase {
    fn update(&mut self, input: &ConstraintInput<'_>, grid: &[Vec<f32>; 3]) {
        let shapes = input.shapes_end;
        let m = input.around;
        let free = m * (input.along - 2);
        self.moved_m += input.max_speed_m_per_s * input.h_s;
        let mut shape_moved = 0.0f32;
        if self.ref_centers.len() == shapes.len() {
            for (k, s) in shapes.iter().enumerate() {
                let d = (s.bound_center_world_m - self.ref_centers[k]).length()
                    + (s.bound_radius_m - self.ref_radii[k]).max(0.0);
                shape_moved = shape_moved.max(d);
            }
        } else {
            self.valid = false;
        }
        if self.valid && self.moved_m + shape_moved <= self.margin_m && self.count.len() == free {
            self.update_lipschitz(shapes);
            return;
        }
        self.rebuilds += 1;
        self.valid = true;
        self.moved_m = 0.0;
        self.ref_centers.clear();
        self.ref_radii.clear();
        self.ref_centers
            .extend(shapes.iter().map(|s| s.bound_center_world_m));
        self.ref_radii
            .extend(shapes.iter().map(|s| s.bound_radius_m));
        self.cand.resize(free * MAX_CANDIDATES, 0);
        self.clear_value.clear();
        self.clear_value.resize(free * MAX_CANDIDATES, f32::NAN);
        self.clear_at.clear();
        self.clear_at.resize(free * MAX_CANDIDATES, Vec3::ZERO);
        self.ref_primitives.clear();
        self.ref_primitives
            .extend(shapes.iter().map(|s| s.geometry.primitive));
        self.update_lipschitz(shapes);
        self.count.resize(free, 0);
        let grow = input.max_fat_m + self.margin_m;
        let too_many = shapes.len() >= usize::from(ALL_SHAPES);
        for f in 0..free {
            let k = m + f;
            let p = Vec3::new(grid[0][k], grid[1][k], grid[2][k]);
            let mut c = 0usize;
            let mut overflow = too_many;
            for (s_idx, s) in shapes.iter().enumerate() {
                let r = s.bound_radius_m + grow;
                if (p - s.bound_center_world_m).length_squared() <= r * r {
                    if c < MAX_CANDIDATES {
                        self.cand[f * MAX_CANDIDATES + c] = s_idx as u8;
                        c += 1;
                    } else {
                        overflow = true;
                    }
                }
            }
            self.count[f] = if overflow { ALL_SHAPES } else { c as u8 };
        }
    }

    /// Per shape: the Lipschitz bound that lets a cached exact value stand in for a new
    /// evaluation, or 0 when the shape does not qualify (see [`superellipsoid_lipschitz_per_m`])
    /// or its primitive changed since the cache was filled.
    fn update_lipschitz(&mut self, shapes: &[ShapeInstance]) {
        self.lipschitz_per_m.clear();
        self.lipschitz_per_m
            .extend(shapes.iter().enumerate().map(|(k, s)| {
                if self.ref_primitives.get(k) == Some(&s.geometry.primitive) {
                    superellipsoid_lipschitz_per_m(&s.geometry)
                } else {
                    0.0
                }
            }));
    }
}

/// Safety margin on `F` for using a cached value (far above `f32` evaluation error).
const CACHE_MARGIN: f32 = 1e-4;

/// For a superellipsoid with `e1, e2 ≤ 2`: a bound `L` with `|F(p) − F(p')| ≤ L |p − p'|`
/// in rest space (before its deformations), 1/m; 0 for anything else.
///
/// Why: `G = F + 1` is then the nested norm `‖(‖(x, z)‖_{2/e2}, y)‖_{2/e1}` of `p / radii`
/// (both exponents ≥ 1, so a convex gauge) and is at most the 1-norm, which is at most
/// `√3` times the Euclidean norm. A norm is Lipschitz with its bound: `|G(u) − G(u')| ≤
/// √3 |u − u'|`, and `|u − u'| ≤ |p − p'| / min(radii)`. So a point whose `F` was `F₀` at
/// `p₀` is still outside while `F₀ − L |p − p₀| > 0`: the constraint pass skips the
/// exact evaluation (the `pow` calls) for such points.
pub fn superellipsoid_lipschitz_per_m(geometry: &ShapeGeometry) -> f32 {
    match geometry.primitive {
        Primitive::Superellipsoid { radii_m, e1, e2 }
            if e1 > 0.0 && e2 > 0.0 && e1 <= 2.0 && e2 <= 2.0 && radii_m.min_element() > 0.0 =>
        {
            3.0f32.sqrt() / radii_m.min_element()
        }
        _ => 0.0,
    }
}

/// Applies the constraints to a candidate state in place. `grid` must hold the full grid of the
/// candidate positions and `normals` its normals. The free points of `x`, `v` and the grid are
/// updated together. `only` restricts the pass to those free points (a re-check); the points
/// moved are written to `touched`.
#[allow(clippy::too_many_arguments)]
pub fn enforce(
    input: &ConstraintInput<'_>,
    broad: &mut Broadphase,
    grid: &mut [Vec<f32>; 3],
    normals: &[Vec<f32>; 3],
    x: &mut [f32],
    v: &mut [f32],
    only: Option<&[u32]>,
    touched: &mut Vec<u32>,
) -> ConstraintOutcome {
    if only.is_none() {
        broad.update(input, grid);
    }
    let m = input.around;
    let free = m * (input.along - 2);
    let shapes = input.shapes_end;
    let mut out = ConstraintOutcome::default();
    let inv_h = if input.h_s > 0.0 {
        1.0 / input.h_s
    } else {
        0.0
    };
    touched.clear();
    let n_points = only.map_or(free, |o| o.len());
    for idx in 0..n_points {
        let f = match only {
            Some(list) => list[idx] as usize,
            None => idx,
        };
        if f >= free {
            continue;
        }
        let count = broad.count[f];
        if count == 0 {
            continue;
        }
        let k = m + f;
        let p0 = Vec3::new(grid[0][k], grid[1][k], grid[2][k]);
        let n = Vec3::new(normals[0][k], normals[1][k], normals[2][k]);
        let fat = input.fat_m[f];
        let mut q = p0 - n * fat;
        let mut moved = false;
        let mut last_normal = Vec3::ZERO;
        let mut last_shape = usize::MAX;
        // Up to four rounds so a point pushed out of one muscle into an overlapping one is
        // fixed too. A later round stops once it passes the previous round's last change
        // without a change of its own: the remaining shapes would see the same fat point as
        // in the previous round, which found nothing there (same result, fewer tests).
        let mut previous_last_change = usize::MAX;
        for _round in 0..4 {
            let mut changed = false;
            let mut last_change = 0usize;
            let list: &[u8] = if count == ALL_SHAPES {
                &[]
            } else {
                &broad.cand[f * MAX_CANDIDATES..f * MAX_CANDIDATES + usize::from(count)]
            };
            let n_tests = if count == ALL_SHAPES {
                shapes.len()
            } else {
                list.len()
            };
            for t in 0..n_tests {
                if !changed && t > previous_last_change {
                    break;
                }
                let s_idx = if count == ALL_SHAPES {
                    t
                } else {
                    usize::from(list[t])
                };
                let s = &shapes[s_idx];
                let r = s.bound_radius_m;
                if (q - s.bound_center_world_m).length_squared() > r * r {
                    continue;
                }
                let local = s.to_shape(q);
                if outside_box(&s.geometry, local) {
                    continue;
                }
                // Cached exact value at a nearby point, with the Lipschitz bound: still
                // outside, so the evaluation below would find `F ≥ 0` too.
                // (In rest space, where the bound holds, so also for deformed shapes.)
                let lipschitz = broad.lipschitz_per_m.get(s_idx).copied().unwrap_or(0.0);
                let slot = f * MAX_CANDIDATES + t;
                let cacheable = count != ALL_SHAPES && lipschitz > 0.0;
                let rest = if cacheable {
                    super::fastshape::superellipsoid_rest(&s.geometry, local)
                } else {
                    None
                };
                let (value, grad) = if let Some((p_rest, jac)) = rest {
                    let f0 = broad.clear_value[slot];
                    if f0 > 0.0
                        && f0 - lipschitz * (p_rest - broad.clear_at[slot]).length() > CACHE_MARGIN
                    {
                        continue;
                    }
                    let (value, grad) = super::fastshape::superellipsoid_value_and_gradient(
                        &s.geometry,
                        p_rest,
                        jac,
                    );
                    broad.clear_value[slot] = value;
                    broad.clear_at[slot] = p_rest;
                    (value, grad)
                } else {
                    super::fastshape::value_and_gradient(&s.geometry, local)
                };
                if value >= 0.0 {
                    continue;
                }
                let on_surface = project_near(&s.geometry, local, value, grad);
                let d = s.world_from_shape.transform_vector3(on_surface - local);
                if !d.is_finite() {
                    continue;
                }
                q += d;
                let len = d.length();
                last_normal = if len > 1e-9 {
                    d / len
                } else {
                    s.world_from_shape
                        .transform_vector3(s.geometry.gradient(on_surface))
                        .normalize_or_zero()
                };
                last_shape = s_idx;
                moved = true;
                changed = true;
                last_change = t;
            }
            if !changed {
                break;
            }
            previous_last_change = last_change;
        }
        if !moved {
            continue;
        }
        let p1 = q + n * fat;
        let d = p1 - p0;
        out.max_component_m = out
            .max_component_m
            .max(d.x.abs())
            .max(d.y.abs())
            .max(d.z.abs());
        if d.length() > out.max_correction_m {
            out.max_correction_m = d.length();
            out.worst = (f as u32, last_shape as u32);
        }
        out.corrected += 1;
        if d.length() > input.recheck_m {
            touched.push(f as u32);
        }
        x[f] = p1.x;
        x[free + f] = p1.y;
        x[2 * free + f] = p1.z;
        grid[0][k] = p1.x;
        grid[1][k] = p1.y;
        grid[2][k] = p1.z;
        // Velocity relative to the muscle surface (its material point's displacement over the
        // step), eq. 13b-d.
        let vel = Vec3::new(v[f], v[free + f], v[2 * free + f]);
        let surface_vel = match input.shapes_start.get(last_shape) {
            Some(start) if input.shapes_start.len() == shapes.len() => {
                let s = &shapes[last_shape];
                let was = s.world_from_shape.transform_point3(start.to_shape(q));
                (q - was) * inv_h
            }
            _ => Vec3::ZERO,
        };
        let rel = vel - surface_vel;
        let vn = rel.dot(last_normal);
        let normal_part = last_normal * vn;
        let tangential = rel - normal_part;
        let new_normal = if vn < 0.0 {
            -input.k_parallel * normal_part
        } else {
            normal_part
        };
        let new_vel = surface_vel + new_normal + input.k_perpendicular * tangential;
        v[f] = new_vel.x;
        v[free + f] = new_vel.y;
        v[2 * free + f] = new_vel.z;
    }
    out
}

/// Cheap exact rejection before the inside/outside function: an undeformed superellipsoid or
/// cylinder lies inside its axis-aligned box in the shape frame.
#[inline]
fn outside_box(geometry: &ShapeGeometry, p: Vec3) -> bool {
    if !geometry.is_undeformed() {
        return false;
    }
    match geometry.primitive {
        Primitive::Superellipsoid { radii_m, .. } => {
            p.x.abs() > radii_m.x || p.y.abs() > radii_m.y || p.z.abs() > radii_m.z
        }
        Primitive::Cylinder {
            radius_m,
            half_length_m,
        } => p.x.abs() > radius_m || p.z.abs() > radius_m || p.y.abs() > half_length_m,
        Primitive::Sphere { .. } => false,
    }
}

/// Projection of a point just inside a shape: up to two Newton steps along the gradient
/// (`q − F ∇F/|∇F|²`, error O(depth²·curvature), far below the shapes' own projection
/// tolerance for the millimetre depths of one step), falling back to the shape's full
/// projection when that does not land on the surface within [`PROJECTION_TOLERANCE_M`].
fn project_near(geometry: &ShapeGeometry, p: Vec3, value: f32, grad: Vec3) -> Vec3 {
    let (mut q, mut v, mut g) = (p, value, grad);
    for _ in 0..2 {
        let len2 = g.length_squared();
        if len2.is_nan() || len2 <= 1e-12 || !v.is_finite() {
            break;
        }
        q -= g * (v / len2);
        let (nv, ng) = super::fastshape::value_and_gradient(geometry, q);
        let glen = ng.length();
        if glen > 0.0 && (nv / glen).abs() <= PROJECTION_TOLERANCE_M {
            return q;
        }
        v = nv;
        g = ng;
    }
    geometry.project(p)
}

/// Deepest penetration of any free point's fat point into any shape, metres (brute force over
/// every point and shape: for tests and checks, not the hot path).
pub fn max_depth_m(
    around: usize,
    along: usize,
    grid: &[Vec<f32>; 3],
    normals: &[Vec<f32>; 3],
    fat_m: &[f32],
    shapes: &[ShapeInstance],
) -> f32 {
    let m = around;
    let free = m * (along - 2);
    let mut worst = 0.0f32;
    for f in 0..free {
        let k = m + f;
        let p = Vec3::new(grid[0][k], grid[1][k], grid[2][k]);
        let n = Vec3::new(normals[0][k], normals[1][k], normals[2][k]);
        let q = p - n * fat_m[f];
        for s in shapes {
            let local = s.to_shape(q);
            if s.geometry.value(local) < 0.0 {
                let depth = (s.geometry.project(local) - local).length();
                worst = worst.max(depth);
            }
        }
    }
    worst
}

/// The free points within one grid step (around or along, periodic around) of `points`, each
/// once, into `out` (`flags` is scratch of one byte per free point).
pub fn neighbourhood(
    around: usize,
    free: usize,
    points: &[u32],
    flags: &mut Vec<u8>,
    out: &mut Vec<u32>,
) {
    flags.clear();
    flags.resize(free, 0);
    out.clear();
    let m = around;
    for &p in points {
        let f = p as usize;
        let (i, row) = (f % m, f / m);
        let left = row * m + (i + m - 1) % m;
        let right = row * m + (i + 1) % m;
        let mut add = |g: usize| {
            if g < free && flags[g] == 0 {
                flags[g] = 1;
                out.push(g as u32);
            }
        };
        add(f);
        add(left);
        add(right);
        if f >= m {
            add(f - m);
        }
        add(f + m);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_lipschitz_bound_holds_for_convex_superellipsoids() {
        let shapes = [
            (Vec3::new(0.08, 0.15, 0.1), 0.6, 1.4),
            (Vec3::new(0.1, 0.2, 0.12), 1.0, 1.0),
            (Vec3::new(0.05, 0.3, 0.05), 0.3, 0.8),
            (Vec3::new(0.12, 0.1, 0.09), 1.8, 0.4),
            (Vec3::new(0.07, 0.12, 0.06), 2.0, 2.0),
            (Vec3::new(0.07, 0.12, 0.06), 0.1, 0.1),
        ];
        let mut state: u32 = 5;
        let mut next = || {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (state >> 8) as f32 / (1u32 << 24) as f32 * 2.0 - 1.0
        };
        for (radii_m, e1, e2) in shapes {
            let g = ShapeGeometry::new(Primitive::Superellipsoid { radii_m, e1, e2 }, &[]);
            let lipschitz = superellipsoid_lipschitz_per_m(&g);
            assert!(lipschitz > 0.0);
            let mut largest_ratio = 0.0f32;
            for i in 0..20_000 {
                let p = Vec3::new(next(), next(), next()) * 0.3;
                let scale = if i % 2 == 0 { 0.01 } else { 0.2 };
                let q = p + Vec3::new(next(), next(), next()) * scale;
                let dist = (p - q).length();
                let change = (g.value(p) - g.value(q)).abs();
                assert!(
                    change <= lipschitz * dist * (1.0 + 1e-4) + 1e-5,
                    "{p} {q}: {change} > {lipschitz}·{dist}"
                );
                if dist > 1e-3 {
                    largest_ratio = largest_ratio.max(change / dist);
                }
            }
            // The bound is not vacuous: it is within a small factor of what is seen.
            assert!(
                largest_ratio >= 0.3 * lipschitz,
                "{largest_ratio} vs {lipschitz}"
            );
        }
        let pinched = ShapeGeometry::new(
            Primitive::Superellipsoid {
                radii_m: Vec3::splat(0.1),
                e1: 2.5,
                e2: 1.0,
            },
            &[],
        );
        assert_eq!(superellipsoid_lipschitz_per_m(&pinched), 0.0);
        let sphere = ShapeGeometry::new(Primitive::Sphere { radius_m: 0.1 }, &[]);
        assert_eq!(superellipsoid_lipschitz_per_m(&sphere), 0.0);
    }
}
