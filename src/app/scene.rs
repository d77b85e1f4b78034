//! Building the renderer's [`Scene`] from the app's state: the character's skin (as the
//! simulation left it), its muscle and bone shapes and skeleton for the current posture, the
//! wand, the calibrated screen's border and a floor grid.
//!
//! Everything is expressed in the physical frame of the calibrated screen (the vehicle frame):
//! the character is carried there by `vehicle_from_world`, while the head, the wand and the
//! screen already live there. So the stereo module's views (made in the calibration's frame)
//! apply unchanged.

use crate::app::skin_display;
use crate::character::resample::resample_field;
use crate::character::{Character, Posture, ShapeInstance, SkeletonPose};
use crate::pose::Pose;
use crate::render::adapter::{TessellationDetail, kind_from_name, tessellate_primitive};
use crate::render::mesh::TriMesh;
use crate::render::scene::{
    FloorGrid, Layers, Rgba, Scene, Segment, ShapeInstance as RenderShape, ShapeKind,
    SkeletonLines, SkinSurface, ToolCursor, Wand,
};
use crate::render::subdivide;
use glam::{Mat4, Vec3};
use std::sync::Arc;

/// Tessellations of each shape's undeformed primitive, made once per character.
#[derive(Debug, Clone, Default)]
pub struct ShapeMeshes {
    rest: Vec<Arc<TriMesh>>,
}

impl ShapeMeshes {
    /// Tessellates every shape of `character`.
    pub fn new(character: &Character) -> Self {
        Self {
            rest: character
                .shapes
                .iter()
                .map(|s| {
                    Arc::new(tessellate_primitive(
                        &s.primitive,
                        TessellationDetail::default(),
                    ))
                })
                .collect(),
        }
    }
}

/// Triangles of an `around × along` skin grid, periodic around, oriented so their normals point
/// out of the body (the skin's `∂r/∂u₂ × ∂r/∂u₁` convention).
pub fn skin_indices(around: u32, along: u32) -> Vec<u32> {
    let mut indices = Vec::new();
    if around < 3 || along < 2 {
        return indices;
    }
    let at = |i: u32, j: u32| j * around + (i % around);
    for j in 0..along - 1 {
        for i in 0..around {
            let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
            indices.extend_from_slice(&[a, d, b, b, d, c]);
        }
    }
    indices
}

/// What one frame's scene is made from.
#[derive(Debug, Clone, Copy)]
pub struct SceneInputs<'a> {
    /// The character.
    pub character: &'a Character,
    /// Its tessellated shapes.
    pub shape_meshes: &'a ShapeMeshes,
    /// The posture being shown.
    pub posture: &'a Posture,
    /// Every joint's world transform for that posture.
    pub skeleton_pose: &'a SkeletonPose,
    /// The motion time (for time-keyed shape parameters), seconds.
    pub time_s: f32,
    /// The skin's points in the world (the simulation's state), `around × along` of them.
    pub skin_positions_world: &'a [Vec3],
    /// Skin grid size.
    pub skin_grid: (u32, u32),
    /// World to the physical (screen) frame.
    pub vehicle_from_world: Pose,
    /// The wand in the physical frame, if any.
    pub wand_physical: Option<Pose>,
    /// Screen corners in the physical frame.
    pub screen_corners: [Vec3; 4],
    /// Layer toggles.
    pub layers: Layers,
    /// Skin opacity (1 = opaque).
    pub skin_opacity: f32,
}

