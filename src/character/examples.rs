//! The example characters, built in code: a penguin (7 spheres), a wombat (2 spheres, 5
//! superellipsoids, 1 cylinder) and a torso (26 spheres, 12 superellipsoids, 2 cylinders)
//! modelled on Table 1 of the LEMAN paper, and an arm for comparison with other simulators.
//!
//! The files in `assets/characters/` are exactly [`Character::to_toml_string`] of these (a test
//! checks it); regenerate them with `cargo run --example make_characters`.
//!
//! Materials live in one place, [`materials`]: change them there and regenerate.

use std::f32::consts::{FRAC_PI_2, PI, TAU};
use std::path::Path;

use glam::{Quat, Vec3};

use super::resample::euler_step_scale;
use super::shape::{Deformation, Param, Primitive, Shape, ShapeInstance};
use super::skeleton::{Dof, DofRef, Joint, JointId, Posture, Skeleton};
use super::skin::Skin;
use super::tissue::{AttachParams, attach_global};
use super::{Character, CharacterFileError, Extrapolation, KeyPosture, Motion, SimulationDefaults};
use crate::pose::Pose;

/// The example characters' names, in the order [`build`] knows them.
pub const NAMES: [&str; 4] = ["penguin", "wombat", "torso", "arm"];

/// Skin resolutions written for each example: the full one (file `NAME.toml`) and the coarse one
/// (file `NAME_16.toml`).
pub const RESOLUTIONS: [(u32, &str); 2] = [(32, ""), (16, "_16")];

/// The material choices of one example character (the one place to tune them).
///
/// Point values are derived from these so that they mean the same at any resolution:
/// `mass_kg = skin_mass_kg / (M·N)`; the stretch elasticity η (a material constant, the same
/// at every resolution) is chosen so that the linearised stretch stiffness of one point at
/// 32×32, `k ≈ 8·η_ii·G⁰_ii·h_j/h_i` (from the energy `η(G−G⁰)²` with forward differences and
/// forces `= density × h₁h₂`), gives `√(k/m) = stretch_omega_rad_per_s`. At 16×16 the points
/// are four times heavier and the frequency halves, as for any coarser membrane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Materials {
    /// Total skin mass, kg.
    pub skin_mass_kg: f32,
    /// Angular frequency of one skin point against its neighbours' stretch springs at 32×32,
    /// rad/s (sets η). Adaptive explicit steps are limited near 2/(2·ω).
    pub stretch_omega_rad_per_s: f32,
    /// Shear elasticity η₁₂ as a fraction of the mean of η₁₁ and η₂₂.
    pub shear_fraction: f32,
    /// Bending ξ (all three components), N/m (0 = a pure membrane).
    pub bending: f32,
    /// Point damping γ / point mass, 1/s.
    pub damping_per_s: f32,
    /// Tissue spring angular frequency √(k_s/m), rad/s (sets k_s per point).
    pub tissue_omega_rad_per_s: f32,
    /// Tissue spring damping ratio (sets k_d = 2ζ√(k_s m)).
    pub tissue_damping_ratio: f32,
    /// Rest metric = initial metric × this² (below 1: the skin is under slight tension).
    pub rest_shrink: f32,
}

/// The materials of each example character (see [`Materials`]).
pub fn materials(name: &str) -> Materials {
    let base = Materials {
        skin_mass_kg: 1.0,
        stretch_omega_rad_per_s: 60.0,
        shear_fraction: 0.5,
        bending: 0.0,
        damping_per_s: 2.0,
        tissue_omega_rad_per_s: 40.0,
        tissue_damping_ratio: 0.3,
        rest_shrink: 1.0,
    };
    match name {
        "penguin" => Materials {
            skin_mass_kg: 1.2,
            ..base
        },
        "wombat" => Materials {
            skin_mass_kg: 1.5,
            stretch_omega_rad_per_s: 55.0,
            ..base
        },
        "torso" => Materials {
            skin_mass_kg: 2.0,
            stretch_omega_rad_per_s: 65.0,
            tissue_omega_rad_per_s: 45.0,
            ..base
        },
        _ => Materials {
            skin_mass_kg: 0.5,
            ..base
        },
    }
}

/// Builds one example character at an `around × along` skin resolution.
pub fn build(name: &str, around: u32, along: u32) -> Option<Character> {
    body(name).map(|body| finish(body, around, along))
}

/// One example's design (skeleton, muscles, motions, how to wrap its skin), by name.
fn body(name: &str) -> Option<Body> {
    match name {
        "penguin" => Some(penguin()),
        "wombat" => Some(wombat()),
        "torso" => Some(torso()),
        "arm" => Some(arm()),
        _ => None,
    }
}

/// Writes every example at every resolution into `dir` (atomically), returning the paths.
pub fn write_all(dir: &Path) -> Result<Vec<std::path::PathBuf>, CharacterFileError> {
    let mut written = Vec::new();
    for name in NAMES {
        for (res, suffix) in RESOLUTIONS {
            let Some(c) = build(name, res, res) else {
                continue;
            };
            let path = dir.join(format!("{name}{suffix}.toml"));
            c.save(&path)?;
            written.push(path);
        }
    }
    Ok(written)
}

/// The examples' RK4 step, seconds. RK4's stability region reaches along the imaginary axis
/// (to `h ω ≈ 2.8`), so unlike explicit Euler it needs no damping to step the skin stably:
/// every example ran 30 s of its motion at 2 and at 4 ms, and 10 s at 8 ms. Against an RK4
/// run at 0.125 ms, 2.3 s into each 32×32 example's motion, 2 ms leaves an RMS position error
/// no larger than the adaptive Verlet's at its default tolerances (torso 0.18 mm vs 0.29,
/// penguin 0.19 vs 0.34, wombat 0.25 vs 0.49, arm 1.9 vs 4.3); 4 ms is about Verlet's, 8 ms
/// worse (wombat 0.57). The contacts, not the step, set the error floor: halving the step
/// below 2 ms does not shrink it much. The 16×16 skins' errors are larger and noisier, and
/// there 2 ms is about Verlet's (0.3-1.7 of it; see docs/simulate.md, "Step control").
const EXAMPLE_RK4_STEP_S: f32 = 0.002;

/// Explicit Euler's step on the examples' 32×32 skins, seconds (other resolutions scale it by
/// the square of the spacing, and no example steps longer than its body's own step).
///
/// Euler's stability region, the disc `|1 + hλ| < 1`, holds a damped oscillation
/// `λ = −γ ± iω` only while `h < 2γ/ω²`. From 16×16 to 32×32 the skin's membrane frequencies
/// double while its damping rate stays ([`Materials`]), so a 16×16 skin's step is up to four
/// times too long at 32×32. Where the tissue springs are slack a point has only the skin's own
/// damping (2/s), and the 32×32 skins rang at 0.5 ms without ever diverging: at rest (neutral
/// posture, 20 s settled, then 2 s sampled at 60 Hz) a point by the penguin's base swung through
/// more than 15 mm at about 20 Hz, its largest move between frames 31 mm (torso 19, wombat 19;
/// the arm 8 mm at its 0.25 ms). At 0.25 ms the penguin still moved 11 mm between frames and
/// the torso 4.8; at 0.2 ms the arm 1.1 mm; at 0.15 ms no example moves more than a quarter of
/// a millimetre between frames after 20 or 60 s, but for six neighbouring points below the
/// wombat's top ring (up to 1.5 mm).
const EXAMPLE_EULER_STEP_32_S: f32 = 0.000_15;

