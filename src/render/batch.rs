//! Turning a [`Scene`] into flat vertex and index arrays ready for upload: the CPU half of a
//! frame. Pure: no GPU here, so the guarantee "nothing non-finite reaches the GPU" is tested
//! without a device. A vertex with a non-finite position is never emitted (its triangles and
//! segments are dropped); a non-finite or zero normal is replaced by +Y; both are counted.

use bytemuck::{Pod, Zeroable};
use glam::{Mat3, Mat4, Vec3};

use super::mesh::TriMesh;
use super::scene::{Rgba, Scene, Segment, ShapeKind};

/// A shaded vertex: world position, world normal, linear colour.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct LitVertex {
    /// World position (metres).
    pub position: [f32; 3],
    /// World unit normal.
    pub normal: [f32; 3],
    /// Linear RGBA.
    pub color: [f32; 4],
}

/// A line vertex: world position and linear colour.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct LineVertex {
    /// World position (metres).
    pub position: [f32; 3],
    /// Linear RGBA.
    pub color: [f32; 4],
}

/// Indexed triangles of [`LitVertex`].
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LitBatch {
    /// Vertices.
    pub vertices: Vec<LitVertex>,
    /// Three indices per triangle into `vertices`.
    pub indices: Vec<u32>,
}

/// Counts of what was left out because it was not finite.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SanitizeCounts {
    /// Vertices with a non-finite position (never uploaded).
    pub non_finite_vertices: usize,
    /// Triangles dropped because a corner was non-finite or an index was out of range.
    pub dropped_triangles: usize,
    /// Normals that were non-finite or zero and replaced.
    pub replaced_normals: usize,
    /// Line segments dropped because an end was non-finite.
    pub dropped_segments: usize,
    /// Shapes dropped because their placement matrix was not finite.
    pub dropped_shapes: usize,
}

impl SanitizeCounts {
    /// True when nothing had to be dropped or replaced.
    pub fn is_clean(&self) -> bool {
        *self == Self::default()
    }
}

/// All geometry of one frame.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FrameGeometry {
    /// Opaque shaded triangles (shapes, joints, wand, and the skin when opaque).
    pub opaque: LitBatch,
    /// The skin when translucent (blended after everything opaque).
    pub translucent: LitBatch,
    /// Line list (two vertices per segment).
    pub lines: Vec<LineVertex>,
    /// What was left out.
    pub sanitized: SanitizeCounts,
}

