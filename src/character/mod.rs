//! The character model as data: skeleton, muscles and bones, fat, connective tissue, skin; its
//! file format.
//!
//! A [`Character`] is the layered model of LEMAN (paper `003_…`, sections 3-4): a
//! [`Skeleton`] of joints, muscle/bone [`Shape`]s attached to joints, an elastic [`Skin`] mesh
//! (with the fat thickness per skin point), connective [`TissueSpring`]s from skin points to
//! anchors on shapes, default simulation parameters and named keyed [`Motion`]s.
//!
//! How the simulation uses it, per step: posture from a motion ([`Motion::posture_at`]) →
//! [`Skeleton::forward_kinematics`] → [`Character::shape_instances_into`] (one
//! [`ShapeInstance`] per shape: world transforms, resolved deformations, bounding sphere) →
//! inside/outside tests, gradients and projections on those instances; tissue anchors in the
//! world from [`ShapeInstance::rest_point_to_world`]; fixed skin rows from
//! [`Character::boundary_positions_into`].

pub mod examples;
pub mod file;
pub mod resample;
pub mod shape;
pub mod skeleton;
pub mod skin;
pub mod tissue;

use glam::Vec3;
use serde::{Deserialize, Serialize};

pub use crate::anim::keyed::{Extrapolation, KeyPosture, Motion};
pub use file::{CharacterFileError, FORMAT_VERSION};
pub use shape::{
    Deformation, PROJECTION_TOLERANCE_M, Param, ParamKey, Primitive, Resolved, Shape,
    ShapeGeometry, ShapeId, ShapeInstance, within_bounds,
};
pub use skeleton::{Dof, DofRef, Joint, JointId, Posture, Skeleton, SkeletonPose};
pub use skin::{Skin, Sym2};
pub use tissue::{AttachParams, TissueSpring, attach_global};

/// Default simulation parameters stored with a character (the simulator may override them).
/// Symbols refer to paper `003_…` section 4.2.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimulationDefaults {
    /// Gravity g, m/s² (world frame; +Y is up).
    pub gravity_m_per_s2: Vec3,
    /// k∥ of eq. 13d: fraction of the normal velocity reversed at a constraint (0 = inelastic).
    pub k_parallel: f32,
    /// k⊥ of eq. 13d: fraction of the tangential velocity kept at a constraint (1 = frictionless).
    pub k_perpendicular: f32,
    /// ε_c: largest position correction per step before the step is rejected, metres.
    pub epsilon_c_m: f32,
    /// Re-check threshold as a fraction of ε_c (0 < f ≤ 1): a constraint correction longer
    /// than `recheck_fraction · ε_c` turns its neighbours' normals enough that their fat points
    /// are tested again in the same step. Larger is faster and leaves fat points deeper
    /// (`docs/simulate.md`, "The re-check passes"). Optional in files (default
    /// [`DEFAULT_RECHECK_FRACTION`]).
    #[serde(default = "default_recheck_fraction")]
    pub recheck_fraction: f32,
    /// Whether a muscle holds the skin resting on it between steps: a point the constraints
    /// pushed out loses the part of its acceleration that presses it into the muscle while it
    /// stays in contact (a one-sided contact reaction), so resting skin is not pushed out
    /// again every step. Off, contact is the paper's projection alone (section 4.2.3).
    /// Optional in files (default true; `docs/simulate.md`, "Resting contact").
    #[serde(default = "default_hold_contacts")]
    pub hold_contacts: bool,
    /// ε_r: position error tolerance of the adaptive step control (eq. 11-12).
    pub epsilon_r: f32,
    /// r_threshold: position magnitude above which error control becomes relative, metres.
    pub r_threshold_m: f32,
    /// ε_v: velocity fixed-point tolerance (eq. 7g).
    pub epsilon_v: f32,
    /// v_threshold: velocity magnitude above which error control becomes relative, m/s.
    pub v_threshold_m_per_s: f32,
    /// Smallest adaptive step, seconds.
    pub min_step_s: f32,
    /// Largest adaptive step, seconds.
    pub max_step_s: f32,
    /// Step of the fixed-step explicit Euler integrator, seconds.
    pub euler_step_s: f32,
    /// Step of the fixed-step classical Runge-Kutta 4 integrator, seconds. Optional in files:
    /// without it RK4 steps at `euler_step_s` (as files written before it existed did).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rk4_step_s: Option<f32>,
}

