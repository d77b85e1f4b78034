//! Small adapters from other modules' plain data to the renderer's scene types: the character's
//! muscle/bone shapes (tessellated from their primitive parameters and deformed by their
//! resolved deformations) and the simulation's surface mesh. The renderer never calls into a
//! model: the app calls these with data it already has.

use std::sync::Arc;

use glam::{Mat4, Vec3};

use super::mesh::TriMesh;
use super::scene::{self, Rgba, ShapeKind, SkinSurface};
use crate::character::shape::{Primitive, ShapeGeometry};

/// How finely shapes are tessellated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TessellationDetail {
    /// Vertices around the polar (Y) axis.
    pub segments: u32,
    /// Rings from pole to pole (spheres, superellipsoids); cylinders use `rings` rows along Y so
    /// bends and tapers show.
    pub rings: u32,
}

impl Default for TessellationDetail {
    fn default() -> Self {
        Self {
            segments: 24,
            rings: 12,
        }
    }
}

/// The primitive tessellated in its rest space (centred on the origin, +Y the polar axis).
pub fn tessellate_primitive(primitive: &Primitive, detail: TessellationDetail) -> TriMesh {
    match *primitive {
        Primitive::Sphere { radius_m } => TriMesh::sphere(radius_m, detail.segments, detail.rings),
        Primitive::Superellipsoid { radii_m, e1, e2 } => {
            TriMesh::superellipsoid(radii_m, e1, e2, detail.segments, detail.rings)
        }
        Primitive::Cylinder {
            radius_m,
            half_length_m,
        } => {
            // Rows along the axis (so a bend or taper deforms it smoothly), then caps.
            let rows = detail.rings.max(1);
            let path: Vec<Vec3> = (0..=rows)
                .map(|i| Vec3::Y * (-half_length_m + 2.0 * half_length_m * i as f32 / rows as f32))
                .collect();
            let mut side = TriMesh::tube(&path, &vec![radius_m; path.len()], detail.segments);
            let caps = TriMesh::cylinder(radius_m, 2.0 * half_length_m, detail.segments)
                .transformed(Mat4::from_translation(-Vec3::Y * half_length_m));
            // Keep only the cylinder's caps (its side is replaced by the finer tube).
            let side_vertices = 2 * (detail.segments.max(3) + 1) as usize;
            let side_indices = 6 * detail.segments.max(3) as usize;
            let base = side.positions.len() as u32;
            side.positions
                .extend_from_slice(&caps.positions[side_vertices..]);
            side.normals
                .extend_from_slice(&caps.normals[side_vertices..]);
            side.indices.extend(
                caps.indices[side_indices..]
                    .iter()
                    .map(|&i| i - side_vertices as u32 + base),
            );
            side
        }
    }
}

/// A shape's geometry (primitive plus deformations, as evaluated for one posture) as a mesh in
/// the shape frame. Normals come from the shape's gradient where it is usable, otherwise from
/// the triangles.
pub fn tessellate_geometry(geometry: &ShapeGeometry, detail: TessellationDetail) -> TriMesh {
    let rest = tessellate_primitive(&geometry.primitive, detail);
    if geometry.is_undeformed() {
        return rest;
    }
    let positions: Vec<Vec3> = rest.positions.iter().map(|&p| geometry.deform(p)).collect();
    let fallback = super::mesh::smooth_normals(&positions, &rest.indices);
    let normals = positions
        .iter()
        .zip(&fallback)
        .map(|(&p, &n)| {
            let g = geometry.gradient(p);
            if g.is_finite() && g.length_squared() > 1e-20 && g.normalize().dot(n) > 0.0 {
                g.normalize()
            } else {
                n
            }
        })
        .collect();
    TriMesh {
        positions,
        normals,
        indices: rest.indices,
    }
}

/// A character shape instance (geometry placed in the world) as a scene shape.
pub fn scene_shape(
    instance: &crate::character::shape::ShapeInstance,
    kind: ShapeKind,
    color: Rgba,
    detail: TessellationDetail,
) -> scene::ShapeInstance {
    scene::ShapeInstance {
        mesh: Arc::new(tessellate_geometry(&instance.geometry, detail)),
        world_from_shape: Mat4::from(instance.world_from_shape),
        color,
        kind,
    }
}

/// The simulation's deformed surface as the scene's skin.
pub fn skin_from_surface(mesh: &crate::sim::SurfaceMesh, color: Rgba) -> SkinSurface {
    SkinSurface {
        mesh: TriMesh {
            positions: mesh.positions_m.clone(),
            normals: mesh.normals.clone(),
            indices: mesh.indices.clone(),
        },
        color,
    }
}

/// Muscle or bone, from a shape's name (the character format has no such field): names with
/// `bone`, `rib`, `pelvis`, `spine`, `vertebra`, `skull`, `scapula`, `clavicle`, `humerus`,
/// `femur` are bones, the rest muscles.
pub fn kind_from_name(name: &str) -> ShapeKind {
    const BONES: [&str; 10] = [
        "bone", "rib", "pelvis", "spine", "vertebra", "skull", "scapula", "clavicle", "humerus",
        "femur",
    ];
    let lower = name.to_ascii_lowercase();
    if BONES.iter().any(|b| lower.contains(b)) {
        ShapeKind::Bone
    } else {
        ShapeKind::Muscle
    }
}