impl FrameGeometry {
    /// Builds the frame's geometry from the scene, honouring its layer toggles.
    pub fn build(scene: &Scene) -> Self {
        let mut g = Self::default();
        let layers = scene.layers;
        // The skin first: when opaque it hides most of the shapes inside it, and drawing it
        // before them lets the depth test reject their fragments early.
        if let Some(skin) = scene.skin.as_ref().filter(|_| layers.skin) {
            // NaN opacity counts as opaque.
            let opaque = skin.color.a >= 0.999 || skin.color.a.is_nan();
            let batch = if opaque {
                &mut g.opaque
            } else {
                &mut g.translucent
            };
            push_mesh(batch, &mut g.sanitized, &skin.mesh, None, skin.color);
        }
        if let Some(grid) = scene.floor_grid.filter(|_| layers.floor_grid) {
            let spacing = grid.spacing_m.max(1e-3);
            let half = grid.half_extent_m.clamp(0.0, 1e4);
            let n = ((half / spacing).floor() as i64).min(10_000);
            for i in -n..=n {
                let t = i as f32 * spacing;
                let c = grid.centre;
                g.push_segment(
                    Segment {
                        a: c + Vec3::new(t, 0.0, -half),
                        b: c + Vec3::new(t, 0.0, half),
                    },
                    Rgba::GRID,
                );
                g.push_segment(
                    Segment {
                        a: c + Vec3::new(-half, 0.0, t),
                        b: c + Vec3::new(half, 0.0, t),
                    },
                    Rgba::GRID,
                );
            }
        }
        for shape in &scene.shapes {
            let visible = match shape.kind {
                ShapeKind::Muscle => layers.muscles,
                ShapeKind::Bone => layers.bones,
            };
            if !visible {
                continue;
            }
            if !shape.world_from_shape.is_finite() {
                g.sanitized.dropped_shapes += 1;
                continue;
            }
            push_mesh(
                &mut g.opaque,
                &mut g.sanitized,
                &shape.mesh,
                Some(shape.world_from_shape),
                shape.color.with_alpha(1.0),
            );
        }
        if layers.skeleton {
            for &bone in &scene.skeleton.bones {
                g.push_segment(bone, Rgba::SKELETON);
            }
            let r = scene.skeleton.joint_radius_m;
            if r > 0.0 && r.is_finite() && !scene.skeleton.joints.is_empty() {
                let ball = TriMesh::sphere(r, 10, 6);
                for &joint in &scene.skeleton.joints {
                    if !joint.is_finite() {
                        g.sanitized.dropped_shapes += 1;
                        continue;
                    }
                    push_mesh(
                        &mut g.opaque,
                        &mut g.sanitized,
                        &ball,
                        Some(Mat4::from_translation(joint)),
                        Rgba::SKELETON,
                    );
                }
            }
        }
        if layers.springs {
            for &s in &scene.springs {
                g.push_segment(s, Rgba::SPRING);
            }
        }
        if layers.fat {
            let h = scene.fat_point_size_m.abs() * 0.5;
            for &p in &scene.fat_points {
                for axis in [Vec3::X, Vec3::Y, Vec3::Z] {
                    g.push_segment(
                        Segment {
                            a: p - axis * h,
                            b: p + axis * h,
                        },
                        Rgba::FAT,
                    );
                }
            }
        }
        if let Some(wand) = scene.wand.filter(|_| layers.wand) {
            if wand.world_from_wand.is_finite() {
                // A thin box-like cylinder along the wand's −Z, and its axes as short lines.
                let length = wand.length_m.clamp(0.0, 10.0);
                let body = TriMesh::cylinder(0.008, length, 8);
                let wand_from_body = Mat4::from_rotation_x(-std::f32::consts::FRAC_PI_2);
                push_mesh(
                    &mut g.opaque,
                    &mut g.sanitized,
                    &body,
                    Some(wand.world_from_wand * wand_from_body),
                    Rgba::WAND,
                );
                let origin = wand.world_from_wand.transform_point3(Vec3::ZERO);
                for (axis, color) in [
                    (Vec3::X, Rgba::rgb(0.9, 0.1, 0.1)),
                    (Vec3::Y, Rgba::rgb(0.1, 0.9, 0.1)),
                    (Vec3::Z, Rgba::rgb(0.1, 0.2, 0.9)),
                ] {
                    let tip = wand.world_from_wand.transform_point3(axis * 0.03);
                    g.push_segment(Segment { a: origin, b: tip }, color);
                }
            } else {
                g.sanitized.dropped_shapes += 1;
            }
        }
        if let Some(cursor) = scene.cursor.filter(|_| layers.cursor) {
            let r = cursor.radius_m.abs();
            let steps = 24;
            for (u, v) in [(Vec3::X, Vec3::Y), (Vec3::Y, Vec3::Z), (Vec3::Z, Vec3::X)] {
                for k in 0..steps {
                    let a0 = std::f32::consts::TAU * k as f32 / steps as f32;
                    let a1 = std::f32::consts::TAU * (k + 1) as f32 / steps as f32;
                    g.push_segment(
                        Segment {
                            a: cursor.position + (u * a0.cos() + v * a0.sin()) * r,
                            b: cursor.position + (u * a1.cos() + v * a1.sin()) * r,
                        },
                        cursor.color,
                    );
                }
            }
            if let Some((origin, direction, length)) = cursor.ray {
                g.push_segment(
                    Segment {
                        a: origin,
                        b: origin + direction.normalize_or_zero() * length,
                    },
                    cursor.color,
                );
            }
        }
        if let Some(corners) = scene.screen_corners.filter(|_| layers.screen_border) {
            // Connect the corners around the rectangle whatever order they came in: sort by
            // angle about the centre in the rectangle's plane.
            let ordered = order_around(corners);
            for k in 0..4 {
                g.push_segment(
                    Segment {
                        a: ordered[k],
                        b: ordered[(k + 1) % 4],
                    },
                    Rgba::SCREEN_BORDER,
                );
            }
        }
        for &(s, color) in &scene.extra_lines {
            g.push_segment(s, color);
        }
        g
    }

