//! What the renderer draws: plain data the app fills each frame. Nothing here knows about the
//! simulation or the character model; adapters elsewhere copy their state into these structs.
//! All positions are in the world frame (metres, +Y up) unless a field says otherwise.

use std::sync::Arc;

use glam::{Mat4, Vec3};

use super::mesh::TriMesh;

/// A linear-light RGBA colour (not sRGB-encoded); `a` is opacity.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rgba {
    /// Red, linear 0..1.
    pub r: f32,
    /// Green, linear 0..1.
    pub g: f32,
    /// Blue, linear 0..1.
    pub b: f32,
    /// Opacity 0..1.
    pub a: f32,
}

impl Rgba {
    /// An opaque colour from linear components.
    pub const fn rgb(r: f32, g: f32, b: f32) -> Self {
        Self { r, g, b, a: 1.0 }
    }

    /// This colour with another opacity.
    pub const fn with_alpha(self, a: f32) -> Self {
        Self { a, ..self }
    }

    /// An opaque colour from 8-bit sRGB components (as a colour picker shows them).
    pub fn from_srgb8(r: u8, g: u8, b: u8) -> Self {
        fn lin(c: u8) -> f32 {
            let c = f32::from(c) / 255.0;
            if c <= 0.04045 {
                c / 12.92
            } else {
                ((c + 0.055) / 1.055).powf(2.4)
            }
        }
        Self::rgb(lin(r), lin(g), lin(b))
    }

    /// The components as an array, non-finite ones replaced by 0 and all clamped to 0..1.
    pub fn to_sanitized_array(self) -> [f32; 4] {
        [self.r, self.g, self.b, self.a].map(|c| {
            if c.is_finite() {
                c.clamp(0.0, 1.0)
            } else {
                0.0
            }
        })
    }

    /// Skin-like colour.
    pub const SKIN: Self = Self::rgb(0.80, 0.50, 0.38);
    /// Muscle red.
    pub const MUSCLE: Self = Self::rgb(0.55, 0.08, 0.07);
    /// Bone ivory.
    pub const BONE: Self = Self::rgb(0.85, 0.82, 0.70);
    /// Skeleton lines and joints.
    pub const SKELETON: Self = Self::rgb(0.95, 0.85, 0.10);
    /// Connective tissue springs.
    pub const SPRING: Self = Self::rgb(0.10, 0.70, 0.30);
    /// Fat points.
    pub const FAT: Self = Self::rgb(0.95, 0.90, 0.55);
    /// Floor grid lines.
    pub const GRID: Self = Self::rgb(0.18, 0.18, 0.20);
    /// The calibrated screen's border.
    pub const SCREEN_BORDER: Self = Self::rgb(0.0, 0.55, 0.90);
    /// Wand body.
    pub const WAND: Self = Self::rgb(0.25, 0.25, 0.30);
    /// Tool cursor and picking ray.
    pub const CURSOR: Self = Self::rgb(1.0, 0.35, 0.05);
    /// Default background.
    pub const BACKGROUND: Self = Self::rgb(0.02, 0.02, 0.03);
}

/// Which layers are drawn. Data for a hidden layer may stay in the scene; it is not uploaded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Layers {
    /// The skin surface.
    pub skin: bool,
    /// Muscle shapes.
    pub muscles: bool,
    /// Bone shapes.
    pub bones: bool,
    /// Skeleton: bones as lines and joints as small spheres.
    pub skeleton: bool,
    /// Connective tissue springs (lines).
    pub springs: bool,
    /// Fat points.
    pub fat: bool,
    /// The wand.
    pub wand: bool,
    /// The tool cursor and its picking ray.
    pub cursor: bool,
    /// The calibrated screen's border.
    pub screen_border: bool,
    /// The floor grid.
    pub floor_grid: bool,
}

impl Default for Layers {
    /// Everything on except the "on demand" layers (springs and fat).
    fn default() -> Self {
        Self {
            skin: true,
            muscles: true,
            bones: true,
            skeleton: true,
            springs: false,
            fat: false,
            wand: true,
            cursor: true,
            screen_border: true,
            floor_grid: true,
        }
    }
}

/// The skin surface: a deformed triangle mesh (world frame) with its normals.
#[derive(Debug, Clone, PartialEq)]
pub struct SkinSurface {
    /// The mesh in the world frame.
    pub mesh: TriMesh,
    /// Colour; `a < 1` draws it translucent (blended, no depth writes) so what is inside shows.
    pub color: Rgba,
}

