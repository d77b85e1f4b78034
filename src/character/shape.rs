//! The muscle/bone layer: implicit shapes attached to joints, with Barr's global deformations
//! (taper, twist, bend) whose parameters may be constant, keyed over time, or tied to a joint
//! angle (a flexing muscle).
//!
//! # Frames
//! A [`Shape`] hangs off a joint by `joint_from_shape`. Inside the shape frame there are two
//! spaces: the *rest* (undeformed) space where the [`Primitive`] is defined, and the *shape*
//! (deformed) space, reached by applying the shape's [`Deformation`]s in list order:
//! `p_shape = D_n(… D_1(p_rest))`. All deformations act about the shape's +Y axis (the
//! superellipsoid's polar axis, the cylinder's axis); bend curves +Y towards +X. Rotate
//! `joint_from_shape` to aim them elsewhere.
//!
//! # The inside/outside function
//! [`ShapeGeometry::value`] is `F(p_shape)`: negative inside, zero on the surface, positive
//! outside, continuous. For an undeformed sphere or cylinder it is the exact signed distance in
//! metres; for superellipsoids it is Barr's function written to be homogeneous of degree one,
//! `F = s·f(p/s)^(e1/2) − 1` (dimensionless; `F/|∇F|` estimates the distance in metres); a
//! deformed shape uses `F(D⁻¹(p))`. These are the simulation's hot path: every function here is
//! allocation-free and works on a [`ShapeGeometry`] that is `Copy` and resolved once per pose
//! (superellipsoid powers are computed in f64 internally so extreme exponents never overflow).
//!
//! # Projection
//! [`ShapeGeometry::project`] returns a point on the surface: closed form (nearest point) for
//! undeformed spheres and cylinders; otherwise Newton steps along the gradient (which converge
//! to the surface point near the gradient line through `p`, i.e. the nearest one for points near
//! the surface), with a fallback to the exact intersection of the ray from the centre in rest
//! space. The result is on the surface within [`PROJECTION_TOLERANCE_M`] (first-order distance
//! `|F|/|∇F|`).

use glam::{Affine3A, Mat3, Vec3};
use serde::{Deserialize, Serialize};

use super::skeleton::{DofRef, JointId, Posture, Skeleton, SkeletonPose};
use crate::pose::Pose;

/// Index of a shape in [`super::Character::shapes`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(transparent)]
pub struct ShapeId(pub u32);

impl ShapeId {
    /// The id as an index.
    pub fn index(self) -> usize {
        self.0 as usize
    }
}

/// Projection tolerance: [`ShapeGeometry::project`] lands within this distance (metres,
/// first-order estimate `|F|/|∇F|`) of the surface.
pub const PROJECTION_TOLERANCE_M: f32 = 1e-5;

/// The most deformations one shape may carry.
pub const MAX_DEFORMATIONS: usize = 4;

/// Smallest scale a taper may reach (the scale is clamped here so the map stays invertible).
pub const MIN_TAPER_SCALE: f32 = 0.05;
/// Relative widening of [`ShapeGeometry::bounding_ellipsoid_weights`].
pub const BOUND_SLACK: f32 = 1e-3;

/// Whether a point `p` of a shape's own frame (metres) lies in both of the shape's bounds: the
/// box `|p_i| ≤ extent_i` ([`ShapeGeometry::extent_m`]) and the ellipsoid `Σ p_i² w_i ≤ 1`
/// with the weights `w` of [`ShapeGeometry::bounding_ellipsoid_weights`]. Every point of the
/// shape does, so a point outside either is outside the shape. Branch-free, so that it
/// vectorises inside a loop over points.
#[inline(always)]
pub fn within_bounds(p: Vec3, extent: Vec3, weights: Vec3) -> bool {
    let in_box = (p.x.abs() <= extent.x) & (p.y.abs() <= extent.y) & (p.z.abs() <= extent.z);
    in_box & (p.x * p.x * weights.x + p.y * p.y * weights.y + p.z * p.z * weights.z <= 1.0)
}

/// Smallest and largest superellipsoid exponent accepted (beyond 2 the surface has cusps where
/// the gradient is infinite).
pub const SUPERELLIPSOID_EXPONENT_RANGE: (f32, f32) = (0.1, 2.0);

/// An undeformed solid in the shape's rest space, centred on the origin.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Primitive {
    /// A sphere of radius `radius_m`.
    Sphere {
        /// Radius, metres (> 0).
        radius_m: f32,
    },
    /// Barr's superellipsoid `(|x/a|^(2/e2) + |z/c|^(2/e2))^(e2/e1) + |y/b|^(2/e1) = 1` with
    /// `radii_m = (a, b, c)` and +Y the polar axis. `e1 = e2 = 1` is an ellipsoid; smaller
    /// exponents are boxier, 2 gives a double cone/octahedron.
    Superellipsoid {
        /// Semi-axes along x, y, z, metres (> 0).
        radii_m: Vec3,
        /// North-south (polar, along Y) exponent, in [`SUPERELLIPSOID_EXPONENT_RANGE`].
        e1: f32,
        /// East-west (around Y) exponent, in [`SUPERELLIPSOID_EXPONENT_RANGE`].
        e2: f32,
    },
    /// A cylinder along Y with flat caps at `y = ±half_length_m`. Use spheres at the ends for
    /// a capsule (as the arm does).
    Cylinder {
        /// Radius, metres (> 0).
        radius_m: f32,
        /// Half of the length along Y, metres (> 0).
        half_length_m: f32,
    },
}

/// One key of a keyed parameter.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ParamKey {
    /// Time, seconds.
    pub time_s: f32,
    /// Value at that time.
    pub value: f32,
}

/// A deformation parameter: constant, keyed over simulation time, or tied to a joint angle.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Param {
    /// A fixed value.
    Constant {
        /// The value.
        value: f32,
    },
    /// Piecewise-linear in time through the keys (sorted by time), held constant outside.
    Keyed {
        /// At least one key, strictly increasing times.
        keys: Vec<ParamKey>,
    },
    /// `value = offset + gain · angle_rad` of one joint degree of freedom (a flexing muscle).
    JointAngle {
        /// The degree of freedom whose (clamped) angle drives the parameter.
        dof: DofRef,
        /// Value at angle 0.
        offset: f32,
        /// Change per radian.
        gain: f32,
    },
}

impl Param {
    /// A constant parameter.
    pub fn constant(value: f32) -> Self {
        Param::Constant { value }
    }