/// The scene for one frame.
pub fn build_scene(inputs: &SceneInputs<'_>) -> Scene {
    let vehicle_from_world = inputs.vehicle_from_world.to_mat4();
    let to_physical = |p: Vec3| inputs.vehicle_from_world.transform_point(p);
    let character = inputs.character;

    // The shapes placed and deformed for this posture: drawn, and read by the skin's display
    // clearance and the tissue springs.
    let mut instances = Vec::with_capacity(character.shapes.len());
    character.shape_instances_into(
        inputs.posture,
        inputs.skeleton_pose,
        inputs.time_s,
        &mut instances,
    );

    let (around, along) = inputs.skin_grid;
    let skin = (inputs.skin_positions_world.len() == around as usize * along as usize
        && around >= 3
        && along >= 2)
        .then(|| {
            // Drawn as a smooth surface through the simulated points, so coarse skins do not
            // cut chords through the muscles under them (render::subdivide), and kept outside
            // the muscles where a muscle bulges between the points (skin_display).
            let level = subdivide::display_level(around);
            let (rm, rn) = subdivide::refined_size(around, along, level);
            let mut refined =
                subdivide::refine_skin_grid(inputs.skin_positions_world, around, along, level);
            // Unrefined (64 points around or more), the drawn points are the simulated ones,
            // which the simulation keeps outside, and the chords between them are short.
            if level > 1 {
                let skin = &character.skin;
                let fat = resample_field(&skin.fat_m, skin.around, skin.along, rm, rn);
                let (rm, rn) = (rm as usize, rn as usize);
                skin_display::keep_outside(&mut refined, rm, rn, &fat, &instances);
            }
            let positions = refined.into_iter().map(to_physical).collect();
            SkinSurface {
                mesh: TriMesh::from_triangles(positions, skin_indices(rm, rn)),
                color: Rgba::SKIN.with_alpha(inputs.skin_opacity.clamp(0.05, 1.0)),
            }
        });

    let mut shapes = Vec::with_capacity(character.shapes.len());
    for (k, (shape, instance)) in character.shapes.iter().zip(&instances).enumerate() {
        let Some(rest) = inputs.shape_meshes.rest.get(k) else {
            continue;
        };
        let world_from_shape = Mat4::from(instance.world_from_shape);
        let mesh = if instance.geometry.is_undeformed() {
            Arc::clone(rest)
        } else {
            let positions = rest
                .positions
                .iter()
                .map(|&p| instance.geometry.deform(p))
                .collect();
            Arc::new(TriMesh::from_triangles(positions, rest.indices.clone()))
        };
        let kind = kind_from_name(&shape.name);
        shapes.push(RenderShape {
            mesh,
            world_from_shape: vehicle_from_world * world_from_shape,
            color: match kind {
                ShapeKind::Bone => Rgba::BONE,
                ShapeKind::Muscle => Rgba::MUSCLE,
            },
            kind,
        });
    }

    let joints: Vec<Vec3> = inputs
        .skeleton_pose
        .world_from_joint
        .iter()
        .map(|p| to_physical(p.position_m))
        .collect();
    let bones = character
        .skeleton
        .joints
        .iter()
        .enumerate()
        .filter_map(|(k, j)| {
            let parent = j.parent?;
            Some(Segment {
                a: *joints.get(parent.index())?,
                b: *joints.get(k)?,
            })
        })
        .collect();

    let springs = if inputs.layers.springs {
        tissue_segments(inputs, &instances)
    } else {
        Vec::new()
    };
    let fat_points = if inputs.layers.fat {
        inputs
            .skin_positions_world
            .iter()
            .zip(&character.skin.fat_m)
            .filter(|(_, f)| **f > 0.0)
            .map(|(p, _)| to_physical(*p))
            .collect()
    } else {
        Vec::new()
    };

    let (wand, cursor) = match inputs.wand_physical {
        Some(w) if w.is_valid() => {
            let forward = w.transform_vector(-Vec3::Z);
            (
                Some(Wand {
                    world_from_wand: w.to_mat4(),
                    length_m: 0.08,
                }),
                Some(ToolCursor {
                    position: w.position_m,
                    radius_m: 0.01,
                    ray: Some((w.position_m, forward, 0.05)),
                    color: Rgba::CURSOR,
                }),
            )
        }
        _ => (None, None),
    };

    // Floor under the character's lowest joint (horizontal in the physical frame).
    let floor_grid = joints
        .iter()
        .copied()
        .reduce(|a, b| if b.y < a.y { b } else { a })
        .map(|lowest| {
            let centre = joints.iter().copied().sum::<Vec3>() / joints.len().max(1) as f32;
            FloorGrid {
                centre: Vec3::new(centre.x, lowest.y - 0.05, centre.z),
                half_extent_m: 0.6,
                spacing_m: 0.1,
            }
        });

    Scene {
        layers: inputs.layers,
        background: Rgba::BACKGROUND,
        skin,
        shapes,
        skeleton: SkeletonLines {
            bones,
            joints,
            joint_radius_m: 0.008,
        },
        springs,
        fat_points,
        fat_point_size_m: 0.004,
        wand,
        cursor,
        screen_corners: Some(inputs.screen_corners),
        floor_grid,
        extra_lines: Vec::new(),
        key_light_direction: Vec3::new(0.3, 1.0, 0.6),
    }
}