/// The explicit Euler step of an example whose body's own step (the 16×16 skin's) is
/// `body_step_s`, at an `around × along` skin: [`EXAMPLE_EULER_STEP_32_S`] scaled by the square
/// of the spacing, but never longer than the body's step (at 16×16 the scaled step, 0.6 ms, is
/// longer than every body's, so the 16×16 files keep theirs).
fn example_euler_step_s(body_step_s: f32, around: u32, along: u32) -> f32 {
    body_step_s.min(EXAMPLE_EULER_STEP_32_S * euler_step_scale((32, 32), (around, along)))
}

/// The simulation settings every example starts from.
fn example_simulation() -> SimulationDefaults {
    SimulationDefaults {
        rk4_step_s: Some(EXAMPLE_RK4_STEP_S),
        ..SimulationDefaults::default()
    }
}

/// A body before its skin is made.
struct Body {
    name: &'static str,
    skeleton: Skeleton,
    shapes: Vec<Shape>,
    motions: Vec<Motion>,
    tube: Tube,
    simulation: SimulationDefaults,
}

/// How to wrap the skin: a straight axis from `start_m` (carried by `bottom_joint`) to
/// `end_m` (carried by `top_joint`), world frame at the neutral posture.
struct Tube {
    bottom_joint: JointId,
    top_joint: JointId,
    start_m: Vec3,
    end_m: Vec3,
    /// A unit vector perpendicular to the axis: direction of angle 0 around.
    zero_dir: Vec3,
    radius: Radius,
    /// Fat thickness as a function of (s along in [0, 1], angle around in radians), metres.
    fat_m: fn(f32, f32) -> f32,
    /// Smoothing passes over the wrapped radii (each never goes below what keeps the fat
    /// layer outside the muscles).
    smooth_passes: u32,
    /// Where the skin's rows sit along the axis.
    rows: RowPlacement,
}

/// Where a tube's rows sit along its axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum RowPlacement {
    /// Evenly along the axis.
    Even,
    /// Evenly along a measure of the wrapped profile ([`profile_rows`]), so that where the
    /// body's outline runs across the axis (a flat rump closing onto a small end ring) the rows
    /// close up instead of leaving one long spoke from the end ring to the first row that
    /// wraps the body.
    Profile,
}

/// Fine stations per row interval of the profile that [`RowPlacement::Profile`] measures.
const PROFILE_STATIONS_PER_ROW: u32 = 4;

#[derive(Debug, Clone, Copy)]
enum Radius {
    /// A tube of fixed radius (the arm).
    Constant(f32),
    /// Shrink-wrapped: outermost muscle surface + fat + margin; the bottom and top rings of
    /// the given radius (`None`: shrink-wrapped too).
    Wrap {
        bottom_radius_m: Option<f32>,
        top_radius_m: Option<f32>,
    },
}

const WRAP_MARGIN_M: f32 = 0.003;
const MIN_RADIUS_M: f32 = 0.01;

struct SkeletonBuilder {
    joints: Vec<Joint>,
}

impl SkeletonBuilder {
    fn new() -> Self {
        Self { joints: Vec::new() }
    }

    fn joint(
        &mut self,
        name: &str,
        parent: Option<JointId>,
        offset_m: Vec3,
        dofs: &[Dof],
    ) -> JointId {
        self.joints.push(Joint {
            name: name.to_string(),
            parent,
            offset_m,
            dofs: dofs.to_vec(),
        });
        JointId(self.joints.len() as u32 - 1)
    }

    fn build(self) -> Skeleton {
        Skeleton {
            joints: self.joints,
        }
    }
}

fn dof(axis: Vec3, min_deg: f32, max_deg: f32) -> Dof {
    Dof::new(axis, min_deg.to_radians(), max_deg.to_radians())
}

fn sphere(name: &str, joint: JointId, at_m: Vec3, radius_m: f32) -> Shape {
    Shape {
        name: name.to_string(),
        joint,
        joint_from_shape: Pose::from_translation(at_m),
        primitive: Primitive::Sphere { radius_m },
        deformations: Vec::new(),
    }
}

#[allow(clippy::too_many_arguments)]
fn superellipsoid(
    name: &str,
    joint: JointId,
    at_m: Vec3,
    rotation: Quat,
    radii_m: Vec3,
    e1: f32,
    e2: f32,
    deformations: Vec<Deformation>,
) -> Shape {
    Shape {
        name: name.to_string(),
        joint,
        joint_from_shape: Pose::new(at_m, rotation),
        primitive: Primitive::Superellipsoid { radii_m, e1, e2 },
        deformations,
    }
}

fn cylinder(
    name: &str,
    joint: JointId,
    at_m: Vec3,
    rotation: Quat,
    radius_m: f32,
    half_length_m: f32,
) -> Shape {
    Shape {
        name: name.to_string(),
        joint,
        joint_from_shape: Pose::new(at_m, rotation),
        primitive: Primitive::Cylinder {
            radius_m,
            half_length_m,
        },
        deformations: Vec::new(),
    }
}

fn flex(joint: JointId, dof_index: u8, offset: f32, gain: f32) -> Param {
    Param::JointAngle {
        dof: DofRef {
            joint,
            dof: dof_index,
        },
        offset,
        gain,
    }
}

/// A key posture from (dof index, angle in degrees) pairs and a root translation.
fn key(skeleton: &Skeleton, time_s: f32, root_m: Vec3, angles_deg: &[(usize, f32)]) -> KeyPosture {
    let mut posture = Posture::neutral(skeleton);
    posture.root_translation_m = root_m;
    for &(k, deg) in angles_deg {
        if let Some(a) = posture.angles_rad.get_mut(k) {
            *a = deg.to_radians();
        }
    }
    KeyPosture::new(time_s, posture)
}

fn dof_at(skeleton: &Skeleton, joint: JointId, d: u8) -> usize {
    skeleton
        .dof_index(DofRef { joint, dof: d })
        .unwrap_or(usize::MAX)
}

// ----------------------------------------------------------------------------------------
// Penguin: 7 spheres.