    /// The parameter's value at `time_s` in `posture` (angles clamped to their limits).
    pub fn evaluate(&self, skeleton: &Skeleton, posture: &Posture, time_s: f32) -> f32 {
        match self {
            Param::Constant { value } => *value,
            Param::Keyed { keys } => keyed_value(keys, time_s),
            Param::JointAngle { dof, offset, gain } => {
                let angle = skeleton
                    .dof_index(*dof)
                    .and_then(|i| {
                        let a = posture.angles_rad.get(i).copied()?;
                        let d = skeleton.joints[dof.joint.index()].dofs[usize::from(dof.dof)];
                        Some(d.clamp(if a.is_finite() { a } else { 0.0 }))
                    })
                    .unwrap_or(0.0);
                offset + gain * angle
            }
        }
    }

    /// The range of values the parameter can take (over all times and angles within limits).
    pub fn range(&self, skeleton: &Skeleton) -> (f32, f32) {
        match self {
            Param::Constant { value } => (*value, *value),
            Param::Keyed { keys } => keys
                .iter()
                .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), k| {
                    (lo.min(k.value), hi.max(k.value))
                }),
            Param::JointAngle { dof, offset, gain } => {
                let (lo, hi) = skeleton
                    .joints
                    .get(dof.joint.index())
                    .and_then(|j| j.dofs.get(usize::from(dof.dof)))
                    .map(|d| (d.min_rad, d.max_rad))
                    .unwrap_or((0.0, 0.0));
                let a = offset + gain * lo;
                let b = offset + gain * hi;
                (a.min(b), a.max(b))
            }
        }
    }
}

fn keyed_value(keys: &[ParamKey], time_s: f32) -> f32 {
    let Some(first) = keys.first() else {
        return 0.0;
    };
    if time_s.is_nan() || time_s <= first.time_s {
        return first.value;
    }
    for w in keys.windows(2) {
        let (a, b) = (w[0], w[1]);
        if time_s <= b.time_s {
            let span = b.time_s - a.time_s;
            if span <= 0.0 {
                return b.value;
            }
            let u = (time_s - a.time_s) / span;
            return a.value + (b.value - a.value) * u;
        }
    }
    keys.last().map(|k| k.value).unwrap_or(0.0)
}

/// One of Barr's global deformations, acting about the shape's +Y axis.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Deformation {
    /// Scales x and z by `r(y) = 1 + rate_per_m · y` (clamped to [`MIN_TAPER_SCALE`]).
    Taper {
        /// Change of scale per metre along Y (1/m).
        rate_per_m: Param,
    },
    /// Rotates about Y by `θ(y) = rate_rad_per_m · y`.
    Twist {
        /// Twist rate, radians per metre.
        rate_rad_per_m: Param,
    },
    /// Bends the Y axis into a circular arc of curvature `curvature_per_m` (1/radius) towards +X,
    /// the origin fixed. Keep `|curvature| · bound radius < 1`.
    Bend {
        /// Curvature, 1/m (0 = straight).
        curvature_per_m: Param,
    },
}

impl Deformation {
    /// The deformation's parameter.
    pub fn param(&self) -> &Param {
        match self {
            Deformation::Taper { rate_per_m } => rate_per_m,
            Deformation::Twist { rate_rad_per_m } => rate_rad_per_m,
            Deformation::Bend { curvature_per_m } => curvature_per_m,
        }
    }

    /// The deformation with its parameter evaluated.
    pub fn resolve(&self, skeleton: &Skeleton, posture: &Posture, time_s: f32) -> Resolved {
        let v = self.param().evaluate(skeleton, posture, time_s);
        let v = if v.is_finite() { v } else { 0.0 };
        match self {
            Deformation::Taper { .. } => Resolved::Taper { rate_per_m: v },
            Deformation::Twist { .. } => Resolved::Twist { rate_rad_per_m: v },
            Deformation::Bend { .. } => Resolved::Bend { curvature_per_m: v },
        }
    }
}

/// A deformation with its parameter evaluated (see [`Deformation`] for the meaning).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Resolved {
    /// Taper with this rate (1/m).
    Taper {
        /// 1/m.
        rate_per_m: f32,
    },
    /// Twist with this rate (rad/m).
    Twist {
        /// rad/m.
        rate_rad_per_m: f32,
    },
    /// Bend with this curvature (1/m).
    Bend {
        /// 1/m.
        curvature_per_m: f32,
    },
}

/// Curvatures below this (1/m) are treated as straight (the bend moves points by less than a
/// micrometre over a metre).
pub const MIN_CURVATURE_PER_M: f32 = 1e-6;

impl Resolved {
    /// Forward map: rest-space point to deformed space.
    pub fn apply(&self, p: Vec3) -> Vec3 {
        match *self {
            Resolved::Taper { rate_per_m } => {
                let r = (1.0 + rate_per_m * p.y).max(MIN_TAPER_SCALE);
                Vec3::new(p.x * r, p.y, p.z * r)
            }
            Resolved::Twist { rate_rad_per_m } => {
                let (s, c) = (rate_rad_per_m * p.y).sin_cos();
                Vec3::new(p.x * c - p.z * s, p.y, p.x * s + p.z * c)
            }
            Resolved::Bend { curvature_per_m: k } => {
                if k.abs() < MIN_CURVATURE_PER_M {
                    return p;
                }
                let theta = k * p.y;
                let (s, c) = theta.sin_cos();
                let half = (0.5 * theta).sin();
                // (1 - cos θ)/k written without cancellation.
                let x = p.x * c + 2.0 * half * half / k;
                let y = (1.0 - k * p.x) * s / k;
                Vec3::new(x, y, p.z)
            }
        }
    }