fn tissue_segments(inputs: &SceneInputs<'_>, instances: &[ShapeInstance]) -> Vec<Segment> {
    let character = inputs.character;
    let mut out = Vec::with_capacity(character.tissue.len());
    for spring in &character.tissue {
        let (Some(p), Some(shape)) = (
            inputs.skin_positions_world.get(spring.skin_point as usize),
            instances.get(spring.shape.index()),
        ) else {
            continue;
        };
        let anchor = shape.rest_point_to_world(spring.anchor_rest_m);
        out.push(Segment {
            a: inputs.vehicle_from_world.transform_point(*p),
            b: inputs.vehicle_from_world.transform_point(anchor),
        });
    }
    out
}

/// The paper's torso (example `torso`, 32×32 skin) simulated with Verlet 0.7 s into its first
/// motion, shoulders raised, where its muscles bulge between the simulated points: the scene
/// state of the display tests and of the scene benchmark (`benches/scene.rs`).
pub struct BentTorso {
    /// The character.
    pub character: Character,
    /// Its tessellated shapes.
    pub shape_meshes: ShapeMeshes,
    /// The posture at [`Self::time_s`].
    pub posture: Posture,
    /// Every joint's world transform for it.
    pub skeleton_pose: SkeletonPose,
    /// The simulated skin points, world, metres.
    pub skin_positions_world: Vec<Vec3>,
    /// Skin grid size `(around, along)`.
    pub skin_grid: (u32, u32),
    /// Motion time, seconds.
    pub time_s: f32,
}

impl BentTorso {
    /// Builds and simulates it (`None` if the example is missing).
    pub fn new() -> Option<Self> {
        use crate::sim::surface::SurfaceModel;
        use crate::sim::{DeformationModel, IntegratorKind, MotionPoses, SurfaceMesh, Unlimited};
        let time_s = 0.7f32;
        let character = crate::character::examples::build("torso", 32, 32)?;
        let motion = character.motions.first()?.clone();
        let mut model = SurfaceModel::new(character.clone(), IntegratorKind::Verlet).ok()?;
        model.advance(
            f64::from(time_s),
            &mut MotionPoses(&motion),
            &mut Unlimited,
            None,
        );
        let mut surface = SurfaceMesh::default();
        model.surface_mesh_into(&mut surface);
        let mut posture = Posture::neutral(&character.skeleton);
        motion.posture_at_into(f64::from(time_s), &mut posture);
        let mut skeleton_pose = SkeletonPose::default();
        character
            .skeleton
            .forward_kinematics_into(&posture, &mut skeleton_pose);
        Some(Self {
            shape_meshes: ShapeMeshes::new(&character),
            character,
            posture,
            skeleton_pose,
            skin_positions_world: surface.positions_m,
            skin_grid: model.resolution(),
            time_s,
        })
    }

    /// The shapes placed and deformed for the posture.
    pub fn shapes(&self) -> Vec<ShapeInstance> {
        let mut shapes = Vec::new();
        self.character.shape_instances_into(
            &self.posture,
            &self.skeleton_pose,
            self.time_s,
            &mut shapes,
        );
        shapes
    }