/// Scene data for a character in one posture: its shapes (tessellated), its skeleton (bones
/// parent to child, joints), its tissue springs (skin point to anchor), and its skin, from the
/// simulation's `surface` when given, else the skin's stored positions. Layers and everything
/// not about the character (floor, screen, wand) keep their defaults.
pub fn scene_from_character(
    character: &crate::character::Character,
    posture: &crate::character::Posture,
    time_s: f32,
    surface: Option<&crate::sim::SurfaceMesh>,
    detail: TessellationDetail,
) -> scene::Scene {
    let skeleton = &character.skeleton;
    let pose = skeleton.forward_kinematics(posture);
    let joints: Vec<Vec3> = pose.world_from_joint.iter().map(|p| p.position_m).collect();
    let bones = skeleton
        .joints
        .iter()
        .enumerate()
        .filter_map(|(i, j)| {
            let parent = joints.get(j.parent?.index())?;
            Some(scene::Segment {
                a: *parent,
                b: *joints.get(i)?,
            })
        })
        .collect();
    let instances: Vec<_> = character
        .shapes
        .iter()
        .map(|shape| shape.instance(skeleton, posture, &pose, time_s))
        .collect();
    let shapes = character
        .shapes
        .iter()
        .zip(&instances)
        .map(|(shape, instance)| {
            let kind = kind_from_name(&shape.name);
            let color = match kind {
                ShapeKind::Bone => Rgba::BONE,
                ShapeKind::Muscle => Rgba::MUSCLE,
            };
            scene_shape(instance, kind, color, detail)
        })
        .collect();
    let skin_points: &[Vec3] = match surface {
        Some(s) => &s.positions_m,
        None => &character.skin.positions_m,
    };
    let springs = character
        .tissue
        .iter()
        .filter_map(|t| {
            let a = *skin_points.get(t.skin_point as usize)?;
            let b = instances
                .get(t.shape.index())?
                .rest_point_to_world(t.anchor_rest_m);
            Some(scene::Segment { a, b })
        })
        .collect();
    let skin = match surface {
        Some(s) => Some(skin_from_surface(s, Rgba::SKIN)),
        None => TriMesh::periodic_grid(
            &character.skin.positions_m,
            character.skin.around,
            character.skin.along,
        )
        .map(|mesh| SkinSurface {
            mesh,
            color: Rgba::SKIN,
        }),
    };
    scene::Scene {
        skin,
        shapes,
        skeleton: scene::SkeletonLines {
            bones,
            joints,
            joint_radius_m: 0.006,
        },
        springs,
        ..scene::Scene::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::character::shape::Resolved;

    fn assert_on_surface(geometry: &ShapeGeometry, mesh: &TriMesh, tolerance: f32) {
        mesh.validate().expect("valid");
        for p in &mesh.positions {
            let v = geometry.value(*p);
            let g = geometry.gradient(*p).length().max(1e-6);
            assert!((v / g).abs() < tolerance, "point {p} is {} m off", v / g);
        }
    }

    #[test]
    fn tessellated_primitives_lie_on_the_character_surfaces() {
        let primitives = [
            Primitive::Sphere { radius_m: 0.05 },
            Primitive::Superellipsoid {
                radii_m: Vec3::new(0.03, 0.08, 0.04),
                e1: 0.5,
                e2: 1.0,
            },
            Primitive::Cylinder {
                radius_m: 0.02,
                half_length_m: 0.1,
            },
        ];
        for primitive in primitives {
            let geometry = ShapeGeometry::new(primitive, &[]);
            let mesh = tessellate_geometry(&geometry, TessellationDetail::default());
            assert_on_surface(&geometry, &mesh, 2e-3);
        }
    }

    #[test]
    fn deformed_shape_mesh_follows_the_deformation() {
        let primitive = Primitive::Cylinder {
            radius_m: 0.02,
            half_length_m: 0.1,
        };
        let geometry = ShapeGeometry::new(
            primitive,
            &[Resolved::Twist {
                rate_rad_per_m: 3.0,
            }],
        );
        let mesh = tessellate_geometry(&geometry, TessellationDetail::default());
        assert_on_surface(&geometry, &mesh, 2e-3);
        // Normals point outwards (away from the axis) on the side.
        for (p, n) in mesh.positions.iter().zip(&mesh.normals) {
            if p.y.abs() < 0.09 && Vec3::new(p.x, 0.0, p.z).length() > 0.019 {
                assert!(n.dot(Vec3::new(p.x, 0.0, p.z)) > 0.0, "{p} {n}");
            }
        }
    }

    #[test]
    fn torso_character_becomes_a_clean_scene() {
        let c = crate::character::examples::build("torso", 32, 32).expect("torso");
        let posture = crate::character::Posture::neutral(&c.skeleton);
        let scene = scene_from_character(&c, &posture, 0.0, None, TessellationDetail::default());
        assert_eq!(scene.shapes.len(), c.shapes.len());
        assert_eq!(scene.skeleton.joints.len(), c.skeleton.joints.len());
        assert_eq!(scene.springs.len(), c.tissue.len());
        let skin = scene.skin.as_ref().expect("skin");
        assert_eq!(skin.mesh.positions.len(), 1024);
        let g = crate::render::batch::FrameGeometry::build(&scene);
        assert!(g.sanitized.is_clean(), "{:?}", g.sanitized);
        assert_eq!(kind_from_name("left_Rib_3"), ShapeKind::Bone);
        assert_eq!(kind_from_name("pectoral"), ShapeKind::Muscle);
    }

    #[test]
    fn surface_mesh_becomes_skin() {
        let m = crate::sim::SurfaceMesh {
            positions_m: vec![Vec3::ZERO, Vec3::X, Vec3::Y],
            normals: vec![Vec3::Z; 3],
            indices: vec![0, 1, 2],
        };
        let skin = skin_from_surface(&m, Rgba::SKIN);
        skin.mesh.validate().expect("valid");
        assert_eq!(skin.mesh.triangle_count(), 1);
    }
}