    /// Inverse map (deformed to rest space) and its Jacobian `∂p_rest/∂p_deformed`.
    pub fn invert(&self, q: Vec3) -> (Vec3, Mat3) {
        match *self {
            Resolved::Taper { rate_per_m } => {
                let raw = 1.0 + rate_per_m * q.y;
                let (r, dr) = if raw > MIN_TAPER_SCALE {
                    (raw, rate_per_m)
                } else {
                    (MIN_TAPER_SCALE, 0.0)
                };
                let inv = 1.0 / r;
                let p = Vec3::new(q.x * inv, q.y, q.z * inv);
                // Columns: ∂p/∂X, ∂p/∂Y, ∂p/∂Z.
                let j = Mat3::from_cols(
                    Vec3::new(inv, 0.0, 0.0),
                    Vec3::new(-q.x * dr * inv * inv, 1.0, -q.z * dr * inv * inv),
                    Vec3::new(0.0, 0.0, inv),
                );
                (p, j)
            }
            Resolved::Twist { rate_rad_per_m: w } => {
                let (s, c) = (w * q.y).sin_cos();
                let x = q.x * c + q.z * s;
                let z = -q.x * s + q.z * c;
                let j = Mat3::from_cols(
                    Vec3::new(c, 0.0, -s),
                    Vec3::new(w * z, 1.0, -w * x),
                    Vec3::new(s, 0.0, c),
                );
                (Vec3::new(x, q.y, z), j)
            }
            Resolved::Bend { curvature_per_m: k } => {
                if k.abs() < MIN_CURVATURE_PER_M {
                    return (q, Mat3::IDENTITY);
                }
                let ky = k * q.y;
                let one_minus_kx = 1.0 - k * q.x;
                let theta = ky.atan2(one_minus_kx);
                let rho = (ky * ky + one_minus_kx * one_minus_kx).sqrt(); // = 1 - k x_rest
                let x = -(k * q.y * q.y - 2.0 * q.x + k * q.x * q.x) / (1.0 + rho);
                let y = theta / k;
                let (s, c) = theta.sin_cos();
                let inv_rho = if rho > 1e-12 { 1.0 / rho } else { 0.0 };
                let j = Mat3::from_cols(
                    Vec3::new(c, s * inv_rho, 0.0),
                    Vec3::new(-s, c * inv_rho, 0.0),
                    Vec3::new(0.0, 0.0, 1.0),
                );
                (Vec3::new(x, y, q.z), j)
            }
        }
    }

    /// A radius that contains the image of the ball of radius `r` about the origin.
    ///
    /// The bend's `√2`: a rest point `(x, y)` goes to `|P|² = x² + 4 (1 − kx) sin²(ky/2) / k²
    /// ≤ x² + (1 − kx) min(y², 4/k²)`, which is at most `x² + 2y²` for every curvature (with
    /// `c = −kx > 1` the excess over `2y²` is at most `(c − 1)·4/k² ≤ c²/k² = x²`, as
    /// `(c − 2)² ≥ 0`).
    pub(crate) fn bound(&self, r: f32) -> f32 {
        match *self {
            Resolved::Taper { rate_per_m } => r * (1.0 + rate_per_m.abs() * r).max(1.0),
            Resolved::Twist { .. } => r,
            Resolved::Bend { curvature_per_m } => {
                if curvature_per_m.abs() < MIN_CURVATURE_PER_M {
                    r
                } else {
                    r * std::f32::consts::SQRT_2
                }
            }
        }
    }
}

impl Primitive {
    /// Radius of a sphere about the origin containing the primitive, metres.
    pub fn bound_radius_m(&self) -> f32 {
        match *self {
            Primitive::Sphere { radius_m } => radius_m,
            Primitive::Superellipsoid { radii_m, .. } => radii_m.length(),
            Primitive::Cylinder {
                radius_m,
                half_length_m,
            } => (radius_m * radius_m + half_length_m * half_length_m).sqrt(),
        }
    }

    /// Inside/outside value `F(p)` in rest space (see module docs).
    pub fn value(&self, p: Vec3) -> f32 {
        match *self {
            Primitive::Sphere { radius_m } => p.length() - radius_m,
            Primitive::Superellipsoid { radii_m, e1, e2 } => se_eval(p, radii_m, e1, e2, false).0,
            Primitive::Cylinder {
                radius_m,
                half_length_m,
            } => cylinder_eval(p, radius_m, half_length_m).0,
        }
    }

    /// `F(p)` and its gradient in rest space.
    pub fn value_and_gradient(&self, p: Vec3) -> (f32, Vec3) {
        match *self {
            Primitive::Sphere { radius_m } => {
                let len = p.length();
                let g = if len > 0.0 { p / len } else { Vec3::Y };
                (len - radius_m, g)
            }
            Primitive::Superellipsoid { radii_m, e1, e2 } => se_eval(p, radii_m, e1, e2, true),
            Primitive::Cylinder {
                radius_m,
                half_length_m,
            } => cylinder_eval(p, radius_m, half_length_m),
        }
    }

    /// The surface point on the ray from the origin through `p` (exact). `p = 0` maps to the
    /// top pole.
    pub fn radial_projection(&self, p: Vec3) -> Vec3 {
        match *self {
            Primitive::Sphere { radius_m } => {
                let len = p.length();
                if len > 0.0 {
                    p * (radius_m / len)
                } else {
                    Vec3::new(0.0, radius_m, 0.0)
                }
            }
            Primitive::Superellipsoid { radii_m, e1, e2 } => {
                let g = se_eval(p, radii_m, e1, e2, false).0 + 1.0;
                if g > 0.0 {
                    p / g
                } else {
                    Vec3::new(0.0, radii_m.y, 0.0)
                }
            }
            Primitive::Cylinder {
                radius_m,
                half_length_m,
            } => {
                let rho = (p.x * p.x + p.z * p.z).sqrt();
                let g = (rho / radius_m).max(p.y.abs() / half_length_m);
                if g > 0.0 {
                    p / g
                } else {
                    Vec3::new(0.0, half_length_m, 0.0)
                }
            }
        }
    }

    /// Nearest surface point, closed form (spheres, cylinders) or the iterative projection
    /// (superellipsoids).
    pub fn project(&self, p: Vec3) -> Vec3 {
        match *self {
            Primitive::Sphere { .. } => self.radial_projection(p),
            Primitive::Cylinder {
                radius_m,
                half_length_m,
            } => cylinder_project(p, radius_m, half_length_m),
            Primitive::Superellipsoid { .. } => {
                let geometry = ShapeGeometry::new(*self, &[]);
                geometry.project(p)
            }
        }
    }
}

fn cylinder_eval(p: Vec3, r: f32, h: f32) -> (f32, Vec3) {
    let rho = (p.x * p.x + p.z * p.z).sqrt();
    let radial = if rho > 0.0 {
        Vec3::new(p.x / rho, 0.0, p.z / rho)
    } else {
        Vec3::X
    };
    let axial = Vec3::new(0.0, if p.y >= 0.0 { 1.0 } else { -1.0 }, 0.0);
    let dx = rho - r;
    let dy = p.y.abs() - h;
    if dx > 0.0 && dy > 0.0 {
        let d = (dx * dx + dy * dy).sqrt();
        (d, (radial * dx + axial * dy) / d)
    } else if dx > dy {
        (dx, radial)
    } else {
        (dy, axial)
    }
}