    fn push_segment(&mut self, s: Segment, color: Rgba) {
        if !(s.a.is_finite() && s.b.is_finite()) {
            self.sanitized.dropped_segments += 1;
            return;
        }
        let color = color.to_sanitized_array();
        self.lines.push(LineVertex {
            position: s.a.to_array(),
            color,
        });
        self.lines.push(LineVertex {
            position: s.b.to_array(),
            color,
        });
    }

    /// True when every uploaded float is finite (what the tests check).
    pub fn all_finite(&self) -> bool {
        let lit = |b: &LitBatch| {
            b.vertices.iter().all(|v| {
                v.position
                    .iter()
                    .chain(&v.normal)
                    .chain(&v.color)
                    .all(|c| c.is_finite())
            })
        };
        lit(&self.opaque)
            && lit(&self.translucent)
            && self
                .lines
                .iter()
                .all(|v| v.position.iter().chain(&v.color).all(|c| c.is_finite()))
    }
}

/// Appends a mesh (optionally transformed) to a batch, leaving out non-finite vertices and the
/// triangles that use them (or use out-of-range indices).
fn push_mesh(
    batch: &mut LitBatch,
    counts: &mut SanitizeCounts,
    mesh: &TriMesh,
    world_from_mesh: Option<Mat4>,
    color: Rgba,
) {
    let color = color.to_sanitized_array();
    let normal_matrix = world_from_mesh.map(|m| Mat3::from_mat4(m).inverse().transpose());
    // Map from mesh vertex index to batch index; None for left-out vertices.
    let mut remap: Vec<Option<u32>> = Vec::with_capacity(mesh.positions.len());
    for (i, &p) in mesh.positions.iter().enumerate() {
        let p = world_from_mesh.map_or(p, |m| m.transform_point3(p));
        if !p.is_finite() {
            counts.non_finite_vertices += 1;
            remap.push(None);
            continue;
        }
        let n = mesh.normals.get(i).copied().unwrap_or(Vec3::ZERO);
        let n = normal_matrix.map_or(n, |m| m * n);
        let n = if n.is_finite() && n.length_squared() > 1e-20 {
            n.normalize()
        } else {
            counts.replaced_normals += 1;
            Vec3::Y
        };
        remap.push(Some(batch.vertices.len() as u32));
        batch.vertices.push(LitVertex {
            position: p.to_array(),
            normal: n.to_array(),
            color,
        });
    }
    for tri in mesh.indices.chunks(3) {
        let mapped: Option<Vec<u32>> = if tri.len() == 3 {
            tri.iter()
                .map(|&i| remap.get(i as usize).copied().flatten())
                .collect()
        } else {
            None
        };
        match mapped {
            Some(t) => batch.indices.extend_from_slice(&t),
            None => counts.dropped_triangles += 1,
        }
    }
}