fn penguin() -> Body {
    let mut b = SkeletonBuilder::new();
    let pelvis = b.joint(
        "pelvis",
        None,
        Vec3::new(0.0, 0.15, 0.0),
        &[dof(Vec3::Z, -25.0, 25.0), dof(Vec3::Y, -45.0, 45.0)],
    );
    let chest = b.joint(
        "chest",
        Some(pelvis),
        Vec3::new(0.0, 0.2, 0.0),
        &[dof(Vec3::X, -30.0, 30.0), dof(Vec3::Z, -20.0, 20.0)],
    );
    let head = b.joint(
        "head",
        Some(chest),
        Vec3::new(0.0, 0.18, 0.0),
        &[dof(Vec3::Y, -60.0, 60.0), dof(Vec3::X, -30.0, 30.0)],
    );
    let left = b.joint(
        "left_flipper",
        Some(chest),
        Vec3::new(0.11, 0.06, 0.0),
        &[dof(Vec3::Z, -10.0, 70.0)],
    );
    let right = b.joint(
        "right_flipper",
        Some(chest),
        Vec3::new(-0.11, 0.06, 0.0),
        &[dof(Vec3::Z, -70.0, 10.0)],
    );
    let skeleton = b.build();
    let shapes = vec![
        sphere("belly", pelvis, Vec3::new(0.0, 0.03, 0.015), 0.14),
        sphere("tail", pelvis, Vec3::new(0.0, -0.06, -0.05), 0.08),
        sphere("chest", chest, Vec3::new(0.0, 0.02, 0.0), 0.115),
        sphere("head", head, Vec3::new(0.0, 0.03, 0.0), 0.075),
        sphere("beak", head, Vec3::new(0.0, 0.02, 0.075), 0.03),
        sphere("left_flipper", left, Vec3::new(0.025, -0.09, 0.0), 0.045),
        sphere("right_flipper", right, Vec3::new(-0.025, -0.09, 0.0), 0.045),
    ];
    let s = &skeleton;
    let (sway, turn) = (dof_at(s, pelvis, 0), dof_at(s, pelvis, 1));
    let (lean, tilt) = (dof_at(s, chest, 0), dof_at(s, chest, 1));
    let (yaw, nod) = (dof_at(s, head, 0), dof_at(s, head, 1));
    let (fl, fr) = (dof_at(s, left, 0), dof_at(s, right, 0));
    let up = Vec3::new(0.0, 0.015, 0.0);
    let waddle = Motion {
        name: "waddle".into(),
        keys: vec![
            key(s, 0.0, Vec3::ZERO, &[]),
            key(
                s,
                0.5,
                up,
                &[
                    (sway, 15.0),
                    (turn, 10.0),
                    (tilt, -8.0),
                    (yaw, -20.0),
                    (fl, 45.0),
                    (fr, -10.0),
                    (lean, 5.0),
                ],
            ),
            key(s, 1.0, Vec3::ZERO, &[(nod, 10.0), (fl, 10.0), (fr, -10.0)]),
            key(
                s,
                1.5,
                up,
                &[
                    (sway, -15.0),
                    (turn, -10.0),
                    (tilt, 8.0),
                    (yaw, 20.0),
                    (fl, 10.0),
                    (fr, -45.0),
                    (lean, 5.0),
                ],
            ),
            key(s, 2.0, Vec3::ZERO, &[]),
        ],
        extrapolation: Extrapolation::Loop,
    };
    let flap = Motion {
        name: "flap".into(),
        keys: vec![
            key(s, 0.0, Vec3::ZERO, &[]),
            key(s, 0.3, Vec3::ZERO, &[(fl, 65.0), (fr, -65.0), (nod, -15.0)]),
            key(s, 0.6, Vec3::ZERO, &[]),
        ],
        extrapolation: Extrapolation::Loop,
    };
    Body {
        name: "penguin",
        skeleton,
        shapes,
        motions: vec![waddle, flap],
        tube: Tube {
            bottom_joint: pelvis,
            top_joint: head,
            start_m: Vec3::new(0.0, 0.0, 0.0),
            end_m: Vec3::new(0.0, 0.635, 0.0),
            zero_dir: Vec3::X,
            radius: Radius::Wrap {
                bottom_radius_m: Some(0.012),
                top_radius_m: Some(0.012),
            },
            smooth_passes: 3,
            rows: RowPlacement::Even,
            fat_m: |s, angle| 0.015 + 0.01 * (PI * s).sin() * (0.5 + 0.5 * angle.sin()),
        },
        simulation: example_simulation(),
    }
}

// ----------------------------------------------------------------------------------------
// Wombat: 2 spheres, 5 superellipsoids, 1 cylinder. The body lies along +Z (nose forward).

/// Where the wombat's skin tube starts (its tail ring, carried by the hips), world z at the
/// neutral posture, metres.
const WOMBAT_TAIL_Z_M: f32 = -0.36;
/// Where the wombat's skin tube ends (its nose ring, carried by the head), world z at the
/// neutral posture, metres: 20 mm in front of the snout's tip (z = 0.465), so the ring's fat
/// point stays outside it. Until session 36 the tube ended at z = 0.345, the head's centre:
/// the nose ring sat inside the head and the last free row, wrapped around the head's widest
/// part, was tied to it by 99 mm spokes through the head, so the skin left the face and snout
/// uncovered. Those spokes, the stiffest edges of the skin (a point's stretch stiffness grows
/// with η·G⁰), set the step of fine resamplings: 3 s of the 128×128 wombat took 3793 steps
/// then, about 1500 now.
const WOMBAT_NOSE_Z_M: f32 = 0.485;
/// The end of the wombat's trunk, world z, metres: the fat's bulge under the belly spans the
/// skin from the tail to here (where the tube ended before it was lengthened over the head).
const WOMBAT_TRUNK_END_Z_M: f32 = 0.345;

/// The wombat's fat thickness, metres, at `s` along the skin (0 at the tail, 1 at the nose)
/// and `angle` around it (radians from +X): 12 mm, with up to 8 mm more under the belly,
/// bulging along the trunk; the head and snout carry 12 mm. (Measured along the trunk rather
/// than along `s`, so lengthening the tube over the head left the trunk's fat where it was:
/// spread over the longer tube instead, its bulge moved 7 cm forward and one step of 10 s of
/// the motion needed an 18.8 mm correction under the belly.)
fn wombat_fat_m(s: f32, angle: f32) -> f32 {
    let z = WOMBAT_TAIL_Z_M + s * (WOMBAT_NOSE_Z_M - WOMBAT_TAIL_Z_M);
    let trunk = ((z - WOMBAT_TAIL_Z_M) / (WOMBAT_TRUNK_END_Z_M - WOMBAT_TAIL_Z_M)).clamp(0.0, 1.0);
    0.012 + 0.008 * (PI * trunk).sin() * (0.5 - 0.5 * angle.sin())
}

fn wombat() -> Body {
    let mut b = SkeletonBuilder::new();
    let hips = b.joint(
        "hips",
        None,
        Vec3::new(0.0, 0.2, -0.2),
        &[dof(Vec3::X, -15.0, 15.0), dof(Vec3::Z, -15.0, 15.0)],
    );
    let spine = b.joint(
        "spine",
        Some(hips),
        Vec3::new(0.0, 0.01, 0.17),
        &[dof(Vec3::X, -25.0, 25.0), dof(Vec3::Y, -30.0, 30.0)],
    );
    let shoulders = b.joint(
        "shoulders",
        Some(spine),
        Vec3::new(0.0, 0.0, 0.17),
        &[dof(Vec3::X, -20.0, 20.0), dof(Vec3::Y, -25.0, 25.0)],
    );
    let head = b.joint(
        "head",
        Some(shoulders),
        Vec3::new(0.0, 0.02, 0.16),
        &[dof(Vec3::X, -30.0, 30.0), dof(Vec3::Y, -45.0, 45.0)],
    );
    let skeleton = b.build();
    let forward = Quat::from_rotation_x(FRAC_PI_2); // shape +Y along +Z
    let shapes = vec![
        superellipsoid(
            "rump",
            hips,
            Vec3::new(0.0, 0.0, -0.02),
            forward,
            Vec3::new(0.14, 0.12, 0.12),
            0.8,
            0.8,
            vec![],
        ),
        superellipsoid(
            "belly",
            spine,
            Vec3::ZERO,
            forward,
            Vec3::new(0.15, 0.13, 0.13),
            0.9,
            0.9,
            // A flexing muscle: the belly curls with the spine's pitch.
            vec![Deformation::Bend {
                curvature_per_m: flex(spine, 0, 0.0, -2.5),
            }],
        ),
        superellipsoid(
            "chest",
            shoulders,
            Vec3::new(0.0, 0.0, 0.0),
            forward,
            Vec3::new(0.13, 0.11, 0.12),
            0.85,
            1.0,
            vec![Deformation::Twist {
                rate_rad_per_m: flex(shoulders, 1, 0.0, 3.0),
            }],
        ),
        superellipsoid(
            "head",
            head,
            Vec3::new(0.0, 0.0, 0.04),
            forward,
            Vec3::new(0.09, 0.1, 0.08),
            0.7,
            1.0,
            vec![Deformation::Taper {
                rate_per_m: Param::constant(-2.5),
            }],
        ),
        superellipsoid(
            "snout",
            head,
            Vec3::new(0.0, -0.01, 0.13),
            forward,
            Vec3::new(0.045, 0.035, 0.04),
            1.0,
            1.0,
            vec![],
        ),
        sphere("left_haunch", hips, Vec3::new(0.1, -0.05, -0.02), 0.07),
        sphere("right_haunch", hips, Vec3::new(-0.1, -0.05, -0.02), 0.07),
        cylinder(
            "neck",
            shoulders,
            Vec3::new(0.0, 0.01, 0.1),
            forward,
            0.075,
            0.05,
        ),
    ];
    let s = &skeleton;
    let (hp, hr) = (dof_at(s, hips, 0), dof_at(s, hips, 1));
    let (sp, sy) = (dof_at(s, spine, 0), dof_at(s, spine, 1));
    let (cp, cy) = (dof_at(s, shoulders, 0), dof_at(s, shoulders, 1));
    let (np, ny) = (dof_at(s, head, 0), dof_at(s, head, 1));
    let sniff = Motion {
        name: "sniff".into(),
        keys: vec![
            key(s, 0.0, Vec3::ZERO, &[]),
            key(
                s,
                0.6,
                Vec3::new(0.0, 0.0, 0.01),
                &[(sp, 15.0), (cp, 10.0), (np, 25.0), (hp, -5.0)],
            ),
            key(
                s,
                1.2,
                Vec3::ZERO,
                &[(sy, 20.0), (cy, 15.0), (ny, 35.0), (hr, 5.0)],
            ),
            key(
                s,
                1.8,
                Vec3::new(0.0, 0.0, 0.01),
                &[
                    (sy, -20.0),
                    (cy, -15.0),
                    (ny, -35.0),
                    (sp, -10.0),
                    (hr, -5.0),
                ],
            ),
            key(s, 2.4, Vec3::ZERO, &[]),
        ],
        extrapolation: Extrapolation::Loop,
    };
    Body {
        name: "wombat",
        skeleton,
        shapes,
        motions: vec![sniff],
        tube: Tube {
            bottom_joint: hips,
            top_joint: head,
            start_m: Vec3::new(0.0, 0.2, WOMBAT_TAIL_Z_M),
            end_m: Vec3::new(0.0, 0.22, WOMBAT_NOSE_Z_M),
            zero_dir: Vec3::X,
            radius: Radius::Wrap {
                bottom_radius_m: Some(0.012),
                top_radius_m: Some(0.012),
            },
            smooth_passes: 3,
            rows: RowPlacement::Profile,
            fat_m: wombat_fat_m,
        },
        simulation: example_simulation(),
    }
}