fn cylinder_project(p: Vec3, r: f32, h: f32) -> Vec3 {
    let rho = (p.x * p.x + p.z * p.z).sqrt();
    let radial = if rho > 0.0 {
        Vec3::new(p.x / rho, 0.0, p.z / rho)
    } else {
        Vec3::X
    };
    let sign_y = if p.y >= 0.0 { 1.0 } else { -1.0 };
    let dx = rho - r;
    let dy = p.y.abs() - h;
    if dx <= 0.0 && dy <= 0.0 {
        // Inside: to the nearest face.
        if dx > dy {
            Vec3::new(radial.x * r, p.y, radial.z * r)
        } else {
            Vec3::new(p.x, sign_y * h, p.z)
        }
    } else {
        let rho_c = rho.min(r);
        let y_c = p.y.clamp(-h, h);
        Vec3::new(radial.x * rho_c, y_c, radial.z * rho_c)
    }
}

/// Superellipsoid value `g − 1` (and gradient of `g` when asked), computed in f64 on the point
/// scaled into the unit box so no power overflows or underflows to a wrong result.
fn se_eval(p: Vec3, radii: Vec3, e1: f32, e2: f32, want_gradient: bool) -> (f32, Vec3) {
    let (a, b, c) = (f64::from(radii.x), f64::from(radii.y), f64::from(radii.z));
    let (x, y, z) = (f64::from(p.x), f64::from(p.y), f64::from(p.z));
    let s = (x.abs() / a).max(y.abs() / b).max(z.abs() / c);
    if s == 0.0 || !s.is_finite() {
        return (-1.0, Vec3::Y);
    }
    let (qx, qy, qz) = (
        (x / (a * s)).abs(),
        (y / (b * s)).abs(),
        (z / (c * s)).abs(),
    );
    if e1 == 1.0 && e2 == 1.0 {
        // Ellipsoid fast path.
        let f = qx * qx + qy * qy + qz * qz;
        let root = f.sqrt();
        let g = s * root;
        if !want_gradient {
            return ((g - 1.0) as f32, Vec3::ZERO);
        }
        // ∇g = (q/radii) / sqrt(f) with signs.
        let inv = 1.0 / root;
        let grad = Vec3::new(
            (signum0(x) * qx / a * inv) as f32,
            (signum0(y) * qy / b * inv) as f32,
            (signum0(z) * qz / c * inv) as f32,
        );
        return ((g - 1.0) as f32, grad);
    }
    let (e1, e2) = (f64::from(e1), f64::from(e2));
    let px = pow0(qx, 2.0 / e2);
    let pz = pow0(qz, 2.0 / e2);
    let py = pow0(qy, 2.0 / e1);
    let big_a = px + pz;
    let a_pow = pow0(big_a, e2 / e1);
    let f = a_pow + py;
    let f_pow = f.powf(e1 / 2.0);
    let g = s * f_pow;
    if !want_gradient {
        return ((g - 1.0) as f32, Vec3::ZERO);
    }
    // ∇g = f^(e1/2−1) · ( A^(e2/e1−1) |qx|^(2/e2−1) sgn(x)/a, |qy|^(2/e1−1) sgn(y)/b, … ).
    let f_term = f_pow / f;
    let a_term = if big_a > 0.0 { a_pow / big_a } else { 0.0 };
    let dx = if qx > 0.0 { px / qx } else { 0.0 };
    let dz = if qz > 0.0 { pz / qz } else { 0.0 };
    let dy = if qy > 0.0 { py / qy } else { 0.0 };
    let grad = Vec3::new(
        (f_term * a_term * dx * signum0(x) / a) as f32,
        (f_term * dy * signum0(y) / b) as f32,
        (f_term * a_term * dz * signum0(z) / c) as f32,
    );
    ((g - 1.0) as f32, grad)
}

fn pow0(v: f64, e: f64) -> f64 {
    if v > 0.0 { v.powf(e) } else { 0.0 }
}

fn signum0(v: f64) -> f64 {
    if v > 0.0 {
        1.0
    } else if v < 0.0 {
        -1.0
    } else {
        0.0
    }
}

/// A shape's geometry in its own frame with every parameter evaluated: the allocation-free,
/// `Copy` object the simulation queries.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShapeGeometry {
    /// The undeformed primitive.
    pub primitive: Primitive,
    deformations: [Resolved; MAX_DEFORMATIONS],
    deformation_count: u8,
    bound_radius_m: f32,
}

impl ShapeGeometry {
    /// Geometry from a primitive and resolved deformations (at most [`MAX_DEFORMATIONS`]; the
    /// rest are ignored).
    pub fn new(primitive: Primitive, deformations: &[Resolved]) -> Self {
        let mut ds = [Resolved::Twist {
            rate_rad_per_m: 0.0,
        }; MAX_DEFORMATIONS];
        let n = deformations.len().min(MAX_DEFORMATIONS);
        ds[..n].copy_from_slice(&deformations[..n]);
        let mut bound = primitive.bound_radius_m();
        for d in &ds[..n] {
            bound = d.bound(bound);
        }
        Self {
            primitive,
            deformations: ds,
            deformation_count: n as u8,
            bound_radius_m: bound,
        }
    }

    /// The resolved deformations, in the order they are applied.
    pub fn deformations(&self) -> &[Resolved] {
        &self.deformations[..usize::from(self.deformation_count)]
    }

    /// True when the shape has no deformation.
    pub fn is_undeformed(&self) -> bool {
        self.deformation_count == 0
    }

    /// Radius of a sphere about the shape origin containing the (deformed) shape, metres.
    pub fn bound_radius_m(&self) -> f32 {
        self.bound_radius_m
    }

    /// A conservative half-extent box of the deformed shape in its own frame (every shape point
    /// `p` has `|p_i| ≤ extent_i`), metres.
    pub fn extent_m(&self) -> Vec3 {
        self.deformations()
            .iter()
            .fold(self.primitive_box(), Self::deformed_box)
    }

    /// The undeformed primitive's half-extent box, metres.
    fn primitive_box(&self) -> Vec3 {
        match self.primitive {
            Primitive::Sphere { radius_m } => Vec3::splat(radius_m),
            Primitive::Superellipsoid { radii_m, .. } => radii_m,
            Primitive::Cylinder {
                radius_m,
                half_length_m,
            } => Vec3::new(radius_m, half_length_m, radius_m),
        }
    }

