//! The skeleton layer: a hierarchy of joints with rotational degrees of freedom, postures and
//! forward kinematics.
//!
//! Frames: every joint has its own frame. A joint's frame is its parent's frame translated by
//! [`Joint::offset_m`] (expressed in the parent's frame) and then rotated by the joint's degrees
//! of freedom in order: `parent_from_joint = T(offset_m) · R(axis₀, θ₀) · R(axis₁, θ₁) · R(axis₂, θ₂)`,
//! each axis expressed in the frame left by the rotations before it (intrinsic rotations). The
//! root's parent frame is the world, and the root also translates by
//! [`Posture::root_translation_m`]: `world_from_root = T(root_translation_m + offset_m) · R(…)`.

use glam::{Quat, Vec3};
use serde::{Deserialize, Serialize};

use crate::pose::Pose;

/// Index of a joint in [`Skeleton::joints`]. Joints are stored parents-first, so a joint's
/// parent always has a smaller id; id 0 is the root.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(transparent)]
pub struct JointId(pub u32);

impl JointId {
    /// The root joint.
    pub const ROOT: JointId = JointId(0);

    /// The id as an index into [`Skeleton::joints`].
    pub fn index(self) -> usize {
        self.0 as usize
    }
}

/// One rotational degree of freedom: a rotation about `axis` limited to `[min_rad, max_rad]`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Dof {
    /// Rotation axis (unit vector) in the joint's frame before this rotation (see module docs).
    pub axis: Vec3,
    /// Lower limit in radians.
    pub min_rad: f32,
    /// Upper limit in radians (>= `min_rad`).
    pub max_rad: f32,
}

impl Dof {
    /// A degree of freedom about `axis` (normalised here) with limits in radians.
    pub fn new(axis: Vec3, min_rad: f32, max_rad: f32) -> Self {
        Self {
            axis: axis.normalize_or_zero(),
            min_rad,
            max_rad,
        }
    }

    /// The angle clamped to this degree of freedom's limits.
    pub fn clamp(&self, angle_rad: f32) -> f32 {
        angle_rad.clamp(self.min_rad, self.max_rad)
    }
}

/// The most rotational degrees of freedom one joint may have.
pub const MAX_DOFS_PER_JOINT: usize = 3;

/// A joint of the articulated figure.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Joint {
    /// Unique name (used by files, tools and the UI).
    pub name: String,
    /// Parent joint; `None` only for the root (joint 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub parent: Option<JointId>,
    /// Position of this joint's origin in its parent's frame, metres (world frame for the root).
    pub offset_m: Vec3,
    /// Up to [`MAX_DOFS_PER_JOINT`] rotations, applied in order.
    pub dofs: Vec<Dof>,
}

/// A hierarchy of joints stored parents-first (see [`JointId`]).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Skeleton {
    /// The joints; index = [`JointId`].
    pub joints: Vec<Joint>,
}

/// Where one degree of freedom lives: its joint and its index among that joint's dofs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DofRef {
    /// The joint.
    pub joint: JointId,
    /// Index into that joint's [`Joint::dofs`] (0..3).
    pub dof: u8,
}

/// A skeleton posture: the root's translation and every degree of freedom's angle.
///
/// `angles_rad` is flat: joint 0's dofs first, then joint 1's, … (see [`Skeleton::dof_index`]).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Posture {
    /// Translation added to the root's offset, world frame, metres.
    pub root_translation_m: Vec3,
    /// One angle per degree of freedom, radians, in skeleton order.
    pub angles_rad: Vec<f32>,
}

impl Posture {
    /// The neutral posture of a skeleton: no root translation, every angle 0 clamped to its
    /// limits.
    pub fn neutral(skeleton: &Skeleton) -> Self {
        let mut p = Self {
            root_translation_m: Vec3::ZERO,
            angles_rad: vec![0.0; skeleton.dof_count()],
        };
        skeleton.clamp_posture(&mut p);
        p
    }

    /// True when every number is finite.
    pub fn is_finite(&self) -> bool {
        self.root_translation_m.is_finite() && self.angles_rad.iter().all(|a| a.is_finite())
    }
}

/// Every joint's world transform for one posture: the seam between skeleton and simulation.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SkeletonPose {
    /// `world_from_joint[j]` maps points in joint `j`'s frame to world, indexed by [`JointId`].
    pub world_from_joint: Vec<Pose>,
}

impl SkeletonPose {
    /// The world transform of one joint (identity if the id is out of range).
    pub fn world_from(&self, joint: JointId) -> Pose {
        self.world_from_joint
            .get(joint.index())
            .copied()
            .unwrap_or(Pose::IDENTITY)
    }
}

impl Skeleton {
    /// Number of joints.
    pub fn len(&self) -> usize {
        self.joints.len()
    }

    /// True when there are no joints.
    pub fn is_empty(&self) -> bool {
        self.joints.is_empty()
    }

    /// Total number of degrees of freedom (the length of [`Posture::angles_rad`]).
    pub fn dof_count(&self) -> usize {
        self.joints.iter().map(|j| j.dofs.len()).sum()
    }

    /// Index into [`Posture::angles_rad`] of a degree of freedom, if it exists.
    pub fn dof_index(&self, r: DofRef) -> Option<usize> {
        let joint = self.joints.get(r.joint.index())?;
        if usize::from(r.dof) >= joint.dofs.len() {
            return None;
        }
        let before: usize = self.joints[..r.joint.index()]
            .iter()
            .map(|j| j.dofs.len())
            .sum();
        Some(before + usize::from(r.dof))
    }