// ----------------------------------------------------------------------------------------
// Torso: 26 spheres, 12 superellipsoids, 2 cylinders; a trunk from the hips to the neck.

fn torso() -> Body {
    let mut b = SkeletonBuilder::new();
    let pelvis = b.joint(
        "pelvis",
        None,
        Vec3::new(0.0, 0.95, 0.0),
        &[dof(Vec3::X, -10.0, 10.0)],
    );
    let lumbar = b.joint(
        "lumbar",
        Some(pelvis),
        Vec3::new(0.0, 0.12, 0.0),
        &[
            dof(Vec3::X, -20.0, 35.0),
            dof(Vec3::Z, -20.0, 20.0),
            dof(Vec3::Y, -30.0, 30.0),
        ],
    );
    let thorax = b.joint(
        "thorax",
        Some(lumbar),
        Vec3::new(0.0, 0.17, 0.0),
        &[
            dof(Vec3::X, -15.0, 25.0),
            dof(Vec3::Z, -15.0, 15.0),
            dof(Vec3::Y, -25.0, 25.0),
        ],
    );
    let neck = b.joint(
        "neck",
        Some(thorax),
        Vec3::new(0.0, 0.22, -0.01),
        &[dof(Vec3::X, -30.0, 30.0), dof(Vec3::Y, -50.0, 50.0)],
    );
    // The shoulders sit below the base of the neck (the trapezius slopes down to them), so
    // the skin runs from the neck over a sloping shoulder line, not a flat shelf.
    let lsh = b.joint(
        "left_shoulder",
        Some(thorax),
        Vec3::new(0.15, 0.13, 0.0),
        &[dof(Vec3::Z, -10.0, 25.0)],
    );
    let rsh = b.joint(
        "right_shoulder",
        Some(thorax),
        Vec3::new(-0.15, 0.13, 0.0),
        &[dof(Vec3::Z, -25.0, 10.0)],
    );
    let skeleton = b.build();
    let id = Quat::IDENTITY;
    let sideways = Quat::from_rotation_z(-FRAC_PI_2); // shape +Y along +X
    let mut shapes = vec![
        // 12 superellipsoids.
        superellipsoid(
            "pelvis_block",
            pelvis,
            Vec3::new(0.0, -0.02, 0.0),
            id,
            Vec3::new(0.15, 0.09, 0.1),
            0.6,
            0.9,
            vec![],
        ),
        superellipsoid(
            "left_glute",
            pelvis,
            Vec3::new(0.07, -0.04, -0.055),
            id,
            Vec3::new(0.075, 0.08, 0.06),
            0.9,
            1.0,
            vec![],
        ),
        superellipsoid(
            "right_glute",
            pelvis,
            Vec3::new(-0.07, -0.04, -0.055),
            id,
            Vec3::new(0.075, 0.08, 0.06),
            0.9,
            1.0,
            vec![],
        ),
        superellipsoid(
            "abdomen",
            lumbar,
            Vec3::new(0.0, 0.01, 0.035),
            id,
            Vec3::new(0.1, 0.12, 0.07),
            0.8,
            1.0,
            // Rectus abdominis: curls when the trunk bends forward.
            vec![Deformation::Bend {
                curvature_per_m: flex(lumbar, 0, 0.0, -2.0),
            }],
        ),
        superellipsoid(
            "left_oblique",
            lumbar,
            Vec3::new(0.075, 0.01, 0.0),
            id,
            Vec3::new(0.06, 0.11, 0.08),
            0.9,
            1.0,
            vec![Deformation::Twist {
                rate_rad_per_m: flex(lumbar, 2, 0.0, 2.0),
            }],
        ),
        superellipsoid(
            "right_oblique",
            lumbar,
            Vec3::new(-0.075, 0.01, 0.0),
            id,
            Vec3::new(0.06, 0.11, 0.08),
            0.9,
            1.0,
            vec![Deformation::Twist {
                rate_rad_per_m: flex(lumbar, 2, 0.0, 2.0),
            }],
        ),
        superellipsoid(
            "lower_back",
            lumbar,
            Vec3::new(0.0, 0.01, -0.035),
            id,
            Vec3::new(0.09, 0.11, 0.05),
            0.8,
            1.0,
            vec![],
        ),
        superellipsoid(
            "ribcage",
            thorax,
            Vec3::new(0.0, 0.05, 0.0),
            id,
            Vec3::new(0.14, 0.16, 0.1),
            0.9,
            1.0,
            vec![Deformation::Taper {
                rate_per_m: Param::constant(-0.6),
            }],
        ),
        superellipsoid(
            "left_pectoral",
            thorax,
            Vec3::new(0.07, 0.1, 0.055),
            id,
            Vec3::new(0.07, 0.05, 0.045),
            0.8,
            1.0,
            vec![],
        ),
        superellipsoid(
            "right_pectoral",
            thorax,
            Vec3::new(-0.07, 0.1, 0.055),
            id,
            Vec3::new(0.07, 0.05, 0.045),
            0.8,
            1.0,
            vec![],
        ),
        superellipsoid(
            "left_latissimus",
            thorax,
            Vec3::new(0.09, 0.04, -0.04),
            id,
            Vec3::new(0.06, 0.12, 0.06),
            1.0,
            1.0,
            vec![Deformation::Taper {
                rate_per_m: flex(lsh, 0, 1.0, 1.5),
            }],
        ),
        superellipsoid(
            "right_latissimus",
            thorax,
            Vec3::new(-0.09, 0.04, -0.04),
            id,
            Vec3::new(0.06, 0.12, 0.06),
            1.0,
            1.0,
            vec![Deformation::Taper {
                rate_per_m: flex(rsh, 0, 1.0, -1.5),
            }],
        ),
        // 2 cylinders: the collar bones.
        cylinder(
            "left_clavicle",
            lsh,
            Vec3::new(-0.07, 0.01, 0.04),
            sideways,
            0.016,
            0.065,
        ),
        cylinder(
            "right_clavicle",
            rsh,
            Vec3::new(0.07, 0.01, 0.04),
            sideways,
            0.016,
            0.065,
        ),
    ];
    // 26 spheres: 12 vertebrae (inside the back muscles), then pairs.
    for k in 0..5 {
        shapes.push(sphere(
            &format!("vertebra_{k}"),
            lumbar,
            Vec3::new(0.0, -0.06 + 0.035 * k as f32, -0.07),
            0.018,
        ));
    }
    for k in 0..7 {
        shapes.push(sphere(
            &format!("vertebra_{}", k + 5),
            thorax,
            Vec3::new(0.0, 0.03 * k as f32, -0.08 + 0.004 * k as f32),
            0.018,
        ));
    }
    for (side, sx) in [("left", 1.0), ("right", -1.0)] {
        let shoulder = if sx > 0.0 { lsh } else { rsh };
        shapes.push(sphere(
            &format!("{side}_deltoid"),
            shoulder,
            Vec3::new(0.02 * sx, -0.015, 0.0),
            0.055,
        ));
        shapes.push(sphere(
            &format!("{side}_trapezius"),
            thorax,
            Vec3::new(0.085 * sx, 0.16, -0.03),
            0.05,
        ));
        shapes.push(sphere(
            &format!("{side}_iliac_crest"),
            pelvis,
            Vec3::new(0.11 * sx, 0.04, 0.0),
            0.05,
        ));
        shapes.push(sphere(
            &format!("{side}_lower_abdomen"),
            pelvis,
            Vec3::new(0.05 * sx, 0.05, 0.045),
            0.06,
        ));
        shapes.push(sphere(
            &format!("{side}_serratus"),
            thorax,
            Vec3::new(0.11 * sx, 0.01, 0.03),
            0.045,
        ));
        shapes.push(sphere(
            &format!("{side}_neck_muscle"),
            neck,
            Vec3::new(0.025 * sx, 0.04, 0.005),
            0.04,
        ));
        shapes.push(sphere(
            &format!("{side}_pectoralis_minor"),
            thorax,
            Vec3::new(0.1 * sx, 0.12, 0.025),
            0.045,
        ));
    }
    let s = &skeleton;
    let (fwd, side, twist) = (
        dof_at(s, lumbar, 0),
        dof_at(s, lumbar, 1),
        dof_at(s, lumbar, 2),
    );
    let (tf, ts, tt) = (
        dof_at(s, thorax, 0),
        dof_at(s, thorax, 1),
        dof_at(s, thorax, 2),
    );
    let (nf, ny) = (dof_at(s, neck, 0), dof_at(s, neck, 1));
    let (l, r) = (dof_at(s, lsh, 0), dof_at(s, rsh, 0));
    let bend_twist = Motion {
        name: "bend_twist".into(),
        keys: vec![
            key(s, 0.0, Vec3::ZERO, &[]),
            key(s, 0.75, Vec3::ZERO, &[(fwd, 30.0), (tf, 20.0), (nf, 20.0)]),
            key(
                s,
                1.5,
                Vec3::ZERO,
                &[(twist, 25.0), (tt, 20.0), (ny, 30.0), (l, 20.0)],
            ),
            key(s, 2.25, Vec3::ZERO, &[(side, 18.0), (ts, 12.0), (r, -20.0)]),
            key(
                s,
                3.0,
                Vec3::ZERO,
                &[(twist, -25.0), (tt, -20.0), (ny, -30.0), (side, -10.0)],
            ),
            key(s, 3.75, Vec3::ZERO, &[]),
        ],
        extrapolation: Extrapolation::Loop,
    };
    Body {
        name: "torso",
        skeleton,
        shapes,
        motions: vec![bend_twist],
        tube: Tube {
            bottom_joint: pelvis,
            top_joint: neck,
            // From the hips (8 cm below the pelvis joint) to a neck ring 9.5 cm above the
            // neck joint, above every shape of the neck.
            start_m: Vec3::new(0.0, 0.87, 0.0),
            end_m: Vec3::new(0.0, 1.555, -0.01),
            zero_dir: Vec3::X,
            radius: Radius::Wrap {
                bottom_radius_m: None,
                top_radius_m: Some(0.075),
            },
            fat_m: |s, angle| 0.008 + 0.008 * (1.0 - s) * (0.5 + 0.5 * angle.sin()),
            smooth_passes: 12,
            rows: RowPlacement::Even,
        },
        simulation: example_simulation(),
    }
}