    /// The half-extent box containing the image of the box `e` under `d`.
    fn deformed_box(e: Vec3, d: &Resolved) -> Vec3 {
        match *d {
            Resolved::Taper { rate_per_m } => {
                let scale = (1.0 + rate_per_m.abs() * e.y).max(1.0);
                Vec3::new(e.x * scale, e.y, e.z * scale)
            }
            Resolved::Twist { .. } => {
                let rho = (e.x * e.x + e.z * e.z).sqrt();
                Vec3::new(rho, e.y, rho)
            }
            Resolved::Bend { curvature_per_m } => {
                if curvature_per_m.abs() < MIN_CURVATURE_PER_M {
                    e
                } else {
                    // The bend maps the xy disc of radius r into that of radius √2·r
                    // (`Resolved::bound`); z is unchanged.
                    let r = (e.x * e.x + e.y * e.y).sqrt() * std::f32::consts::SQRT_2;
                    Vec3::new(r, r, e.z)
                }
            }
        }
    }

    /// Semi-axes `E` of a conservative axis-aligned ellipsoid about the origin of the shape's
    /// own frame: every point `p` of the deformed shape has `Σ (p_i / E_i)² ≤ 1`, metres. An
    /// axis may be unbounded (`f32::INFINITY`, its term 0): a cylinder's ellipsoid is the
    /// infinite one around its axis. Together with [`Self::extent_m`]'s box it cuts off the
    /// box's corners, where the constraint pass would otherwise evaluate points that cannot be
    /// inside.
    ///
    /// - Superellipsoid, in coordinates `x̂ = x/a` etc.: `w = ‖(x̂, ẑ)‖_(2/e2)` and
    ///   `‖(w, ŷ)‖_(2/e1) ≤ 1`. For `p ≥ 2`, `‖v‖₂² ≤ 2^(1 − 2/p) ‖v‖_p²` in two dimensions (and
    ///   `‖v‖₂ ≤ ‖v‖_p` for `p < 2`), so `x̂² + ẑ² ≤ A w²` and `w² + ŷ² ≤ B` with
    ///   `A = 2^max(0, 1 − e2)`, `B = 2^max(0, 1 − e1)`: every axis scales by `√(AB)` (1 for an
    ///   ellipsoid).
    /// - Taper (x and z scaled by `1 + t y`, `|y| ≤` the box's y): x and z scale by the largest
    ///   factor, as in the box.
    /// - Twist (x and z turned about y): a turn keeps `x² + z²`, so both take the larger axis.
    /// - Bend (in the xy plane, z kept): a rest point `(x, y)` goes to distance `|P|` with
    ///   `|P|² = x² + (4R/k) sin²(ky/2)`, `R = 1/k − x`, so `|P|² ≤ x² + (1 − kx) y² ≤
    ///   (1 + |k| X)(x² + y²)` with `X ≥ |x|` (the box's x), and also `|P|² ≤ 2(x² + y²)`
    ///   (the bend in `Resolved::bound`); each z slice's disc grows by the smaller factor, and
    ///   x and y both take the larger axis times that.
    pub fn bounding_ellipsoid_m(&self) -> Vec3 {
        let mut e = match self.primitive {
            Primitive::Sphere { radius_m } => Vec3::splat(radius_m),
            Primitive::Superellipsoid { radii_m, e1, e2 } => {
                let exponent = (1.0 - e1).max(0.0) + (1.0 - e2).max(0.0);
                radii_m * (0.5 * exponent).exp2()
            }
            Primitive::Cylinder { radius_m, .. } => Vec3::new(radius_m, f32::INFINITY, radius_m),
        };
        // The box before each deformation, for the bounds the ellipsoid steps need.
        let mut bx = self.primitive_box();
        for d in self.deformations() {
            e = match *d {
                Resolved::Taper { rate_per_m } => {
                    let scale = (1.0 + rate_per_m.abs() * bx.y).max(1.0);
                    Vec3::new(e.x * scale, e.y, e.z * scale)
                }
                Resolved::Twist { .. } => {
                    let r = e.x.max(e.z);
                    Vec3::new(r, e.y, r)
                }
                Resolved::Bend { curvature_per_m } => {
                    if curvature_per_m.abs() < MIN_CURVATURE_PER_M {
                        e
                    } else {
                        let grow = (1.0 + curvature_per_m.abs() * bx.x).min(2.0).sqrt();
                        let r = e.x.max(e.y) * grow;
                        Vec3::new(r, r, e.z)
                    }
                }
            };
            bx = Self::deformed_box(bx, d);
        }
        e
    }

    /// [`Self::bounding_ellipsoid_m`] as weights `w = 1/E²` per axis, widened by
    /// [`BOUND_SLACK`] so that rounding in a mapping to the shape frame cannot drop a point of
    /// the shape: every shape point `p` has `Σ p_i² w_i ≤ 1`. An unbounded axis weighs 0, and
    /// so does every axis when a weight would not be finite (a degenerate axis), which turns
    /// the test off rather than dropping every point, 1/m².
    pub fn bounding_ellipsoid_weights(&self) -> Vec3 {
        let e = self.bounding_ellipsoid_m() * (1.0 + BOUND_SLACK);
        let w = Vec3::ONE / (e * e);
        if w.is_finite() { w } else { Vec3::ZERO }
    }

    /// Rest space to shape (deformed) space.
    pub fn deform(&self, p_rest: Vec3) -> Vec3 {
        self.deformations().iter().fold(p_rest, |p, d| d.apply(p))
    }

    /// Shape (deformed) space to rest space.
    pub fn undeform(&self, p_shape: Vec3) -> Vec3 {
        self.deformations()
            .iter()
            .rev()
            .fold(p_shape, |q, d| d.invert(q).0)
    }

    /// `F(p_shape)`: negative inside, zero on the surface, positive outside.
    #[inline]
    pub fn value(&self, p_shape: Vec3) -> f32 {
        if self.deformation_count == 0 {
            return self.primitive.value(p_shape);
        }
        self.primitive.value(self.undeform(p_shape))
    }

    /// `F(p_shape)` and `∇F` (not normalised) in shape space.
    #[inline]
    pub fn value_and_gradient(&self, p_shape: Vec3) -> (f32, Vec3) {
        if self.deformation_count == 0 {
            return self.primitive.value_and_gradient(p_shape);
        }
        let mut q = p_shape;
        let mut jac = Mat3::IDENTITY; // ∂p_rest/∂p_shape
        for d in self.deformations().iter().rev() {
            let (p, j) = d.invert(q);
            jac = j * jac;
            q = p;
        }
        let (v, g_rest) = self.primitive.value_and_gradient(q);
        (v, jac.transpose() * g_rest)
    }

    /// `∇F` in shape space (not normalised).
    pub fn gradient(&self, p_shape: Vec3) -> Vec3 {
        self.value_and_gradient(p_shape).1
    }

