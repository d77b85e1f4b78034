//! The reference scene used by the golden-image tests and the render benchmark: a floor grid,
//! a few shaded shapes (muscle, bone, sphere), a skin-like translucent tube with a bone inside,
//! skeleton lines and joints, the wand with the tool cursor and its picking ray, and the
//! calibrated screen's border. Sized for the default desktop calibration (a 0.53 m × 0.30 m
//! screen centred on the world origin in the plane z = 0, viewer 0.6 m in front): things reach
//! from 0.1 m in front of the screen to 0.3 m behind it, so both crossed and uncrossed parallax
//! show.

use std::sync::Arc;

use glam::{Mat4, Quat, Vec3};

use super::mesh::TriMesh;
use super::scene::{
    FloorGrid, Rgba, Scene, Segment, ShapeInstance, ShapeKind, SkeletonLines, SkinSurface,
    ToolCursor, Wand,
};

/// The default screen's corners (0.53 m × 0.30 m at z = 0), for the border.
pub const REFERENCE_SCREEN_CORNERS: [Vec3; 4] = [
    Vec3::new(-0.265, -0.15, 0.0),
    Vec3::new(0.265, -0.15, 0.0),
    Vec3::new(0.265, 0.15, 0.0),
    Vec3::new(-0.265, 0.15, 0.0),
];

/// The reference scene.
pub fn reference_scene() -> Scene {
    let joints = vec![
        Vec3::new(-0.16, -0.06, -0.12),
        Vec3::new(-0.05, 0.02, -0.08),
        Vec3::new(0.06, 0.00, -0.02),
        Vec3::new(0.15, 0.07, 0.04),
    ];
    let bones = joints
        .windows(2)
        .map(|w| Segment { a: w[0], b: w[1] })
        .collect();
    // Skin: a tube along a bent arm-like path, translucent so the bone inside shows.
    let path: Vec<Vec3> = (0..=12)
        .map(|i| {
            let t = i as f32 / 12.0;
            Vec3::new(
                -0.20 + 0.30 * t,
                -0.02 + 0.09 * (t * 3.0).sin(),
                -0.22 + 0.04 * t,
            )
        })
        .collect();
    let radii: Vec<f32> = (0..=12)
        .map(|i| 0.030 + 0.012 * (i as f32 / 12.0 * std::f32::consts::PI).sin())
        .collect();
    let skin_mesh = TriMesh::tube(&path, &radii, 20);
    let inner_bone = TriMesh::cylinder(0.010, 0.26, 10);
    let shapes = vec![
        ShapeInstance {
            mesh: Arc::new(TriMesh::superellipsoid(
                Vec3::new(0.035, 0.06, 0.03),
                0.6,
                1.0,
                24,
                16,
            )),
            world_from_shape: Mat4::from_rotation_translation(
                Quat::from_rotation_z(0.5),
                Vec3::new(0.12, -0.05, -0.10),
            ),
            color: Rgba::MUSCLE,
            kind: ShapeKind::Muscle,
        },
        ShapeInstance {
            mesh: Arc::new(TriMesh::sphere(0.03, 24, 12)),
            world_from_shape: Mat4::from_translation(Vec3::new(-0.10, 0.06, 0.06)),
            color: Rgba::rgb(0.15, 0.35, 0.75),
            kind: ShapeKind::Muscle,
        },
        ShapeInstance {
            mesh: Arc::new(TriMesh::superellipsoid(
                Vec3::new(0.025, 0.04, 0.025),
                0.25,
                0.25,
                16,
                8,
            )),
            world_from_shape: Mat4::from_rotation_translation(
                Quat::from_rotation_y(0.6),
                Vec3::new(0.19, -0.09, -0.28),
            ),
            color: Rgba::BONE,
            kind: ShapeKind::Bone,
        },
        ShapeInstance {
            mesh: Arc::new(inner_bone),
            world_from_shape: Mat4::from_rotation_translation(
                Quat::from_rotation_arc(Vec3::Y, (path[12] - path[0]).normalize()),
                path[0] + Vec3::new(0.02, 0.0, 0.0),
            ),
            color: Rgba::BONE,
            kind: ShapeKind::Bone,
        },
    ];
    let wand_position = Vec3::new(0.17, -0.10, 0.12);
    let cursor_position = Vec3::new(0.06, 0.00, -0.02);
    let ray_direction = (cursor_position - wand_position).normalize();
    Scene {
        skin: Some(SkinSurface {
            mesh: skin_mesh,
            color: Rgba::SKIN.with_alpha(0.6),
        }),
        shapes,
        skeleton: SkeletonLines {
            bones,
            joints,
            joint_radius_m: 0.006,
        },
        wand: Some(Wand {
            world_from_wand: Mat4::from_rotation_translation(
                Quat::from_rotation_arc(-Vec3::Z, ray_direction),
                wand_position,
            ),
            length_m: 0.06,
        }),
        cursor: Some(ToolCursor {
            position: cursor_position,
            radius_m: 0.015,
            ray: Some((wand_position, ray_direction, 0.17)),
            color: Rgba::CURSOR,
        }),
        screen_corners: Some(REFERENCE_SCREEN_CORNERS),
        floor_grid: Some(FloorGrid {
            centre: Vec3::new(0.0, -0.16, -0.2),
            half_extent_m: 0.5,
            spacing_m: 0.05,
        }),
        ..Scene::default()
    }
}

/// The paper's torso (the example character `torso` with a 32 × 32 = 1024-point skin) at its
/// neutral posture, with the floor grid and the screen border: the benchmark scene.
pub fn torso_scene() -> Option<Scene> {
    let character = crate::character::examples::build("torso", 32, 32)?;
    let posture = crate::character::Posture::neutral(&character.skeleton);
    let mut scene = super::adapter::scene_from_character(
        &character,
        &posture,
        0.0,
        None,
        super::adapter::TessellationDetail::default(),
    );
    scene.screen_corners = Some(REFERENCE_SCREEN_CORNERS);
    Some(scene)
}

/// A torso-like closed-ish skin of about `points` vertices (a tube of rings × segments, the
/// count rounded to whole rings), for benchmarks: the paper's 1024-point torso is
/// `torso_skin(1024)`.
pub fn torso_skin(points: usize) -> SkinSurface {
    let segments = 32usize;
    let rings = (points / (segments + 1)).max(2);
    let path: Vec<Vec3> = (0..rings)
        .map(|i| Vec3::new(0.0, -0.12 + 0.24 * i as f32 / (rings - 1) as f32, -0.1))
        .collect();
    let radii: Vec<f32> = (0..rings)
        .map(|i| {
            let t = i as f32 / (rings - 1) as f32;
            0.05 + 0.04 * (t * std::f32::consts::PI).sin()
        })
        .collect();
    SkinSurface {
        mesh: TriMesh::tube(&path, &radii, segments as u32),
        color: Rgba::SKIN,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::batch::FrameGeometry;

    #[test]
    fn reference_scene_is_clean_and_has_every_layer() {
        let scene = reference_scene();
        let g = FrameGeometry::build(&scene);
        assert!(g.sanitized.is_clean(), "{:?}", g.sanitized);
        assert!(!g.opaque.indices.is_empty());
        assert!(!g.translucent.indices.is_empty());
        assert!(g.lines.len() > 100);
    }

    #[test]
    fn torso_has_about_the_asked_points() {
        let s = torso_skin(1024);
        let n = s.mesh.positions.len();
        assert!((990..=1024).contains(&n), "{n}");
        s.mesh.validate().expect("valid");
    }
}