// ----------------------------------------------------------------------------------------
// Arm: two 0.30 m bones, capsules of radius 0.05 m, a 0.06 m sphere at the elbow, a skin tube of
// radius 0.08 m fixed at the shoulder and the wrist; motion "bend": elbow 0° -> 90° -> 0° in 2 s.

/// The arm's fat thickness, metres, at `s` along the skin (0 at the shoulder, 1 at the wrist)
/// and `angle` around it (radians from +Y, the side the elbow bends towards): 15 mm, thinning
/// to 5 mm in the elbow's crease (the thinning falls to 1/e about 7 cm either side of the elbow
/// along the arm and to half about 66° either side of the crease around it), as the skin inside
/// a real elbow carries little fat.
///
/// With 15 mm everywhere, the skin squeezed into the crease as the elbow bent had its fat
/// points 15 mm in along normals that every push turned, and the re-check passes pushed it
/// back and forth between the bones (`docs/simulate.md`, "Fat on fine skins"): on a 64×64 skin,
/// 3 s of the `bend` motion took 1262 steps with 337 constraint rejections and 56 forced steps;
/// with the crease thinned, 553, 27 and 8 (thinning the outside of the elbow instead: 1310,
/// 382 and 90). The 32×32 arm went from 462 steps to 314.
fn arm_fat_m(s: f32, angle: f32) -> f32 {
    const FAT_M: f32 = 0.015;
    const CREASE_THINNING_M: f32 = 0.010;
    const CREASE_HALF_WIDTH: f32 = 0.12;
    let along = (-((s - 0.5) / CREASE_HALF_WIDTH).powi(2)).exp();
    let around = (0.5 + 0.5 * angle.cos()).powi(2);
    FAT_M - CREASE_THINNING_M * along * around
}