    /// First-order distance estimate `F/|∇F|` in metres (exact for undeformed spheres and
    /// cylinders); negative inside.
    pub fn distance_estimate_m(&self, p_shape: Vec3) -> f32 {
        let (v, g) = self.value_and_gradient(p_shape);
        let len = g.length();
        if len > 1e-12 { v / len } else { v }
    }

    /// A point on the surface near `p_shape` (see module docs), within
    /// [`PROJECTION_TOLERANCE_M`].
    pub fn project(&self, p_shape: Vec3) -> Vec3 {
        if self.deformation_count == 0 {
            match self.primitive {
                Primitive::Sphere { .. } => return self.primitive.radial_projection(p_shape),
                Primitive::Cylinder {
                    radius_m,
                    half_length_m,
                } => return cylinder_project(p_shape, radius_m, half_length_m),
                Primitive::Superellipsoid { .. } => {}
            }
        }
        let mut q = p_shape;
        for _ in 0..24 {
            let (v, g) = self.value_and_gradient(q);
            let len2 = g.length_squared();
            if len2.is_nan() || len2 <= 1e-20 || !v.is_finite() {
                break;
            }
            let step = g * (v / len2);
            q -= step;
            if step.length() < 0.1 * PROJECTION_TOLERANCE_M {
                if self.distance_estimate_m(q).abs() <= PROJECTION_TOLERANCE_M
                    && (q - p_shape).length() <= 2.0 * self.bound_radius_m + 1e-3
                {
                    return q;
                }
                break;
            }
        }
        // Fallback: exact intersection of the rest-space ray from the centre.
        self.deform(self.primitive.radial_projection(self.undeform(p_shape)))
    }
}

/// A muscle or bone shape attached to a joint.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Shape {
    /// Name (unique within the character).
    pub name: String,
    /// The joint the shape moves with.
    pub joint: JointId,
    /// The shape frame in the joint's frame (metres, rotation).
    pub joint_from_shape: Pose,
    /// The undeformed solid.
    pub primitive: Primitive,
    /// Global deformations applied in order (at most [`MAX_DEFORMATIONS`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub deformations: Vec<Deformation>,
}

impl Shape {
    /// The shape's geometry with its parameters evaluated at `time_s` in `posture`.
    pub fn geometry(&self, skeleton: &Skeleton, posture: &Posture, time_s: f32) -> ShapeGeometry {
        let mut resolved = [Resolved::Twist {
            rate_rad_per_m: 0.0,
        }; MAX_DEFORMATIONS];
        let n = self.deformations.len().min(MAX_DEFORMATIONS);
        for (slot, d) in resolved.iter_mut().zip(&self.deformations) {
            *slot = d.resolve(skeleton, posture, time_s);
        }
        ShapeGeometry::new(self.primitive, &resolved[..n])
    }

    /// The shape placed in the world for one posture: geometry plus `world_from_shape`.
    pub fn instance(
        &self,
        skeleton: &Skeleton,
        posture: &Posture,
        pose: &SkeletonPose,
        time_s: f32,
    ) -> ShapeInstance {
        let world_from_shape = pose.world_from(self.joint) * self.joint_from_shape;
        ShapeInstance::new(self.geometry(skeleton, posture, time_s), world_from_shape)
    }
}

/// A shape resolved for one posture and time and placed in the world. Precompute one per shape
/// per step; all queries are allocation-free.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShapeInstance {
    /// The geometry in the shape frame.
    pub geometry: ShapeGeometry,
    /// Shape frame to world.
    pub world_from_shape: Affine3A,
    /// World to shape frame.
    pub shape_from_world: Affine3A,
    /// Centre of the bounding sphere in the world (the shape origin), metres.
    pub bound_center_world_m: Vec3,
    /// Radius of the bounding sphere, metres.
    pub bound_radius_m: f32,
}

impl ShapeInstance {
    /// An instance from geometry and its placement.
    pub fn new(geometry: ShapeGeometry, world_from_shape: Pose) -> Self {
        let world_from_shape = Affine3A::from_rotation_translation(
            world_from_shape.orientation,
            world_from_shape.position_m,
        );
        Self {
            geometry,
            world_from_shape,
            shape_from_world: world_from_shape.inverse(),
            bound_center_world_m: Vec3::from(world_from_shape.translation),
            bound_radius_m: geometry.bound_radius_m(),
        }
    }

    /// Maps a world point into the shape frame.
    #[inline]
    pub fn to_shape(&self, p_world: Vec3) -> Vec3 {
        self.shape_from_world.transform_point3(p_world)
    }

    /// True when the world point may be inside or on the shape (bounding-sphere test).
    #[inline]
    pub fn may_contain_world(&self, p_world: Vec3) -> bool {
        (p_world - self.bound_center_world_m).length_squared()
            <= self.bound_radius_m * self.bound_radius_m
    }

    /// True when the world point is strictly inside the shape (`F < 0`), the bounding sphere
    /// tested first.
    #[inline]
    pub fn contains_world(&self, p_world: Vec3) -> bool {
        self.may_contain_world(p_world) && self.value_world(p_world) < 0.0
    }

    /// `F` of a world point.
    #[inline]
    pub fn value_world(&self, p_world: Vec3) -> f32 {
        self.geometry.value(self.to_shape(p_world))
    }

    /// `F` of a world point and `∇F` in world coordinates (not normalised).
    #[inline]
    pub fn value_and_gradient_world(&self, p_world: Vec3) -> (f32, Vec3) {
        let (v, g) = self.geometry.value_and_gradient(self.to_shape(p_world));
        (v, self.world_from_shape.transform_vector3(g))
    }

    /// A surface point near a world point, in world coordinates.
    #[inline]
    pub fn project_world(&self, p_world: Vec3) -> Vec3 {
        self.world_from_shape
            .transform_point3(self.geometry.project(self.to_shape(p_world)))
    }

