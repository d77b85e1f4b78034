//! The connective tissue layer: one-sided springs ("rubber bands") from skin points to anchors
//! fixed on muscle surfaces (paper eq. 3).

use glam::Vec3;

use super::shape::ShapeId;

/// A connective-tissue spring between a skin point and an anchor on a shape.
///
/// The anchor is stored in the shape's *rest* (undeformed) space, so it follows the skeleton and
/// stays on the surface as the muscle flexes: its world position is
/// [`super::shape::ShapeInstance::rest_point_to_world`]`(anchor_rest_m)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TissueSpring {
    /// Index of the skin point ([`super::skin::Skin::index`]).
    pub skin_point: u32,
    /// The shape carrying the anchor.
    pub shape: ShapeId,
    /// Anchor in the shape's rest space, metres.
    pub anchor_rest_m: Vec3,
    /// Spring constant k_s, N/m (≥ 0).
    pub stiffness_n_per_m: f32,
    /// Damping coefficient k_d, N·s/m (≥ 0).
    pub damping_n_s_per_m: f32,
    /// Rest length l⁰, metres (≥ 0): the spring is slack while shorter.
    pub rest_length_m: f32,
}

impl TissueSpring {
    /// Force on the skin point (eq. 3), newtons. `l_m` = skin point − anchor, `l_dot_m_per_s` =
    /// its rate of change (skin velocity − anchor velocity). Zero while `|l| ≤ l⁰`; beyond, the
    /// magnitude `k_s(|l| − l⁰) + k_d (l̇·l̂)` is clamped at zero so the spring only ever pulls
    /// the skin towards the anchor.
    #[inline]
    pub fn force(&self, l_m: Vec3, l_dot_m_per_s: Vec3) -> Vec3 {
        let len = l_m.length();
        if len <= self.rest_length_m || len <= 0.0 {
            return Vec3::ZERO;
        }
        let dir = l_m / len;
        let magnitude = self.stiffness_n_per_m * (len - self.rest_length_m)
            + self.damping_n_s_per_m * l_dot_m_per_s.dot(dir);
        -dir * magnitude.max(0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn springs_only_pull() {
        let s = TissueSpring {
            skin_point: 0,
            shape: ShapeId(0),
            anchor_rest_m: Vec3::ZERO,
            stiffness_n_per_m: 100.0,
            damping_n_s_per_m: 2.0,
            rest_length_m: 0.01,
        };
        // Slack: no force, whatever the velocity.
        assert_eq!(
            s.force(Vec3::new(0.005, 0.0, 0.0), Vec3::X * 10.0),
            Vec3::ZERO
        );
        // Stretched: pulls back towards the anchor with k_s·(|l|−l0).
        let f = s.force(Vec3::new(0.03, 0.0, 0.0), Vec3::ZERO);
        assert!((f - Vec3::new(-2.0, 0.0, 0.0)).length() < 1e-5);
        // Stretched but approaching fast: damping would push; clamped to zero.
        let f = s.force(Vec3::new(0.03, 0.0, 0.0), Vec3::new(-10.0, 0.0, 0.0));
        assert_eq!(f, Vec3::ZERO);
    }
}

/// Parameters of the global "attach" command (paper section 6.2).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AttachParams {
    /// k_s of every new spring, N/m.
    pub stiffness_n_per_m: f32,
    /// k_d of every new spring, N·s/m.
    pub damping_n_s_per_m: f32,
    /// Rest length = this × the distance from the skin point to its anchor at attach time
    /// (1 = slack until the skin moves further away than it is now).
    pub rest_length_scale: f32,
    /// How far along the inward normal to look for a muscle surface, metres; beyond that the
    /// nearest surface point is used.
    pub max_ray_m: f32,
}

/// Distance beyond a shape's bounding sphere at which a point is taken as surely outside the
/// shape (guards the sphere test against rounding), metres.
const BOUND_MARGIN_M: f32 = 0.001;

/// The stretch `[enter, leave]` of the line `origin + t·dir` (`dir` a unit vector) within
/// [`BOUND_MARGIN_M`] of the shape's bounding sphere; `None` when the line misses it.
fn bound_interval(
    inst: &super::shape::ShapeInstance,
    origin: Vec3,
    dir: Vec3,
) -> Option<(f32, f32)> {
    let to_c = inst.bound_center_world_m - origin;
    let along = to_c.dot(dir);
    let reach = inst.bound_radius_m + BOUND_MARGIN_M;
    let disc = along * along - (to_c.length_squared() - reach * reach);
    (disc >= 0.0).then(|| {
        let half = disc.sqrt();
        (along - half, along + half)
    })
}

/// [`anchor_for_point`] for many skin points (`(position, outward normal)` pairs, world
/// frame), with the same results in the same order, split over the machine's cores (each
/// point's search is independent; a 128×128 skin has about 15 000 points to search).
pub fn anchors_for_points(
    instances: &[super::shape::ShapeInstance],
    points: &[(Vec3, Vec3)],
    max_ray_m: f32,
) -> Vec<Option<(ShapeId, Vec3, f32)>> {
    /// Fewer points than this per thread are not worth a thread.
    const MIN_PER_THREAD: usize = 256;
    let threads = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .min(points.len() / MIN_PER_THREAD)
        .max(1);
    let search = |chunk: &[(Vec3, Vec3)]| -> Vec<Option<(ShapeId, Vec3, f32)>> {
        chunk
            .iter()
            .map(|&(p, n)| anchor_for_point(instances, p, n, max_ray_m))
            .collect()
    };
    if threads == 1 {
        return search(points);
    }
    let per_thread = points.len().div_ceil(threads);
    std::thread::scope(|scope| {
        let handles: Vec<_> = points
            .chunks(per_thread)
            .map(|chunk| (chunk, scope.spawn(move || search(chunk))))
            .collect();
        handles
            .into_iter()
            // A thread that could not finish (it cannot panic short of running out of memory)
            // has its points searched again here.
            .flat_map(|(chunk, handle)| handle.join().unwrap_or_else(|_| search(chunk)))
            .collect()
    })
}

/// Finds the anchor for one skin point: the first muscle surface hit along the inward normal
/// (`-normal`) within `max_ray_m`, else the nearest surface point of any shape. Returns the
/// shape, the anchor in that shape's rest space and the distance (metres). `None` only when
/// there are no shapes.
pub fn anchor_for_point(
    instances: &[super::shape::ShapeInstance],
    point_world: Vec3,
    outward_normal: Vec3,
    max_ray_m: f32,
) -> Option<(ShapeId, Vec3, f32)> {
    const STEP_M: f32 = 0.002;
    let dir = -outward_normal.normalize_or_zero();
    if dir != Vec3::ZERO && max_ray_m > 0.0 {
        let steps = (max_ray_m / STEP_M).ceil() as u32;
        let mut best: Option<(usize, f32)> = None;
        for (k, inst) in instances.iter().enumerate() {
            // Samples further than BOUND_MARGIN_M outside the shape's bounding sphere are
            // outside the shape: a ray segment that misses the grown sphere cannot hit it, and
            // the march starts at the last sample before the sphere and stops after it (the
            // same samples and brackets as marching the whole ray, without the evaluations).
            let Some((enter, leave)) = bound_interval(inst, point_world, dir)
                .filter(|&(enter, leave)| leave >= 0.0 && enter <= max_ray_m)
            else {
                continue;
            };
            if inst.value_world(point_world) < 0.0 {
                continue; // starts inside this shape: not a surface below the skin
            }
            // First t with F < 0 along the ray, refined by bisection.
            let first = if enter > 0.0 {
                ((enter / STEP_M).floor() as u32).max(1)
            } else {
                1
            };
            let mut prev_t = if first > 1 {
                ((first - 1) as f32 * STEP_M).min(max_ray_m)
            } else {
                0.0
            };
            for s in first..=steps {
                let t = (s as f32 * STEP_M).min(max_ray_m);
                if best.is_some_and(|(_, bt)| t > bt) || t > leave {
                    break;
                }
                if inst.value_world(point_world + dir * t) < 0.0 {
                    let (mut lo, mut hi) = (prev_t, t);
                    for _ in 0..30 {
                        let mid = 0.5 * (lo + hi);
                        if mid <= lo || mid >= hi {
                            break; // adjacent floats: the remaining halvings change nothing
                        }
                        if inst.value_world(point_world + dir * mid) < 0.0 {
                            hi = mid;
                        } else {
                            lo = mid;
                        }
                    }
                    let hit_t = 0.5 * (lo + hi);
                    if best.is_none_or(|(_, bt)| hit_t < bt) {
                        best = Some((k, hit_t));
                    }
                    break;
                }
                prev_t = t;
            }
        }
        if let Some((k, t)) = best {
            let inst = &instances[k];
            // Put the anchor exactly on the surface.
            let on_surface = inst.project_world(point_world + dir * t);
            let rest = inst.geometry.undeform(inst.to_shape(on_surface));
            return Some((ShapeId(k as u32), rest, (on_surface - point_world).length()));
        }
    }
    let mut best: Option<(usize, Vec3, f32)> = None;
    for (k, inst) in instances.iter().enumerate() {
        let q = inst.project_world(point_world);
        let d = (q - point_world).length();
        if best.is_none_or(|(_, _, bd)| d < bd) {
            best = Some((k, q, d));
        }
    }
    best.map(|(k, q, d)| {
        let inst = &instances[k];
        (
            ShapeId(k as u32),
            inst.geometry.undeform(inst.to_shape(q)),
            d,
        )
    })
}

/// The global "attach" command: one spring per skin point (fixed rows included) from the
/// point's neutral-posture position to the muscle surface below it along its inward normal
/// (else the nearest muscle surface point), with the given parameters. Empty if the character
/// has no shapes.
pub fn attach_global(character: &super::Character, params: &AttachParams) -> Vec<TissueSpring> {
    let (instances, points) = character.neutral_layout();
    let mut springs = Vec::with_capacity(points.len());
    let found = anchors_for_points(&instances, &points, params.max_ray_m);
    for (k, found) in found.into_iter().enumerate() {
        if let Some((shape, anchor, distance)) = found {
            springs.push(TissueSpring {
                skin_point: k as u32,
                shape,
                anchor_rest_m: anchor,
                stiffness_n_per_m: params.stiffness_n_per_m,
                damping_n_s_per_m: params.damping_n_s_per_m,
                rest_length_m: distance * params.rest_length_scale,
            });
        }
    }
    springs
}

#[cfg(test)]
mod attach_tests {
    use super::*;
    use crate::character::PROJECTION_TOLERANCE_M;
    use crate::character::examples::build;