fn arm() -> Body {
    let mut b = SkeletonBuilder::new();
    let shoulder = b.joint("shoulder", None, Vec3::new(0.0, 1.2, 0.0), &[]);
    let elbow = b.joint(
        "elbow",
        Some(shoulder),
        Vec3::new(0.3, 0.0, 0.0),
        &[dof(Vec3::Z, 0.0, 150.0)],
    );
    let wrist = b.joint("wrist", Some(elbow), Vec3::new(0.3, 0.0, 0.0), &[]);
    let skeleton = b.build();
    let along_x = Quat::from_rotation_z(-FRAC_PI_2);
    let shapes = vec![
        sphere("shoulder_cap", shoulder, Vec3::ZERO, 0.05),
        cylinder(
            "upper_bone",
            shoulder,
            Vec3::new(0.15, 0.0, 0.0),
            along_x,
            0.05,
            0.15,
        ),
        sphere("elbow", elbow, Vec3::ZERO, 0.06),
        cylinder(
            "lower_bone",
            elbow,
            Vec3::new(0.15, 0.0, 0.0),
            along_x,
            0.05,
            0.15,
        ),
        sphere("wrist_cap", wrist, Vec3::ZERO, 0.05),
    ];
    let e = dof_at(&skeleton, elbow, 0);
    let bend = Motion {
        name: "bend".into(),
        keys: vec![
            key(&skeleton, 0.0, Vec3::ZERO, &[]),
            key(&skeleton, 1.0, Vec3::ZERO, &[(e, 90.0)]),
            key(&skeleton, 2.0, Vec3::ZERO, &[]),
        ],
        extrapolation: Extrapolation::Loop,
    };
    Body {
        name: "arm",
        skeleton,
        shapes,
        motions: vec![bend],
        tube: Tube {
            bottom_joint: shoulder,
            top_joint: wrist,
            start_m: Vec3::new(0.0, 1.2, 0.0),
            end_m: Vec3::new(0.6, 1.2, 0.0),
            zero_dir: Vec3::Y,
            radius: Radius::Constant(0.08),
            fat_m: arm_fat_m,
            smooth_passes: 0,
            rows: RowPlacement::Even,
        },
        // Explicit Euler grows every lightly damped mode whose `h ω²` exceeds its damping rate;
        // the other 16×16 examples' damping absorbs that at 0.5 ms, the arm's light skin does
        // not: at 0.5 ms the 32×32 arm diverged after 4.7 s of its motion (5.3 s at rest), at
        // 0.4 ms after 12.9 s; 0.35 ms ran 60 s and 0.3 ms 120 s without diverging (session
        // 28), but its skin still rang at 0.25 ms: the 32×32 arm takes
        // `EXAMPLE_EULER_STEP_32_S`, this is the 16×16 arm's step.
        simulation: SimulationDefaults {
            euler_step_s: 0.000_25,
            ..example_simulation()
        },
    }
}

// ----------------------------------------------------------------------------------------
// Skin wrapping, materials and attachment.

fn inside_any(instances: &[ShapeInstance], p: Vec3) -> bool {
    instances.iter().any(|s| s.contains_world(p))
}

