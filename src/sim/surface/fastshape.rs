//! A faster inside/outside function for the constraint hot path (a local adapter over the
//! character model's shapes, which stay the reference): superellipsoids are evaluated in `f32`
//! (the model evaluates them in `f64` with `pow`, which profiling showed to take over half of
//! the simulation time on the torso). The formula is the model's own (`F = s·f^(e1/2) − 1`
//! on the point scaled into the unit box, see `character::shape`), so the zero set is the same;
//! the unit test below checks values and gradients against the model. Other primitives, and
//! the deformation chain, use the model's functions.

use glam::{Mat3, Vec3};

use crate::character::{Primitive, ShapeGeometry};

/// `F(p_shape)` and `∇F` (shape space, not normalised), as `ShapeGeometry::value_and_gradient`.
#[inline]
pub fn value_and_gradient(geometry: &ShapeGeometry, p_shape: Vec3) -> (f32, Vec3) {
    let Primitive::Superellipsoid { radii_m, e1, e2 } = geometry.primitive else {
        return geometry.value_and_gradient(p_shape);
    };
    if geometry.is_undeformed() {
        return superellipsoid(p_shape, radii_m, e1, e2);
    }
    let mut q = p_shape;
    let mut jac = Mat3::IDENTITY;
    for d in geometry.deformations().iter().rev() {
        let (p, j) = d.invert(q);
        jac = j * jac;
        q = p;
    }
    let (v, g_rest) = superellipsoid(q, radii_m, e1, e2);
    (v, jac.transpose() * g_rest)
}

/// A superellipsoid's rest-space point for `p_shape` and `∂p_rest/∂p_shape` (identity when
/// undeformed); `None` for other primitives.
#[inline]
pub fn superellipsoid_rest(geometry: &ShapeGeometry, p_shape: Vec3) -> Option<(Vec3, Mat3)> {
    let Primitive::Superellipsoid { .. } = geometry.primitive else {
        return None;
    };
    let mut q = p_shape;
    let mut jac = Mat3::IDENTITY;
    for d in geometry.deformations().iter().rev() {
        let (p, j) = d.invert(q);
        jac = j * jac;
        q = p;
    }
    Some((q, jac))
}

/// [`value_and_gradient`] from the parts [`superellipsoid_rest`] returned (same result).
#[inline]
pub fn superellipsoid_value_and_gradient(
    geometry: &ShapeGeometry,
    p_rest: Vec3,
    jac: Mat3,
) -> (f32, Vec3) {
    let Primitive::Superellipsoid { radii_m, e1, e2 } = geometry.primitive else {
        return (f32::NAN, Vec3::ZERO);
    };
    let (v, g_rest) = superellipsoid(p_rest, radii_m, e1, e2);
    if geometry.is_undeformed() {
        (v, g_rest)
    } else {
        (v, jac.transpose() * g_rest)
    }
}

#[inline]
fn pow0(v: f32, e: f32) -> f32 {
    if v > 0.0 { v.powf(e) } else { 0.0 }
}

#[inline]
fn superellipsoid(p: Vec3, radii: Vec3, e1: f32, e2: f32) -> (f32, Vec3) {
    let s = (p.x.abs() / radii.x)
        .max(p.y.abs() / radii.y)
        .max(p.z.abs() / radii.z);
    if s.is_nan() || s <= 0.0 || !s.is_finite() {
        return (-1.0, Vec3::Y);
    }
    let inv_s = 1.0 / s;
    let (qx, qy, qz) = (
        p.x.abs() / radii.x * inv_s,
        p.y.abs() / radii.y * inv_s,
        p.z.abs() / radii.z * inv_s,
    );
    if e1 == 1.0 && e2 == 1.0 {
        let f = qx * qx + qy * qy + qz * qz;
        let root = f.sqrt();
        let inv = 1.0 / root;
        let grad = Vec3::new(
            p.x.signum() * qx / radii.x * inv,
            p.y.signum() * qy / radii.y * inv,
            p.z.signum() * qz / radii.z * inv,
        );
        return (s * root - 1.0, grad);
    }
    // e2 = 1 (round cross-sections, common in the examples): the square needs no pow.
    let (px, pz) = if e2 == 1.0 {
        (qx * qx, qz * qz)
    } else {
        (pow0(qx, 2.0 / e2), pow0(qz, 2.0 / e2))
    };
    let py = pow0(qy, 2.0 / e1);
    let big_a = px + pz;
    let a_pow = pow0(big_a, e2 / e1);
    let f = a_pow + py;
    let f_pow = f.powf(0.5 * e1);
    let g = s * f_pow;
    let f_term = f_pow / f;
    let a_term = if big_a > 0.0 { a_pow / big_a } else { 0.0 };
    let dx = if qx > 0.0 { px / qx } else { 0.0 };
    let dz = if qz > 0.0 { pz / qz } else { 0.0 };
    let dy = if qy > 0.0 { py / qy } else { 0.0 };
    let sign = |v: f32| {
        if v > 0.0 {
            1.0
        } else if v < 0.0 {
            -1.0
        } else {
            0.0
        }
    };
    let grad = Vec3::new(
        f_term * a_term * dx * sign(p.x) / radii.x,
        f_term * dy * sign(p.y) / radii.y,
        f_term * a_term * dz * sign(p.z) / radii.z,
    );
    (g - 1.0, grad)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::character::Resolved;

    #[test]
    fn matches_the_character_models_superellipsoids() {
        let shapes = [
            (Vec3::new(0.08, 0.15, 0.1), 0.6, 1.4),
            (Vec3::new(0.1, 0.2, 0.12), 1.0, 1.0),
            (Vec3::new(0.05, 0.3, 0.05), 0.3, 0.8),
            (Vec3::new(0.12, 0.1, 0.09), 1.8, 0.4),
        ];
        let deformations = [
            vec![],
            vec![Resolved::Taper { rate_per_m: 1.5 }],
            vec![
                Resolved::Twist {
                    rate_rad_per_m: 3.0,
                },
                Resolved::Bend {
                    curvature_per_m: 2.0,
                },
            ],
        ];
        let mut state: u32 = 99;
        let mut next = || {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (state >> 8) as f32 / (1u32 << 24) as f32 * 2.0 - 1.0
        };
        for (radii_m, e1, e2) in shapes {
            for defs in &deformations {
                let g = ShapeGeometry::new(Primitive::Superellipsoid { radii_m, e1, e2 }, defs);
                for _ in 0..500 {
                    let p = Vec3::new(next(), next(), next()) * 0.3;
                    let (v_ref, g_ref) = g.value_and_gradient(p);
                    let (v, grad) = value_and_gradient(&g, p);
                    assert!(
                        (v - v_ref).abs() <= 1e-5 * v_ref.abs().max(1.0),
                        "{p}: {v} vs {v_ref}"
                    );
                    assert_eq!(v < 0.0, v_ref < 0.0, "{p}: inside/outside disagree");
                    assert!(
                        (grad - g_ref).length() <= 1e-3 * g_ref.length().max(1.0),
                        "{p}: {grad} vs {g_ref}"
                    );
                }
            }
        }
    }
}