/// The re-check threshold of [`SimulationDefaults::recheck_fraction`] when a file gives none:
/// one tenth of ε_c keeps the torso's median residual depth near 0.06 mm.
pub const DEFAULT_RECHECK_FRACTION: f32 = 0.1;

fn default_recheck_fraction() -> f32 {
    DEFAULT_RECHECK_FRACTION
}

fn default_hold_contacts() -> bool {
    true
}

/// Whether `f` can be a [`SimulationDefaults::recheck_fraction`]: in (0, 1] (NaN is not). The
/// one rule the file, the simulator's parameter change and the command line all check.
pub fn is_recheck_fraction(f: f32) -> bool {
    f > 0.0 && f <= 1.0
}

/// Whether `k` can be eq. 13d's k∥ or k⊥: a fraction of a velocity component, in [0, 1] (NaN is
/// not). Above 1 a contact would add energy (k⊥ = 10³⁰ made the tangential velocity infinite
/// after the guard had passed the step). The one rule the file and the simulator's parameter
/// change check.
pub fn is_velocity_fraction(k: f32) -> bool {
    (0.0..=1.0).contains(&k)
}

impl Default for SimulationDefaults {
    fn default() -> Self {
        Self {
            gravity_m_per_s2: Vec3::new(0.0, -9.81, 0.0),
            k_parallel: 0.0,
            k_perpendicular: 1.0,
            epsilon_c_m: 0.005,
            recheck_fraction: DEFAULT_RECHECK_FRACTION,
            hold_contacts: true,
            epsilon_r: 1e-3,
            r_threshold_m: 1.0,
            epsilon_v: 1e-3,
            v_threshold_m_per_s: 1.0,
            min_step_s: 1e-4,
            max_step_s: 0.016,
            euler_step_s: 0.0005,
            rk4_step_s: None,
        }
    }
}

impl SimulationDefaults {
    /// The step RK4 takes, seconds: [`SimulationDefaults::rk4_step_s`], or without it
    /// `euler_step_s` (as files written before RK4 had its own step).
    pub fn rk4_step_or_euler_s(&self) -> f32 {
        self.rk4_step_s.unwrap_or(self.euler_step_s)
    }

    fn validate(&self) -> Result<(), String> {
        let scalars = [
            ("k_parallel", self.k_parallel),
            ("k_perpendicular", self.k_perpendicular),
            ("epsilon_c_m", self.epsilon_c_m),
            ("recheck_fraction", self.recheck_fraction),
            ("epsilon_r", self.epsilon_r),
            ("r_threshold_m", self.r_threshold_m),
            ("epsilon_v", self.epsilon_v),
            ("v_threshold_m_per_s", self.v_threshold_m_per_s),
            ("min_step_s", self.min_step_s),
            ("max_step_s", self.max_step_s),
            ("euler_step_s", self.euler_step_s),
            // Absent, RK4 takes Euler's step, checked above.
            ("rk4_step_s", self.rk4_step_or_euler_s()),
        ];
        if !self.gravity_m_per_s2.is_finite() {
            return Err("simulation: gravity_m_per_s2 is not finite".into());
        }
        for (name, v) in scalars {
            if !v.is_finite() || v < 0.0 {
                return Err(format!(
                    "simulation: {name} must be finite and >= 0, got {v}"
                ));
            }
        }
        // The error scaling divides by max(|value|, threshold) (eq. 8), so a zero threshold
        // makes the error of a coordinate at exactly 0 infinite and no step can be taken; the
        // simulator's `Tolerances::check` refuses it too.
        for (name, v) in [
            ("epsilon_c_m", self.epsilon_c_m),
            ("epsilon_r", self.epsilon_r),
            ("r_threshold_m", self.r_threshold_m),
            ("epsilon_v", self.epsilon_v),
            ("v_threshold_m_per_s", self.v_threshold_m_per_s),
            ("min_step_s", self.min_step_s),
            ("euler_step_s", self.euler_step_s),
            ("rk4_step_s", self.rk4_step_or_euler_s()),
        ] {
            if v <= 0.0 {
                return Err(format!("simulation: {name} must be > 0, got {v}"));
            }
        }
        for (name, k) in [
            ("k_parallel", self.k_parallel),
            ("k_perpendicular", self.k_perpendicular),
        ] {
            if !is_velocity_fraction(k) {
                return Err(format!("simulation: {name} must be in [0, 1], got {k}"));
            }
        }
        if !is_recheck_fraction(self.recheck_fraction) {
            return Err(format!(
                "simulation: recheck_fraction must be in (0, 1], got {}",
                self.recheck_fraction
            ));
        }
        if self.max_step_s < self.min_step_s {
            return Err(format!(
                "simulation: max_step_s {} is below min_step_s {}",
                self.max_step_s, self.min_step_s
            ));
        }
        Ok(())
    }
}