/// Distance from `origin` along `dir` to the outermost muscle surface within `t_max`, if any.
fn outermost_hit(instances: &[ShapeInstance], origin: Vec3, dir: Vec3, t_max: f32) -> Option<f32> {
    const STEP: f32 = 0.002;
    let steps = (t_max / STEP).ceil() as u32;
    for k in (0..steps).rev() {
        let t = k as f32 * STEP;
        if inside_any(instances, origin + dir * t) {
            let (mut lo, mut hi) = (t, t + STEP);
            for _ in 0..24 {
                let mid = 0.5 * (lo + hi);
                if inside_any(instances, origin + dir * mid) {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            return Some(hi);
        }
    }
    None
}

/// Axial fractions (0 at the tube's start, 1 at its end) of `along` rows spaced evenly along a
/// measure of the tube's profile. `ring(s)` gives the ring at `s`, sampled at
/// [`PROFILE_STATIONS_PER_ROW`] stations per row interval; between neighbouring stations the
/// measure grows by the mean of their axial distance and the longest distance between matching
/// ring points (the axial half leaves the ends fewer rows than the longest distance alone
/// would, and more for the body), smoothed over one row interval either side (so that the
/// spacing changes gradually from row to row: unsmoothed, a 32×31 resampling of the 16×16
/// wombat differed from its rest metric by more than 12 % at some coincident points, smoothed
/// by at most 10.9 %).
/// A rounded end gets short spokes from it; an end where a muscle comes close to a small end
/// ring does not (the penguin's tail: its first rows crowd over the tail with their fat
/// normals along the axis, and the generator's push-out cannot get them out).
fn profile_rows(along: u32, axis_length_m: f32, ring: impl Fn(f32) -> Vec<Vec3>) -> Vec<f32> {
    let stations = (PROFILE_STATIONS_PER_ROW * (along - 1)) as usize;
    let station_s = |f: usize| f as f32 / stations as f32;
    let axial_m = axis_length_m / stations as f32;
    let mut previous = ring(0.0);
    let raw: Vec<f32> = (1..=stations)
        .map(|f| {
            let next = ring(station_s(f));
            let longest = previous
                .iter()
                .zip(&next)
                .map(|(a, b)| a.distance(*b))
                .fold(0.0f32, f32::max);
            previous = next;
            0.5 * (axial_m + longest)
        })
        .collect();
    let window = PROFILE_STATIONS_PER_ROW as usize;
    let mut arc = Vec::with_capacity(stations + 1);
    arc.push(0.0f32);
    for f in 0..stations {
        let near = &raw[f.saturating_sub(window)..(f + window + 1).min(stations)];
        arc.push(arc[f] + near.iter().sum::<f32>() / near.len() as f32);
    }
    let total = arc[stations];
    let mut f = 0usize;
    (0..along)
        .map(|j| {
            if j == 0 {
                return 0.0;
            }
            if j + 1 == along {
                return 1.0;
            }
            let target = total * j as f32 / (along - 1) as f32;
            while arc[f + 1] < target {
                f += 1;
            }
            let within = (target - arc[f]) / (arc[f + 1] - arc[f]);
            (f as f32 + within) / stations as f32
        })
        .collect()
}

fn finish(body: Body, around: u32, along: u32) -> Character {
    let Body {
        name,
        skeleton,
        shapes,
        motions,
        tube,
        simulation,
    } = body;
    let simulation = SimulationDefaults {
        euler_step_s: example_euler_step_s(simulation.euler_step_s, around, along),
        ..simulation
    };
    let posture = Posture::neutral(&skeleton);
    let pose = skeleton.forward_kinematics(&posture);
    let mut character = Character {
        name: name.to_string(),
        skeleton,
        shapes,
        skin: Skin {
            around,
            along,
            bottom_joint: tube.bottom_joint,
            top_joint: tube.top_joint,
            bottom_ring_m: Vec::new(),
            top_ring_m: Vec::new(),
            positions_m: Vec::new(),
            mass_kg: Vec::new(),
            damping_n_s_per_m: Vec::new(),
            rest_metric: Vec::new(),
            stretch: Vec::new(),
            bending: Vec::new(),
            fat_m: Vec::new(),
        },
        tissue: Vec::new(),
        simulation,
        motions,
    };
    let mut instances = Vec::new();
    character.shape_instances_into(&posture, &pose, 0.0, &mut instances);

    // Ring frame: e1 = zero_dir, e2 = e1 × axis, so that ∂r/∂u₂ × ∂r/∂u₁ points outwards.
    let axis = (tube.end_m - tube.start_m).normalize();
    let e1 = (tube.zero_dir - axis * tube.zero_dir.dot(axis)).normalize();
    let e2 = e1.cross(axis);
    let n_points = (around * along) as usize;
    let mut radius = vec![0.0f32; n_points];
    let mut fat = vec![0.0f32; n_points];
    let dirs: Vec<Vec3> = (0..around)
        .map(|i| {
            let phi = TAU * i as f32 / around as f32;
            e1 * phi.cos() + e2 * phi.sin()
        })
        .collect();
    // The radius of the ring at `s` along the axis in direction `i`: what keeps its fat layer
    // outside every muscle, or the end ring's given radius.
    let ring_radius = |s: f32, i: u32| -> f32 {
        let end_radius = match tube.radius {
            Radius::Wrap {
                bottom_radius_m, ..
            } if s == 0.0 => bottom_radius_m,
            Radius::Wrap { top_radius_m, .. } if s == 1.0 => top_radius_m,
            _ => None,
        };
        match (tube.radius, end_radius) {
            (Radius::Constant(r), _) | (_, Some(r)) => r,
            (Radius::Wrap { .. }, None) => {
                let centre = tube.start_m.lerp(tube.end_m, s);
                let fat = (tube.fat_m)(s, TAU * i as f32 / around as f32);
                let hit = outermost_hit(&instances, centre, dirs[i as usize], 0.5);
                hit.map_or(MIN_RADIUS_M, |t| t + fat + WRAP_MARGIN_M)
                    .max(MIN_RADIUS_M)
            }
        }
    };
    let row_s = match tube.rows {
        RowPlacement::Even => (0..along).map(|j| j as f32 / (along - 1) as f32).collect(),
        RowPlacement::Profile => profile_rows(along, tube.start_m.distance(tube.end_m), |s| {
            let centre = tube.start_m.lerp(tube.end_m, s);
            (0..around)
                .map(|i| centre + dirs[i as usize] * ring_radius(s, i))
                .collect()
        }),
    };
    for (j, &s) in (0..along).zip(&row_s) {
        for i in 0..around {
            let k = (j * around + i) as usize;
            fat[k] = (tube.fat_m)(s, TAU * i as f32 / around as f32);
            radius[k] = ring_radius(s, i);
        }
    }
    let required = radius.clone();
    // Smooth the wrapped radii a little (never below what keeps the fat layer outside).
    if matches!(tube.radius, Radius::Wrap { .. }) {
        for _ in 0..tube.smooth_passes {
            let old = radius.clone();
            for j in 1..along - 1 {
                for i in 0..around {
                    let k = (j * around + i) as usize;
                    let left = old[(j * around + (i + around - 1) % around) as usize];
                    let right = old[(j * around + (i + 1) % around) as usize];
                    let down = old[((j - 1) * around + i) as usize];
                    let up = old[((j + 1) * around + i) as usize];
                    let avg = 0.4 * old[k] + 0.15 * (left + right + down + up);
                    radius[k] = avg.max(required[k]);
                }
            }
        }
    }
    let position = |radius: &[f32], k: usize| {
        let (i, j) = ((k as u32) % around, (k as u32) / around);
        tube.start_m.lerp(tube.end_m, row_s[j as usize]) + dirs[i as usize] * radius[k]
    };
    let mut positions: Vec<Vec3> = (0..n_points).map(|k| position(&radius, k)).collect();
    // Push out any free point whose fat point (r − τ·n̂) is still inside a muscle.
    let skin_probe = Skin {
        around,
        along,
        ..character.skin.clone()
    };
    let mut normals = Vec::new();
    for _ in 0..20 {
        skin_probe.fat_normals(&positions, &mut normals);
        let mut moved = false;
        for k in 0..n_points {
            let j = k as u32 / around;
            if j == 0 || j + 1 == along {
                continue;
            }
            let fat_point = positions[k] - normals[k] * fat[k];
            if inside_any(&instances, fat_point) {
                radius[k] += 0.002;
                positions[k] = position(&radius, k);
                moved = true;
            }
        }
        if !moved {
            break;
        }
    }
    let bottom = pose.world_from(tube.bottom_joint).inverse();
    let top = pose.world_from(tube.top_joint).inverse();
    let last = (along - 1) * around;
    let bottom_ring: Vec<Vec3> = (0..around)
        .map(|i| bottom.transform_point(positions[i as usize]))
        .collect();
    let top_ring: Vec<Vec3> = (0..around)
        .map(|i| top.transform_point(positions[(last + i) as usize]))
        .collect();
    // Store the fixed rows exactly as their joints will reproduce them.
    let world_bottom = pose.world_from(tube.bottom_joint);
    let world_top = pose.world_from(tube.top_joint);
    for i in 0..around as usize {
        positions[i] = world_bottom.transform_point(bottom_ring[i]);
        positions[last as usize + i] = world_top.transform_point(top_ring[i]);
    }

    let mats = materials(name);
    let point_mass = mats.skin_mass_kg / n_points as f32;
    let mut skin = Skin {
        around,
        along,
        bottom_joint: tube.bottom_joint,
        top_joint: tube.top_joint,
        bottom_ring_m: bottom_ring,
        top_ring_m: top_ring,
        positions_m: Vec::new(),
        mass_kg: vec![point_mass; n_points],
        damping_n_s_per_m: vec![point_mass * mats.damping_per_s; n_points],
        rest_metric: Vec::new(),
        stretch: Vec::new(),
        bending: vec![[mats.bending; 3]; n_points],
        fat_m: fat,
    };
    let metric = skin.metric_of(&positions);
    let shrink2 = mats.rest_shrink * mats.rest_shrink;
    skin.rest_metric = metric
        .iter()
        .map(|g| [g[0] * shrink2, g[1] * shrink2, g[2] * shrink2])
        .collect();
    // η so that one point's stretch stiffness 8·η·G⁰·h_j/h_i gives ω at 32×32.
    let reference_mass = mats.skin_mass_kg / (32.0 * 32.0);
    let k_target = reference_mass * mats.stretch_omega_rad_per_s * mats.stretch_omega_rad_per_s;
    let mean_g11 = skin.rest_metric.iter().map(|g| g[0]).sum::<f32>() / n_points as f32;
    let mean_g22 = skin.rest_metric.iter().map(|g| g[2]).sum::<f32>() / n_points as f32;
    let eta11 = k_target / (8.0 * mean_g11 * (1.0 / 31.0) / (1.0 / 32.0));
    let eta22 = k_target / (8.0 * mean_g22 * (1.0 / 32.0) / (1.0 / 31.0));
    let eta12 = mats.shear_fraction * 0.5 * (eta11 + eta22);
    skin.stretch = vec![[eta11, eta12, eta22]; n_points];
    skin.positions_m = positions;
    character.skin = skin;

    let k_s = point_mass * mats.tissue_omega_rad_per_s * mats.tissue_omega_rad_per_s;
    let k_d = 2.0 * mats.tissue_damping_ratio * (k_s * point_mass).sqrt();
    character.tissue = attach_global(
        &character,
        &AttachParams {
            stiffness_n_per_m: k_s,
            damping_n_s_per_m: k_d,
            rest_length_scale: 1.0,
            max_ray_m: 0.3,
        },
    );
    character
}

#[cfg(test)]
mod tests {
    use super::*;

    fn count(c: &Character) -> (usize, usize, usize) {
        let mut n = (0, 0, 0);
        for s in &c.shapes {
            match s.primitive {
                Primitive::Sphere { .. } => n.0 += 1,
                Primitive::Superellipsoid { .. } => n.1 += 1,
                Primitive::Cylinder { .. } => n.2 += 1,
            }
        }
        n
    }

    #[test]
    fn examples_match_table_1_and_validate() {
        let want = [
            ("penguin", (7, 0, 0)),
            ("wombat", (2, 5, 1)),
            ("torso", (26, 12, 2)),
            ("arm", (3, 0, 2)),
        ];
        for (name, shapes) in want {
            let c = build(name, 16, 16).expect("known example");
            assert_eq!(count(&c), shapes, "{name}");
            c.validate().expect("valid");
            assert_eq!(c.skin.point_count(), 256);
            assert_eq!(c.tissue.len(), 256, "{name}: one spring per point");
            assert!(!c.motions.is_empty());
        }
    }
}

#[cfg(test)]
mod file_tests {
    use super::*;

    #[test]
    fn committed_assets_equal_the_generator_and_round_trip_exactly() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/characters");
        for name in NAMES {
            for (res, suffix) in RESOLUTIONS {
                let c = build(name, res, res).expect("known example");
                let text = c.to_toml_string();
                let path = dir.join(format!("{name}{suffix}.toml"));
                let committed = std::fs::read_to_string(&path).expect("asset file exists");
                assert!(
                    committed == text,
                    "{} differs from the generator: run `cargo run --example make_characters`",
                    path.display()
                );
                let loaded = Character::load(&path).expect("asset loads");
                assert_eq!(loaded, c, "{name}{suffix}: load(save(c)) == c");
            }
        }
    }

    #[test]
    fn skins_start_outside_the_muscles_by_their_fat() {
        for name in NAMES {
            let c = build(name, 32, 32).expect("known example");
            let (instances, points) = c.neutral_layout();
            for (k, &(p, normal)) in points.iter().enumerate() {
                if c.skin.is_fixed(k) {
                    continue;
                }
                let fat_point = p - normal * c.skin.fat_m[k];
                for (s, inst) in instances.iter().enumerate() {
                    assert!(
                        inst.value_world(fat_point) >= 0.0,
                        "{name}: point {k} fat point inside shape {s} ({})",
                        c.shapes[s].name
                    );
                }
            }
            // Outward normals point away from the body axis on average.
            let centre =
                c.skin.positions_m.iter().copied().sum::<Vec3>() / c.skin.point_count() as f32;
            let outward = points
                .iter()
                .filter(|(p, n)| (*p - centre).dot(*n) > 0.0)
                .count();
            assert!(
                outward * 10 > c.skin.point_count() * 8,
                "{name}: normals mostly outward"
            );
        }
    }

    #[test]
    fn skins_reach_past_every_muscle_along_their_axis() {
        // A skin closed by small rings at both ends (the penguin's and the wombat's) covers
        // the whole muscle layer: along the line from the bottom ring's centre to the top
        // ring's, every shape's surface lies between the two rings. (The torso and the arm are
        // open tubes, cut at the hips, the neck, the shoulder and the wrist, where muscles may
        // reach past the rings.) Until session 36 the wombat's skin ended at its head's
        // centre, 12 cm short of its snout's tip, with its nose ring inside the head.
        let closed: Vec<&str> = NAMES
            .into_iter()
            .filter(|name| {
                let tube = body(name).expect("known example").tube;
                matches!(
                    tube.radius,
                    Radius::Wrap {
                        bottom_radius_m: Some(_),
                        top_radius_m: Some(_)
                    }
                )
            })
            .collect();
        assert_eq!(closed, ["penguin", "wombat"], "the closed skins");
        for name in closed {
            let c = build(name, 32, 32).expect("known example");
            let (instances, _) = c.neutral_layout();
            let skin = &c.skin;
            let bottom = skin.ring_center(&skin.positions_m, 0);
            let top = skin.ring_center(&skin.positions_m, skin.along - 1);
            let length = (top - bottom).length();
            let axis = (top - bottom) / length;
            // Surface points of each shape: projections of points on a large sphere around it.
            let directions: Vec<Vec3> = (0..400)
                .map(|k| {
                    let z = 1.0 - 2.0 * (k as f32 + 0.5) / 400.0;
                    let phi = k as f32 * 2.399_963;
                    let r = (1.0 - z * z).sqrt();
                    Vec3::new(r * phi.cos(), r * phi.sin(), z)
                })
                .collect();
            for (shape, inst) in c.shapes.iter().zip(&instances) {
                for d in &directions {
                    let far = inst.bound_center_world_m + *d * 2.0 * inst.bound_radius_m;
                    let surface = inst.project_world(far);
                    let t = (surface - bottom).dot(axis);
                    assert!(
                        (0.0..=length).contains(&t),
                        "{name}: shape {} reaches {:.3} m along the skin's axis, outside its \
                         rings (0 to {length:.3} m)",
                        shape.name,
                        t
                    );
                }
            }
        }
    }

    /// Ring points of one fixed row, each with its fat point moved in by `margin_m` more, in
    /// the row's joint frame: `(point, inward unit vector, fat + margin)`.
    fn ring_probes(c: &Character, top: bool, margin_m: f32) -> Vec<(Vec3, Vec3, f32)> {
        let ring = if top {
            &c.skin.top_ring_m
        } else {
            &c.skin.bottom_ring_m
        };
        let row = if top { c.skin.along - 1 } else { 0 };
        let centre = ring.iter().copied().sum::<Vec3>() / ring.len() as f32;
        ring.iter()
            .enumerate()
            .map(|(i, p)| {
                let k = (row * c.skin.around) as usize + i;
                let inward = (centre - *p).normalize_or_zero();
                (*p, inward, c.skin.fat_m[k] + margin_m)
            })
            .collect()
    }

    #[test]
    fn fixed_rings_stay_outside_every_shape_through_the_motion() {
        // The fixed rows cannot be pushed out of a muscle, so each ring point's fat point (and
        // 2 mm more) must stay outside every shape at every posture of every motion.
        const MARGIN_M: f32 = 0.002;
        let mut failures = Vec::new();
        for name in NAMES {
            let c = build(name, 32, 32).expect("known example");
            let bottom = ring_probes(&c, false, MARGIN_M);
            let top = ring_probes(&c, true, MARGIN_M);
            let mut instances = Vec::new();
            for m in &c.motions {
                let samples = 150;
                for step in 0..=samples {
                    let t = m.pass_s() * f64::from(step) / f64::from(samples);
                    let posture = m.posture_at(t);
                    let pose = c.skeleton.forward_kinematics(&posture);
                    c.shape_instances_into(&posture, &pose, t as f32, &mut instances);
                    for (joint, probes, which) in [
                        (c.skin.bottom_joint, &bottom, "bottom"),
                        (c.skin.top_joint, &top, "top"),
                    ] {
                        let world = pose.world_from(joint);
                        for (i, (p, inward, depth)) in probes.iter().enumerate() {
                            let q = world.transform_point(*p + *inward * *depth);
                            for (s, inst) in instances.iter().enumerate() {
                                if inst.value_world(q) <= 0.0 {
                                    failures.push(format!(
                                        "{name}/{} t={t:.3}: {which} ring point {i} (fat point + \
                                         {MARGIN_M} m) inside shape {}",
                                        m.name, c.shapes[s].name
                                    ));
                                }
                            }
                        }
                    }
                }
            }
        }
        for f in failures.iter().take(20) {
            eprintln!("{f}");
        }
        assert!(
            failures.is_empty(),
            "{} ring probes inside shapes",
            failures.len()
        );
    }

    #[test]
    fn rest_state_has_every_fat_point_outside_the_muscles() {
        // As the simulator sees it (its own normals): nothing to push out at t = 0.
        for name in NAMES {
            for (res, _) in RESOLUTIONS {
                let c = build(name, res, res).expect("known example");
                let sim =
                    crate::sim::surface::SurfaceModel::new(c, crate::sim::IntegratorKind::Verlet)
                        .expect("valid example");
                let depth = sim.max_depth_m();
                assert!(depth < 1e-4, "{name} {res}x{res}: rest depth {depth} m");
            }
        }
    }

    #[test]
    fn every_motion_moves_the_skeleton() {
        for name in NAMES {
            let c = build(name, 16, 16).expect("known example");
            for m in &c.motions {
                let a = c.skeleton.forward_kinematics(&m.posture_at(0.0));
                let quarter = m.pass_s() * 0.25;
                let b = c.skeleton.forward_kinematics(&m.posture_at(quarter));
                let moved = a
                    .world_from_joint
                    .iter()
                    .zip(&b.world_from_joint)
                    .map(|(x, y)| {
                        (x.position_m - y.position_m).length()
                            + (x.orientation.dot(y.orientation).abs() - 1.0).abs()
                    })
                    .fold(0.0, f32::max);
                assert!(
                    moved > 1e-3,
                    "{name}/{}: the skeleton does not move",
                    m.name
                );
            }
        }
        // The arm's bend: 0° at 0 s, 90° at 1 s, back at 2 s.
        let arm = build("arm", 16, 16).expect("arm");
        let bend = arm.motion("bend").expect("bend");
        assert!((bend.posture_at(1.0).angles_rad[0] - FRAC_PI_2).abs() < 1e-6);
        assert!(bend.posture_at(2.0).angles_rad[0].abs() < 1e-6);
        assert!((bend.posture_at(3.0).angles_rad[0] - FRAC_PI_2).abs() < 1e-5);
    }
}