    /// Scene inputs for it: the world as the physical frame, no wand, default layers.
    pub fn inputs(&self) -> SceneInputs<'_> {
        SceneInputs {
            character: &self.character,
            shape_meshes: &self.shape_meshes,
            posture: &self.posture,
            skeleton_pose: &self.skeleton_pose,
            time_s: self.time_s,
            skin_positions_world: &self.skin_positions_world,
            skin_grid: self.skin_grid,
            vehicle_from_world: Pose::IDENTITY,
            wand_physical: None,
            screen_corners: [Vec3::ZERO; 4],
            layers: Layers::default(),
            skin_opacity: 1.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::character::Primitive;

    #[test]
    fn skin_triangles_cover_the_grid_and_face_outward() {
        // A cylinder of radius 1 along +Y, points ordered as the skin's convention requires.
        let (m, n) = (8u32, 4u32);
        let mut positions = Vec::new();
        for j in 0..n {
            for i in 0..m {
                // Increasing i turns counter-clockwise seen from +Y (x toward z), so that
                // r_u2 × r_u1 = y × z = x is outward at i = 0.
                let a = (i as f32) / m as f32 * std::f32::consts::TAU;
                positions.push(Vec3::new(a.cos(), j as f32, a.sin()));
            }
        }
        let indices = skin_indices(m, n);
        assert_eq!(indices.len() as u32, m * (n - 1) * 6);
        let mesh = TriMesh::from_triangles(positions.clone(), indices);
        mesh.validate().expect("valid");
        for (p, nrm) in positions.iter().zip(&mesh.normals) {
            let radial = Vec3::new(p.x, 0.0, p.z).normalize();
            assert!(nrm.dot(radial) > 0.5, "normal {nrm} at {p} not outward");
        }
    }

    #[test]
    fn primitive_meshes_are_centred_and_sized() {
        let c = tessellate_primitive(
            &Primitive::Cylinder {
                radius_m: 0.05,
                half_length_m: 0.2,
            },
            TessellationDetail::default(),
        );
        let (lo, hi) = c.positions.iter().fold(
            (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)),
            |(lo, hi), p| (lo.min(*p), hi.max(*p)),
        );
        assert!((lo.y + 0.2).abs() < 1e-5 && (hi.y - 0.2).abs() < 1e-5);
        assert!((hi.x - 0.05).abs() < 1e-3);
        let s = tessellate_primitive(
            &Primitive::Sphere { radius_m: 0.1 },
            TessellationDetail::default(),
        );
        assert!(s.positions.iter().all(|p| (p.length() - 0.1).abs() < 1e-4));
    }

    #[test]
    fn bones_are_told_from_muscles_by_name() {
        assert_eq!(kind_from_name("left femur"), ShapeKind::Bone);
        assert_eq!(kind_from_name("Ribcage"), ShapeKind::Bone);
        assert_eq!(kind_from_name("biceps"), ShapeKind::Muscle);
    }

    #[test]
    fn the_drawn_skin_of_a_bent_torso_stays_outside_its_muscles() {
        let torso = BentTorso::new().expect("the torso example exists");
        let shapes = torso.shapes();
        // Deepest point of a drawn surface inside any muscle, metres.
        let deepest = |points: &[Vec3]| {
            let mut worst = 0.0f32;
            for p in points {
                for s in &shapes {
                    let local = s.shape_from_world.transform_point3(*p);
                    if s.geometry.value(local) < 0.0 {
                        worst = worst.max((s.geometry.project(local) - local).length());
                    }
                }
            }
            worst
        };
        let (m, n) = torso.skin_grid;
        let level = subdivide::display_level(m);
        let smooth = subdivide::refine_skin_grid(&torso.skin_positions_world, m, n, level);
        let before = deepest(&smooth);
        assert!(
            before > 2e-3,
            "the interpolated skin should cut the muscles here: {before} m"
        );
        let scene = build_scene(&torso.inputs());
        let drawn = &scene.skin.expect("the skin is drawn").mesh.positions;
        assert_eq!(drawn.len(), smooth.len());
        assert!(drawn.iter().all(|p| p.is_finite()));
        let after = deepest(drawn);
        assert!(
            after < 1e-4,
            "the drawn skin is still {after} m inside a muscle (was {before})"
        );
    }
}