/// What a shape is, for its layer toggle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ShapeKind {
    /// A muscle (shown with [`Layers::muscles`]).
    Muscle,
    /// A bone shape (shown with [`Layers::bones`]).
    Bone,
}

/// One muscle or bone shape: a mesh in its own frame, placed by `world_from_shape`.
#[derive(Debug, Clone, PartialEq)]
pub struct ShapeInstance {
    /// The mesh in the shape's frame; shared, so the app can tessellate once and place it often.
    pub mesh: Arc<TriMesh>,
    /// Places the shape in the world (may scale).
    pub world_from_shape: Mat4,
    /// Colour (opacity < 1 is drawn opaque for shapes).
    pub color: Rgba,
    /// Muscle or bone.
    pub kind: ShapeKind,
}

/// A coloured line segment (world frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    /// One end.
    pub a: Vec3,
    /// The other end.
    pub b: Vec3,
}

/// The skeleton: bones as segments between joints and the joints themselves.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SkeletonLines {
    /// Bones, parent joint to child joint.
    pub bones: Vec<Segment>,
    /// Joint positions.
    pub joints: Vec<Vec3>,
    /// Radius of the sphere drawn at each joint (metres); 0 hides joints.
    pub joint_radius_m: f32,
}

/// The 3D mouse ("wand") in the right hand.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Wand {
    /// The wand's frame: it points along its −Z, +Y up on the handle.
    pub world_from_wand: Mat4,
    /// Length of the drawn body (metres).
    pub length_m: f32,
}

/// The active tool's cursor and its picking ray.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ToolCursor {
    /// Cursor centre.
    pub position: Vec3,
    /// Radius of the cursor's wire sphere (metres).
    pub radius_m: f32,
    /// The picking ray: origin, unit direction and drawn length (metres); `None` hides it.
    pub ray: Option<(Vec3, Vec3, f32)>,
    /// Colour of cursor and ray.
    pub color: Rgba,
}

/// A square grid of lines on a horizontal plane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FloorGrid {
    /// Centre of the grid; its y is the floor height.
    pub centre: Vec3,
    /// Half the side of the square (metres).
    pub half_extent_m: f32,
    /// Distance between lines (metres).
    pub spacing_m: f32,
}

impl Default for FloorGrid {
    fn default() -> Self {
        Self {
            centre: Vec3::ZERO,
            half_extent_m: 1.0,
            spacing_m: 0.1,
        }
    }
}

/// Everything drawn in one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    /// Layer toggles.
    pub layers: Layers,
    /// Background colour.
    pub background: Rgba,
    /// The skin, if any.
    pub skin: Option<SkinSurface>,
    /// Muscle and bone shapes.
    pub shapes: Vec<ShapeInstance>,
    /// The skeleton.
    pub skeleton: SkeletonLines,
    /// Connective tissue springs.
    pub springs: Vec<Segment>,
    /// Fat points (drawn as small crosses).
    pub fat_points: Vec<Vec3>,
    /// Size of a fat point's cross (metres).
    pub fat_point_size_m: f32,
    /// The wand, if tracked.
    pub wand: Option<Wand>,
    /// The tool cursor, if a tool shows one.
    pub cursor: Option<ToolCursor>,
    /// The calibrated screen's corners (any order around the rectangle), if calibrated.
    pub screen_corners: Option<[Vec3; 4]>,
    /// The floor grid.
    pub floor_grid: Option<FloorGrid>,
    /// Extra lines for debugging and tools.
    pub extra_lines: Vec<(Segment, Rgba)>,
    /// Direction towards the key light (world frame); normalised when used.
    pub key_light_direction: Vec3,
}

impl Default for Scene {
    fn default() -> Self {
        Self {
            layers: Layers::default(),
            background: Rgba::BACKGROUND,
            skin: None,
            shapes: Vec::new(),
            skeleton: SkeletonLines::default(),
            springs: Vec::new(),
            fat_points: Vec::new(),
            fat_point_size_m: 0.005,
            wand: None,
            cursor: None,
            screen_corners: None,
            floor_grid: Some(FloorGrid::default()),
            extra_lines: Vec::new(),
            key_light_direction: Vec3::new(-0.4, 1.0, 0.6),
        }
    }
}