/// A complete layered character.
#[derive(Debug, Clone, PartialEq)]
pub struct Character {
    /// Name, e.g. "penguin".
    pub name: String,
    /// The articulated skeleton.
    pub skeleton: Skeleton,
    /// Muscle and bone shapes; index = [`ShapeId`].
    pub shapes: Vec<Shape>,
    /// The skin mesh, its materials and the fat thickness per point.
    pub skin: Skin,
    /// Connective tissue springs.
    pub tissue: Vec<TissueSpring>,
    /// Default simulation parameters.
    pub simulation: SimulationDefaults,
    /// Named keyed motions of the skeleton.
    pub motions: Vec<Motion>,
}

/// A problem found by [`Character::validate`]; the message names the item and the value.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct ValidationError(pub String);

impl Character {
    /// The motion with this name.
    pub fn motion(&self, name: &str) -> Option<&Motion> {
        self.motions.iter().find(|m| m.name == name)
    }

    /// Every shape placed for one posture and time, written into `out` (cleared first; no
    /// allocation once it has the capacity). `out[k]` belongs to `ShapeId(k)`.
    pub fn shape_instances_into(
        &self,
        posture: &Posture,
        pose: &SkeletonPose,
        time_s: f32,
        out: &mut Vec<ShapeInstance>,
    ) {
        out.clear();
        out.extend(
            self.shapes
                .iter()
                .map(|s| s.instance(&self.skeleton, posture, pose, time_s)),
        );
    }

    /// The character as it is built: every shape placed in the neutral posture at time 0, and
    /// the skin's stored points with their outward unit normals (world frame). What the
    /// global attach and the checks of a fresh skin start from.
    pub fn neutral_layout(&self) -> (Vec<ShapeInstance>, Vec<(Vec3, Vec3)>) {
        let posture = Posture::neutral(&self.skeleton);
        let pose = self.skeleton.forward_kinematics(&posture);
        let mut instances = Vec::new();
        self.shape_instances_into(&posture, &pose, 0.0, &mut instances);
        let mut normals = Vec::new();
        self.skin
            .outward_normals(&self.skin.positions_m, &mut normals);
        let points = self.skin.positions_m.iter().copied().zip(normals).collect();
        (instances, points)
    }

    /// World positions of the fixed skin rows for a skeleton pose: row 0 (M points) followed by
    /// row N−1 (M points), written into `out`.
    pub fn boundary_positions_into(&self, pose: &SkeletonPose, out: &mut Vec<Vec3>) {
        out.clear();
        let bottom = pose.world_from(self.skin.bottom_joint);
        let top = pose.world_from(self.skin.top_joint);
        out.extend(
            self.skin
                .bottom_ring_m
                .iter()
                .map(|p| bottom.transform_point(*p)),
        );
        out.extend(self.skin.top_ring_m.iter().map(|p| top.transform_point(*p)));
    }

    /// Checks everything: the skeleton's hierarchy and limits, every shape's joint, sizes and
    /// parameters, the skin's arrays, every spring's point and shape, the simulation defaults and
    /// every motion. `Err` names the first problem found.
    pub fn validate(&self) -> Result<(), ValidationError> {
        self.validate_inner().map_err(ValidationError)
    }