/// The four corners ordered around their centre (so the border is a rectangle, not a bow tie).
fn order_around(corners: [Vec3; 4]) -> [Vec3; 4] {
    let centre = corners.iter().copied().sum::<Vec3>() / 4.0;
    let u = (corners[0] - centre).normalize_or(Vec3::X);
    let normal = (corners[1] - centre).cross(corners[0] - centre);
    let normal = if normal.length_squared() > 1e-20 {
        normal.normalize()
    } else {
        (corners[2] - centre)
            .cross(corners[0] - centre)
            .normalize_or(Vec3::Z)
    };
    let v = normal.cross(u);
    let mut sorted = corners;
    sorted.sort_by(|a, b| {
        let angle = |p: &Vec3| (*p - centre).dot(v).atan2((*p - centre).dot(u));
        angle(a).total_cmp(&angle(b))
    });
    sorted
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::scene::{ShapeInstance, SkinSurface};
    use std::sync::Arc;

    fn skin_with_nan() -> SkinSurface {
        let mut mesh = TriMesh::sphere(0.2, 8, 4);
        mesh.positions[10] = Vec3::new(f32::NAN, 0.0, 0.0);
        mesh.positions[11] = Vec3::new(0.0, f32::INFINITY, 0.0);
        mesh.normals[12] = Vec3::NAN;
        mesh.normals[13] = Vec3::ZERO;
        SkinSurface {
            mesh,
            color: Rgba::SKIN,
        }
    }

    #[test]
    fn non_finite_vertices_never_reach_the_upload_arrays() {
        let skin = skin_with_nan();
        let uses_bad = skin
            .mesh
            .indices
            .chunks(3)
            .filter(|t| t.contains(&10) || t.contains(&11))
            .count();
        let scene = Scene {
            skin: Some(skin.clone()),
            springs: vec![Segment {
                a: Vec3::ZERO,
                b: Vec3::NAN,
            }],
            ..Scene::default()
        };
        let g = FrameGeometry::build(&scene);
        assert!(g.all_finite());
        assert_eq!(g.sanitized.non_finite_vertices, 2);
        assert_eq!(
            g.sanitized.dropped_segments, 0,
            "springs layer is off by default"
        );
        let scene = Scene {
            layers: crate::render::scene::Layers {
                springs: true,
                ..Default::default()
            },
            ..scene
        };
        let g = FrameGeometry::build(&scene);
        assert!(g.all_finite());
        assert_eq!(g.sanitized.non_finite_vertices, 2);
        assert_eq!(g.sanitized.replaced_normals, 2);
        assert_eq!(g.sanitized.dropped_segments, 1);
        assert_eq!(g.sanitized.dropped_triangles, uses_bad);
        assert!(uses_bad > 0);
        assert_eq!(
            g.opaque.indices.len(),
            skin.mesh.indices.len() - 3 * uses_bad
        );
        assert_eq!(g.opaque.vertices.len(), skin.mesh.positions.len() - 2);
        let n = g.opaque.vertices.len() as u32;
        assert!(g.opaque.indices.iter().all(|&i| i < n));
    }

    #[test]
    fn non_finite_shape_placement_and_bad_indices_are_dropped() {
        let mut broken = TriMesh::sphere(0.1, 6, 3);
        broken.indices.extend_from_slice(&[0, 1, 9999]);
        let scene = Scene {
            shapes: vec![
                ShapeInstance {
                    mesh: Arc::new(TriMesh::sphere(0.1, 6, 3)),
                    world_from_shape: Mat4::from_scale(Vec3::splat(f32::NAN)),
                    color: Rgba::MUSCLE,
                    kind: ShapeKind::Muscle,
                },
                ShapeInstance {
                    mesh: Arc::new(broken),
                    world_from_shape: Mat4::IDENTITY,
                    color: Rgba::BONE,
                    kind: ShapeKind::Bone,
                },
            ],
            floor_grid: None,
            ..Scene::default()
        };
        let g = FrameGeometry::build(&scene);
        assert_eq!(g.sanitized.dropped_shapes, 1);
        assert_eq!(g.sanitized.dropped_triangles, 1);
        assert!(g.all_finite());
    }

    #[test]
    fn layer_toggles_leave_geometry_out() {
        let scene = Scene {
            skin: Some(SkinSurface {
                mesh: TriMesh::sphere(0.2, 8, 4),
                color: Rgba::SKIN.with_alpha(0.5),
            }),
            ..Scene::default()
        };
        let g = FrameGeometry::build(&scene);
        assert!(g.opaque.indices.is_empty());
        assert!(
            !g.translucent.indices.is_empty(),
            "translucent skin goes last"
        );
        assert!(!g.lines.is_empty(), "floor grid");
        let hidden = Scene {
            layers: crate::render::scene::Layers {
                skin: false,
                floor_grid: false,
                ..Default::default()
            },
            ..scene
        };
        let g = FrameGeometry::build(&hidden);
        assert!(g.translucent.indices.is_empty() && g.lines.is_empty());
    }

    #[test]
    fn screen_border_is_a_rectangle_whatever_the_corner_order() {
        let c = [
            Vec3::new(-1.0, -1.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(1.0, -1.0, 0.0),
            Vec3::new(-1.0, 1.0, 0.0),
        ];
        let scene = Scene {
            screen_corners: Some(c),
            floor_grid: None,
            ..Scene::default()
        };
        let g = FrameGeometry::build(&scene);
        assert_eq!(g.lines.len(), 8);
        for seg in g.lines.chunks(2) {
            let a = Vec3::from_array(seg[0].position);
            let b = Vec3::from_array(seg[1].position);
            assert!(((a - b).length() - 2.0).abs() < 1e-5, "diagonal {a} {b}");
        }
    }
}