    /// A rest-space point of this shape (e.g. a tissue anchor) in world coordinates.
    #[inline]
    pub fn rest_point_to_world(&self, p_rest: Vec3) -> Vec3 {
        self.world_from_shape
            .transform_point3(self.geometry.deform(p_rest))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn samples() -> Vec<Vec3> {
        // Deterministic spread of points in a 0.3 m cube.
        let mut pts = Vec::new();
        let mut state: u32 = 12345;
        let mut next = || {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (state >> 8) as f32 / (1u32 << 24) as f32 * 2.0 - 1.0
        };
        for _ in 0..300 {
            pts.push(Vec3::new(next(), next(), next()) * 0.3);
        }
        pts
    }

    fn geometries() -> Vec<(&'static str, ShapeGeometry)> {
        let sphere = Primitive::Sphere { radius_m: 0.1 };
        let se = Primitive::Superellipsoid {
            radii_m: Vec3::new(0.08, 0.15, 0.1),
            e1: 0.6,
            e2: 1.4,
        };
        let ell = Primitive::Superellipsoid {
            radii_m: Vec3::new(0.08, 0.15, 0.1),
            e1: 1.0,
            e2: 1.0,
        };
        let cyl = Primitive::Cylinder {
            radius_m: 0.05,
            half_length_m: 0.15,
        };
        let taper = Resolved::Taper { rate_per_m: 2.0 };
        let twist = Resolved::Twist {
            rate_rad_per_m: 4.0,
        };
        let bend = Resolved::Bend {
            curvature_per_m: 3.0,
        };
        vec![
            ("sphere", ShapeGeometry::new(sphere, &[])),
            ("superellipsoid", ShapeGeometry::new(se, &[])),
            ("ellipsoid", ShapeGeometry::new(ell, &[])),
            ("cylinder", ShapeGeometry::new(cyl, &[])),
            ("tapered sphere", ShapeGeometry::new(sphere, &[taper])),
            ("twisted superellipsoid", ShapeGeometry::new(se, &[twist])),
            ("bent cylinder", ShapeGeometry::new(cyl, &[bend])),
            ("all three", ShapeGeometry::new(se, &[taper, twist, bend])),
        ]
    }

    #[test]
    fn sign_is_negative_inside_zero_on_surface_positive_outside() {
        for (name, g) in geometries() {
            assert!(g.value(Vec3::ZERO) < 0.0, "{name}: centre inside");
            assert!(g.value(Vec3::splat(1.0)) > 0.0, "{name}: far point outside");
            // Along rays from the centre: inside before the surface point, outside after.
            for dir in [
                Vec3::X,
                Vec3::Y,
                -Vec3::Z,
                Vec3::new(1.0, -2.0, 0.5).normalize(),
            ] {
                let surf = g.deform(g.primitive.radial_projection(g.undeform(dir * 0.01)));
                assert!(g.value(surf).abs() < 1e-4, "{name}: surface {surf}");
                let centre_side = surf * 0.9;
                let out_side = surf * 1.1;
                assert!(g.value(centre_side) < 0.0, "{name}: inside along {dir}");
                assert!(g.value(out_side) > 0.0, "{name}: outside along {dir}");
            }
        }
    }

    #[test]
    fn gradient_matches_finite_differences() {
        let h = 1e-3_f32;
        for (name, g) in geometries() {
            let mut checked = 0;
            for p in samples() {
                // Skip points near creases where F is not differentiable.
                let (_, grad) = g.value_and_gradient(p);
                let fd = Vec3::new(
                    g.value(p + Vec3::X * h) - g.value(p - Vec3::X * h),
                    g.value(p + Vec3::Y * h) - g.value(p - Vec3::Y * h),
                    g.value(p + Vec3::Z * h) - g.value(p - Vec3::Z * h),
                ) / (2.0 * h);
                let smooth = {
                    // Consistency of gradients one step apart says we are off a crease.
                    let g2 = g.gradient(p + Vec3::splat(2.0 * h));
                    let g3 = g.gradient(p - Vec3::splat(2.0 * h));
                    (g2 - grad).length() < 0.05 * grad.length().max(1.0)
                        && (g3 - grad).length() < 0.05 * grad.length().max(1.0)
                };
                if smooth {
                    checked += 1;
                    let err = (fd - grad).length();
                    assert!(
                        err < 0.02 * grad.length().max(1.0),
                        "{name} at {p}: analytic {grad}, numeric {fd}"
                    );
                }
            }
            assert!(
                checked >= 150,
                "{name}: only {checked} of 300 points were checked"
            );
        }
    }

    #[test]
    fn projection_lands_on_surface_and_is_idempotent() {
        for (name, g) in geometries() {
            for p in samples() {
                let q = g.project(p);
                let d = g.distance_estimate_m(q).abs();
                assert!(
                    d <= PROJECTION_TOLERANCE_M * 1.01,
                    "{name}: {p} -> {q}, off by {d}"
                );
                let q2 = g.project(q);
                assert!(
                    (q2 - q).length() <= 2.0 * PROJECTION_TOLERANCE_M,
                    "{name}: not idempotent {q} -> {q2}"
                );
            }
        }
    }

    #[test]
    fn closed_form_projections_are_nearest_points() {
        let s = ShapeGeometry::new(Primitive::Sphere { radius_m: 0.5 }, &[]);
        assert!((s.project(Vec3::new(0.0, 0.0, 2.0)) - Vec3::new(0.0, 0.0, 0.5)).length() < 1e-6);
        let c = ShapeGeometry::new(
            Primitive::Cylinder {
                radius_m: 0.1,
                half_length_m: 0.2,
            },
            &[],
        );
        // Inside, nearer the side than the caps.
        let q = c.project(Vec3::new(0.05, 0.0, 0.0));
        assert!((q - Vec3::new(0.1, 0.0, 0.0)).length() < 1e-6);
        // Outside beyond the rim.
        let q = c.project(Vec3::new(0.3, 0.5, 0.0));
        assert!((q - Vec3::new(0.1, 0.2, 0.0)).length() < 1e-6);
        assert!(
            (c.value(Vec3::new(0.3, 0.5, 0.0)) - (0.2f32 * 0.2 + 0.3 * 0.3).sqrt()).abs() < 1e-6
        );
    }

    #[test]
    fn deformations_invert_consistently() {
        let ds = [
            Resolved::Taper { rate_per_m: 1.5 },
            Resolved::Taper { rate_per_m: -2.0 },
            Resolved::Twist {
                rate_rad_per_m: 5.0,
            },
            Resolved::Bend {
                curvature_per_m: 2.5,
            },
            Resolved::Bend {
                curvature_per_m: -4.0,
            },
            Resolved::Bend {
                curvature_per_m: 1e-4,
            },
        ];
        for d in ds {
            for p in samples() {
                if let Resolved::Bend { curvature_per_m: k } = d
                    && 1.0 - k * p.x < 0.2
                {
                    continue; // beyond the centre of curvature: outside the valid domain
                }
                let q = d.apply(p);
                let (back, jac) = d.invert(q);
                assert!((back - p).length() < 2e-6, "{d:?}: {p} -> {q} -> {back}");
                // Jacobian of the inverse against finite differences.
                let h = 1e-3;
                for (k, axis) in [Vec3::X, Vec3::Y, Vec3::Z].into_iter().enumerate() {
                    let fd = (d.invert(q + axis * h).0 - d.invert(q - axis * h).0) / (2.0 * h);
                    assert!(
                        (fd - jac.col(k)).length() < 1e-3,
                        "{d:?} col {k}: {fd} vs {}",
                        jac.col(k)
                    );
                }
            }
        }
        // A bend maps the axis to a circle of radius 1/k through the origin.
        let b = Resolved::Bend {
            curvature_per_m: 2.0,
        };
        let q = b.apply(Vec3::new(0.0, std::f32::consts::FRAC_PI_4, 0.0));
        assert!((q - Vec3::new(0.5, 0.5, 0.0)).length() < 1e-6, "{q}");
    }

    #[test]
    fn bounding_spheres_contain_the_shapes() {
        for (name, g) in geometries() {
            let r = g.bound_radius_m();
            for p in samples() {
                let surf = g.deform(g.primitive.radial_projection(p));
                assert!(surf.length() <= r * 1.0001, "{name}: {surf} outside {r}");
            }
        }
    }

    #[test]
    fn bounding_ellipsoids_contain_the_shapes_and_cut_the_box_corners() {
        // The last two are boxy: their ellipsoid cannot cut the box's corners.
        let exponents = [(0.6, 0.9), (0.9, 1.0), (1.0, 1.0), (2.0, 0.3), (0.1, 0.1)];
        let mut all = geometries();
        for (i, (e1, e2)) in exponents.into_iter().enumerate() {
            let se = Primitive::Superellipsoid {
                radii_m: Vec3::new(0.06, 0.11, 0.08),
                e1,
                e2,
            };
            let bend = Resolved::Bend {
                curvature_per_m: -6.0,
            };
            let names = if i < 3 {
                ["superellipsoid", "bent superellipsoid"]
            } else {
                ["boxy superellipsoid", "boxy bent superellipsoid"]
            };
            all.push((names[0], ShapeGeometry::new(se, &[])));
            all.push((names[1], ShapeGeometry::new(se, &[bend])));
        }
        for (name, g) in all {
            let e = g.bounding_ellipsoid_m();
            let measure = |p: Vec3| (p / e).length_squared();
            let mut worst = 0.0f32;
            for p in samples() {
                let surf = g.primitive.radial_projection(p);
                for t in [1.0, 0.8, 0.5] {
                    worst = worst.max(measure(g.deform(surf * t)));
                }
            }
            assert!(worst <= 1.0001, "{name}: a shape point at {worst} > 1");
            // The bound is of use: the box's corner is outside it (an ellipsoid's inscribed
            // box has its corners at 1/√3 of the axes), except for boxy shapes and where it
            // bounds one axis only (a bent cylinder).
            let bounded = e.to_array().iter().filter(|a| a.is_finite()).count();
            let corner = g.extent_m() * 0.9;
            let useful = bounded < 2 || name.starts_with("boxy") || measure(corner) > 1.0;
            assert!(useful, "{name}: the box corner is inside");
        }
    }

    /// Bends whose curvature times the shape's reach across them is above 1, where the side
    /// away from the centre of curvature stretches most (`1 − kx > 2`).
    #[test]
    fn strong_bends_stay_inside_their_box_sphere_and_ellipsoid() {
        let se = Primitive::Superellipsoid {
            radii_m: Vec3::new(0.3, 0.25, 0.1),
            e1: 1.0,
            e2: 1.0,
        };
        for k in [4.0, -4.0, 3.0, 30.0, -30.0] {
            let g = ShapeGeometry::new(se, &[Resolved::Bend { curvature_per_m: k }]);
            let (bx, r, e) = (g.extent_m(), g.bound_radius_m(), g.bounding_ellipsoid_m());
            for p in samples() {
                let rest = g.primitive.radial_projection(p);
                if 1.0 - k * rest.x <= 0.0 {
                    continue; // beyond the centre of curvature: outside the valid domain
                }
                let q = g.deform(rest);
                let tag = format!("k = {k}: {rest} -> {q}");
                assert!(
                    (q.abs() - bx * 1.0001).max_element() <= 0.0,
                    "{tag} outside {bx}"
                );
                assert!(q.length() <= r * 1.0001, "{tag} outside {r}");
                assert!((q / e).length_squared() <= 1.0001, "{tag} outside {e}");
            }
        }
    }

    #[test]
    fn extreme_exponents_and_far_points_stay_finite() {
        let g = ShapeGeometry::new(
            Primitive::Superellipsoid {
                radii_m: Vec3::new(0.1, 0.2, 0.1),
                e1: 0.1,
                e2: 0.1,
            },
            &[],
        );
        for p in [
            Vec3::splat(1e6),
            Vec3::new(1e-30, 0.0, 0.0),
            Vec3::ZERO,
            Vec3::new(0.0, 0.0, 1e-9),
        ] {
            let (v, grad) = g.value_and_gradient(p);
            assert!(v.is_finite() && grad.is_finite(), "{p}: {v} {grad}");
            assert!(g.project(p).is_finite());
        }
    }

    #[test]
    fn params_constant_keyed_and_joint_angle() {
        use crate::character::skeleton::{Dof, Joint};
        let skeleton = Skeleton {
            joints: vec![Joint {
                name: "j".into(),
                parent: None,
                offset_m: Vec3::ZERO,
                dofs: vec![Dof::new(Vec3::Z, -1.0, 1.0)],
            }],
        };
        let posture = Posture {
            root_translation_m: Vec3::ZERO,
            angles_rad: vec![2.0], // clamped to 1.0
        };
        assert_eq!(Param::constant(3.0).evaluate(&skeleton, &posture, 9.0), 3.0);
        let keyed = Param::Keyed {
            keys: vec![
                ParamKey {
                    time_s: 0.0,
                    value: 0.0,
                },
                ParamKey {
                    time_s: 2.0,
                    value: 4.0,
                },
            ],
        };
        assert_eq!(keyed.evaluate(&skeleton, &posture, -1.0), 0.0);
        assert_eq!(keyed.evaluate(&skeleton, &posture, 0.5), 1.0);
        assert_eq!(keyed.evaluate(&skeleton, &posture, 5.0), 4.0);
        let flex = Param::JointAngle {
            dof: DofRef {
                joint: JointId(0),
                dof: 0,
            },
            offset: 0.5,
            gain: 2.0,
        };
        assert_eq!(flex.evaluate(&skeleton, &posture, 0.0), 2.5);
        assert_eq!(flex.range(&skeleton), (-1.5, 2.5));
    }
}