    fn validate_inner(&self) -> Result<(), String> {
        if self.name.trim().is_empty() {
            return Err("character: name is empty".into());
        }
        validate_skeleton(&self.skeleton)?;
        for (k, shape) in self.shapes.iter().enumerate() {
            validate_shape(&self.skeleton, k, shape)?;
        }
        self.skin.validate(&self.skeleton)?;
        let points = self.skin.point_count();
        for (k, s) in self.tissue.iter().enumerate() {
            if s.skin_point as usize >= points {
                return Err(format!(
                    "tissue spring {k}: skin_point {} is beyond the skin's {points} points",
                    s.skin_point
                ));
            }
            if s.shape.index() >= self.shapes.len() {
                return Err(format!(
                    "tissue spring {k}: shape {} does not exist ({} shapes)",
                    s.shape.0,
                    self.shapes.len()
                ));
            }
            if !s.anchor_rest_m.is_finite() {
                return Err(format!("tissue spring {k}: anchor_rest_m is not finite"));
            }
            for (what, v) in [
                ("stiffness_n_per_m", s.stiffness_n_per_m),
                ("damping_n_s_per_m", s.damping_n_s_per_m),
                ("rest_length_m", s.rest_length_m),
            ] {
                if !v.is_finite() || v < 0.0 {
                    return Err(format!(
                        "tissue spring {k}: {what} must be finite and >= 0, got {v}"
                    ));
                }
            }
        }
        self.simulation.validate()?;
        for (k, m) in self.motions.iter().enumerate() {
            if self.motions[..k].iter().any(|o| o.name == m.name) {
                return Err(format!("motion \"{}\": name used twice", m.name));
            }
            m.validate(&self.skeleton)?;
        }
        // The fixed rows must sit where their joints put them at the neutral posture.
        let pose = self
            .skeleton
            .forward_kinematics(&Posture::neutral(&self.skeleton));
        let mut ring = Vec::new();
        self.boundary_positions_into(&pose, &mut ring);
        let m = self.skin.around;
        let top_row = self.skin.along - 1;
        for i in 0..m {
            for (j, expected) in [(0, ring[i as usize]), (top_row, ring[(m + i) as usize])] {
                let stored = self.skin.positions_m[self.skin.index(i, j)];
                if (stored - expected).length() > 1e-4 {
                    return Err(format!(
                        "skin: positions_m of fixed point ({i}, {j}) is {stored} but its joint puts it at {expected}"
                    ));
                }
            }
        }
        Ok(())
    }
}

fn validate_skeleton(skeleton: &Skeleton) -> Result<(), String> {
    if skeleton.joints.is_empty() {
        return Err("skeleton: has no joints".into());
    }
    for (k, joint) in skeleton.joints.iter().enumerate() {
        let name = &joint.name;
        if name.trim().is_empty() {
            return Err(format!("joint {k}: name is empty"));
        }
        if skeleton.joints[..k].iter().any(|o| &o.name == name) {
            return Err(format!("joint {k} \"{name}\": name used twice"));
        }
        match (k, joint.parent) {
            (0, None) => {}
            (0, Some(_)) => {
                return Err(format!("joint 0 \"{name}\": the root must have no parent"));
            }
            (_, None) => {
                return Err(format!(
                    "joint {k} \"{name}\": has no parent (only joint 0 is the root)"
                ));
            }
            (_, Some(p)) if p.index() >= k => {
                return Err(format!(
                    "joint {k} \"{name}\": parent {} must be an earlier joint",
                    p.0
                ));
            }
            _ => {}
        }
        if !joint.offset_m.is_finite() {
            return Err(format!("joint {k} \"{name}\": offset_m is not finite"));
        }
        if joint.dofs.len() > skeleton::MAX_DOFS_PER_JOINT {
            return Err(format!(
                "joint {k} \"{name}\": has {} degrees of freedom, at most {}",
                joint.dofs.len(),
                skeleton::MAX_DOFS_PER_JOINT
            ));
        }
        for (d, dof) in joint.dofs.iter().enumerate() {
            if !dof.axis.is_finite() || (dof.axis.length() - 1.0).abs() > 1e-3 {
                return Err(format!(
                    "joint {k} \"{name}\": dof {d} axis {} is not a unit vector",
                    dof.axis
                ));
            }
            if !dof.min_rad.is_finite() || !dof.max_rad.is_finite() || dof.min_rad > dof.max_rad {
                return Err(format!(
                    "joint {k} \"{name}\": dof {d} limits [{}, {}] are not an interval",
                    dof.min_rad, dof.max_rad
                ));
            }
        }
    }
    Ok(())
}