    /// The id of the joint with this name.
    pub fn joint_by_name(&self, name: &str) -> Option<JointId> {
        self.joints
            .iter()
            .position(|j| j.name == name)
            .map(|i| JointId(i as u32))
    }

    /// Clamps every angle to its limits; resizes `angles_rad` to [`Self::dof_count`] (missing
    /// angles become 0 clamped) and replaces non-finite values with the clamped 0.
    pub fn clamp_posture(&self, posture: &mut Posture) {
        posture.angles_rad.resize(self.dof_count(), 0.0);
        if !posture.root_translation_m.is_finite() {
            posture.root_translation_m = Vec3::ZERO;
        }
        let mut k = 0;
        for joint in &self.joints {
            for dof in &joint.dofs {
                let a = posture.angles_rad[k];
                posture.angles_rad[k] = dof.clamp(if a.is_finite() { a } else { 0.0 });
                k += 1;
            }
        }
    }

    /// Forward kinematics into a fresh [`SkeletonPose`]. Angles are clamped to their limits
    /// (the posture itself is not changed); missing angles count as 0.
    pub fn forward_kinematics(&self, posture: &Posture) -> SkeletonPose {
        let mut out = SkeletonPose::default();
        self.forward_kinematics_into(posture, &mut out);
        out
    }

    /// Forward kinematics reusing `out`'s storage (no allocation once it has the right size).
    pub fn forward_kinematics_into(&self, posture: &Posture, out: &mut SkeletonPose) {
        out.world_from_joint.clear();
        out.world_from_joint.reserve(self.joints.len());
        let mut k = 0;
        for (index, joint) in self.joints.iter().enumerate() {
            let mut rotation = Quat::IDENTITY;
            for dof in &joint.dofs {
                let raw = posture.angles_rad.get(k).copied().unwrap_or(0.0);
                let angle = dof.clamp(if raw.is_finite() { raw } else { 0.0 });
                rotation *= Quat::from_axis_angle(dof.axis, angle);
                k += 1;
            }
            let parent_from_joint = Pose::new(joint.offset_m, rotation.normalize());
            let world_from_joint = match joint.parent {
                Some(p) if p.index() < index => out.world_from_joint[p.index()] * parent_from_joint,
                _ => {
                    let t = if posture.root_translation_m.is_finite() {
                        posture.root_translation_m
                    } else {
                        Vec3::ZERO
                    };
                    Pose::from_translation(t) * parent_from_joint
                }
            };
            out.world_from_joint.push(world_from_joint);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f32::consts::FRAC_PI_2;

    /// A planar 3-link chain along +X with hinges about +Z.
    fn chain() -> Skeleton {
        let hinge = || vec![Dof::new(Vec3::Z, -FRAC_PI_2, FRAC_PI_2)];
        Skeleton {
            joints: vec![
                Joint {
                    name: "root".into(),
                    parent: None,
                    offset_m: Vec3::new(0.0, 1.0, 0.0),
                    dofs: hinge(),
                },
                Joint {
                    name: "a".into(),
                    parent: Some(JointId(0)),
                    offset_m: Vec3::new(1.0, 0.0, 0.0),
                    dofs: hinge(),
                },
                Joint {
                    name: "b".into(),
                    parent: Some(JointId(1)),
                    offset_m: Vec3::new(1.0, 0.0, 0.0),
                    dofs: vec![],
                },
            ],
        }
    }

    #[test]
    fn fk_of_a_planar_chain_matches_hand_computation() {
        let s = chain();
        let posture = Posture {
            root_translation_m: Vec3::new(0.5, 0.0, 0.0),
            angles_rad: vec![FRAC_PI_2, -FRAC_PI_2],
        };
        let pose = s.forward_kinematics(&posture);
        let p = |j: u32| pose.world_from(JointId(j)).position_m;
        // root at (0.5, 1, 0); rotated +90° about Z so its +X points to world +Y.
        assert!((p(0) - Vec3::new(0.5, 1.0, 0.0)).length() < 1e-6);
        assert!((p(1) - Vec3::new(0.5, 2.0, 0.0)).length() < 1e-6);
        // joint a turns back by -90°, so b is 1 m along world +X from a.
        assert!((p(2) - Vec3::new(1.5, 2.0, 0.0)).length() < 1e-6);
        let x_of_b = pose.world_from(JointId(2)).transform_vector(Vec3::X);
        assert!((x_of_b - Vec3::X).length() < 1e-6);
    }

    #[test]
    fn limits_clamp_angles_in_fk_and_in_clamp_posture() {
        let s = chain();
        let wild = Posture {
            root_translation_m: Vec3::ZERO,
            angles_rad: vec![3.0, -3.0],
        };
        let limited = Posture {
            root_translation_m: Vec3::ZERO,
            angles_rad: vec![FRAC_PI_2, -FRAC_PI_2],
        };
        assert_eq!(s.forward_kinematics(&wild), s.forward_kinematics(&limited));
        let mut p = wild.clone();
        s.clamp_posture(&mut p);
        assert_eq!(p, limited);
        let mut short = Posture {
            root_translation_m: Vec3::ZERO,
            angles_rad: vec![f32::NAN],
        };
        s.clamp_posture(&mut short);
        assert_eq!(short.angles_rad, vec![0.0, 0.0]);
    }

    #[test]
    fn dof_index_counts_earlier_joints() {
        let s = chain();
        assert_eq!(s.dof_count(), 2);
        assert_eq!(
            s.dof_index(DofRef {
                joint: JointId(1),
                dof: 0
            }),
            Some(1)
        );
        assert_eq!(
            s.dof_index(DofRef {
                joint: JointId(2),
                dof: 0
            }),
            None
        );
        assert_eq!(s.joint_by_name("b"), Some(JointId(2)));
    }
}