    #[test]
    fn attach_gives_one_spring_per_point_to_a_surface_point_below_it() {
        for name in ["penguin", "torso", "arm"] {
            let c = build(name, 16, 16).expect("example");
            let params = AttachParams {
                stiffness_n_per_m: 3.0,
                damping_n_s_per_m: 0.1,
                rest_length_scale: 1.0,
                max_ray_m: 0.3,
            };
            let springs = attach_global(&c, &params);
            assert_eq!(springs.len(), c.skin.point_count(), "{name}");
            let (instances, points) = c.neutral_layout();
            let mut below = 0;
            for (k, s) in springs.iter().enumerate() {
                assert_eq!(s.skin_point as usize, k);
                let inst = &instances[s.shape.index()];
                let anchor = inst.rest_point_to_world(s.anchor_rest_m);
                let d = inst
                    .geometry
                    .distance_estimate_m(inst.to_shape(anchor))
                    .abs();
                assert!(
                    d < 10.0 * PROJECTION_TOLERANCE_M,
                    "{name} {k}: anchor off surface by {d}"
                );
                let l = c.skin.positions_m[k] - anchor;
                assert!((l.length() - s.rest_length_m).abs() < 1e-4);
                if l.normalize_or_zero().dot(points[k].1) > 0.7 {
                    below += 1;
                }
            }
            // Most anchors lie along the inward normal (the paper's "attach").
            assert!(
                below * 10 >= springs.len() * 7,
                "{name}: only {below} along the normal"
            );
            assert_eq!(springs[0].stiffness_n_per_m, 3.0);
        }
    }

    #[test]
    fn many_points_at_once_give_the_one_by_one_anchors_in_order() {
        // 32×32 = 1024 points: enough for every core of a 4-core machine to take a share.
        let c = build("torso", 32, 32).expect("example");
        let (instances, points) = c.neutral_layout();
        let batch = anchors_for_points(&instances, &points, 0.3);
        assert_eq!(batch.len(), points.len());
        for (k, (&(p, n), got)) in points.iter().zip(&batch).enumerate() {
            assert_eq!(*got, anchor_for_point(&instances, p, n, 0.3), "point {k}");
        }
        assert!(anchors_for_points(&instances, &[], 0.3).is_empty());
    }
}