fn validate_shape(skeleton: &Skeleton, k: usize, shape: &Shape) -> Result<(), String> {
    let name = &shape.name;
    let here = format!("shape {k} \"{name}\"");
    if shape.joint.index() >= skeleton.len() {
        return Err(format!(
            "{here}: joint {} does not exist ({} joints)",
            shape.joint.0,
            skeleton.len()
        ));
    }
    if !shape.joint_from_shape.is_valid() {
        return Err(format!(
            "{here}: joint_from_shape is not finite or its rotation is not a unit quaternion"
        ));
    }
    let positive = |what: &str, v: f32| {
        if v.is_finite() && v > 0.0 {
            Ok(())
        } else {
            Err(format!("{here}: {what} must be > 0, got {v}"))
        }
    };
    match shape.primitive {
        Primitive::Sphere { radius_m } => positive("radius_m", radius_m)?,
        Primitive::Superellipsoid { radii_m, e1, e2 } => {
            positive("radii_m.x", radii_m.x)?;
            positive("radii_m.y", radii_m.y)?;
            positive("radii_m.z", radii_m.z)?;
            let (lo, hi) = shape::SUPERELLIPSOID_EXPONENT_RANGE;
            for (what, e) in [("e1", e1), ("e2", e2)] {
                if !(e.is_finite() && (lo..=hi).contains(&e)) {
                    return Err(format!("{here}: {what} must be in [{lo}, {hi}], got {e}"));
                }
            }
        }
        Primitive::Cylinder {
            radius_m,
            half_length_m,
        } => {
            positive("radius_m", radius_m)?;
            positive("half_length_m", half_length_m)?;
        }
    }
    if shape.deformations.len() > shape::MAX_DEFORMATIONS {
        return Err(format!(
            "{here}: has {} deformations, at most {}",
            shape.deformations.len(),
            shape::MAX_DEFORMATIONS
        ));
    }
    let mut bound = shape.primitive.bound_radius_m();
    for (d, def) in shape.deformations.iter().enumerate() {
        let param = def.param();
        match param {
            Param::Constant { value } => {
                if !value.is_finite() {
                    return Err(format!("{here}: deformation {d} value is not finite"));
                }
            }
            Param::Keyed { keys } => {
                if keys.is_empty() {
                    return Err(format!("{here}: deformation {d} has no keys"));
                }
                for (i, key) in keys.iter().enumerate() {
                    if !key.time_s.is_finite() || !key.value.is_finite() {
                        return Err(format!("{here}: deformation {d} key {i} is not finite"));
                    }
                    if i > 0 && key.time_s <= keys[i - 1].time_s {
                        return Err(format!(
                            "{here}: deformation {d} key {i} time is not after the previous key"
                        ));
                    }
                }
            }
            Param::JointAngle { dof, offset, gain } => {
                if skeleton.dof_index(*dof).is_none() {
                    return Err(format!(
                        "{here}: deformation {d} refers to dof {} of joint {}, which does not exist",
                        dof.dof, dof.joint.0
                    ));
                }
                if !offset.is_finite() || !gain.is_finite() {
                    return Err(format!("{here}: deformation {d} offset/gain is not finite"));
                }
            }
        }
        let (lo, hi) = param.range(skeleton);
        let worst = lo.abs().max(hi.abs());
        match def {
            Deformation::Taper { .. } => {
                if worst * bound >= 1.0 - shape::MIN_TAPER_SCALE {
                    return Err(format!(
                        "{here}: deformation {d} taper rate up to {worst} 1/m folds the shape (bound radius {bound} m)"
                    ));
                }
            }
            Deformation::Bend { .. } => {
                if worst * bound >= 0.9 {
                    return Err(format!(
                        "{here}: deformation {d} bend curvature up to {worst} 1/m is too tight for bound radius {bound} m"
                    ));
                }
            }
            Deformation::Twist { .. } => {}
        }
        let extreme = match def {
            Deformation::Taper { .. } => Resolved::Taper { rate_per_m: worst },
            Deformation::Twist { .. } => Resolved::Twist {
                rate_rad_per_m: worst,
            },
            Deformation::Bend { .. } => Resolved::Bend {
                curvature_per_m: worst,
            },
        };
        bound = extreme.bound(bound);
    }
    Ok(())
}
