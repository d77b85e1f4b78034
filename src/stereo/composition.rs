//! Stereo output modes as a recipe: a list of eye passes, each "render this eye's view into this
//! pixel viewport of the output, with this colour mask, only on rows of this parity, only on
//! frames of this parity, clearing first or not". The renderer executes the recipe literally
//! and does no projection math of its own.
//!
//! Conventions (wgpu): pixel viewports have their origin at the top-left corner of the output,
//! y down. A pass's `clear_color` / `clear_depth` mean "clear the whole attachment before this
//! pass" (`LoadOp::Clear`), otherwise load. Row parity counts output rows from the top (row 0 is
//! even); a renderer can honour it with a fragment discard on `floor(position.y) % 2` or a
//! stencil mask. Frame parity counts presented frames; see [`Composition::passes_for_frame`].

use super::view::{EyeView, StereoViews};
use crate::calibration::frames::Eye;
use serde::{Deserialize, Serialize};

/// How the two eyes reach the display.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StereoMode {
    /// One view from the eye midpoint, still head-coupled (motion parallax without glasses).
    #[default]
    Mono,
    /// Left eye in the left half, right eye in the right half, each squeezed to half width
    /// (3D TVs and monitors in "SBS half" mode stretch them back).
    SideBySideHalf,
    /// Left and right halves of an output twice the display's width (a desktop spanning two
    /// projectors or a "full SBS" signal): each eye keeps the display's full resolution.
    SideBySideFull,
    /// Left eye in the top half, right eye in the bottom half (each squeezed to half height).
    TopBottom,
    /// Red-cyan anaglyph: left eye writes red only, right eye green and blue.
    AnaglyphRedCyan,
    /// Alternate rows (passive polarised 3D monitors): left eye on even rows, right on odd
    /// (or the other way with `swap_eyes`).
    RowInterleaved,
    /// Whole frames alternate: left on even frames, right on odd (shutter glasses synced to the
    /// display; only meaningful with vsync and a steady frame rate, since wgpu has no
    /// quad-buffer stereo).
    FrameSequential,
}

impl StereoMode {
    /// Every mode, for UIs and tests.
    pub const ALL: [StereoMode; 7] = [
        StereoMode::Mono,
        StereoMode::SideBySideHalf,
        StereoMode::SideBySideFull,
        StereoMode::TopBottom,
        StereoMode::AnaglyphRedCyan,
        StereoMode::RowInterleaved,
        StereoMode::FrameSequential,
    ];

    /// A short human-readable name.
    pub fn label(self) -> &'static str {
        match self {
            StereoMode::Mono => "mono (head-coupled)",
            StereoMode::SideBySideHalf => "side by side (half)",
            StereoMode::SideBySideFull => "side by side (full)",
            StereoMode::TopBottom => "top-bottom",
            StereoMode::AnaglyphRedCyan => "anaglyph red-cyan",
            StereoMode::RowInterleaved => "row-interleaved",
            StereoMode::FrameSequential => "frame-sequential",
        }
    }

    /// Size of the output image, pixels (width, height), for a display of `display_size_px`:
    /// twice the display's width for [`StereoMode::SideBySideFull`], the display's size
    /// otherwise.
    pub fn output_size_px(self, display_size_px: [u32; 2]) -> [u32; 2] {
        let [w, h] = display_size_px;
        match self {
            StereoMode::SideBySideFull => [w.min(u32::MAX / 2) * 2, h],
            _ => display_size_px,
        }
    }
}

/// Output settings chosen by the user.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct OutputSettings {
    /// The mode.
    pub mode: StereoMode,
    /// Show the right eye's view where the left eye's belongs and vice versa (for displays and
    /// glasses wired the other way, or a window on an odd screen row in row-interleaved mode).
    pub swap_eyes: bool,
}

/// Which channels a pass writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct ColorMask {
    /// Write red.
    pub red: bool,
    /// Write green.
    pub green: bool,
    /// Write blue.
    pub blue: bool,
    /// Write alpha.
    pub alpha: bool,
}

impl ColorMask {
    /// All channels.
    pub const ALL: ColorMask = ColorMask {
        red: true,
        green: true,
        blue: true,
        alpha: true,
    };
    /// Red (and alpha) only: the left lens of red-cyan glasses.
    pub const RED: ColorMask = ColorMask {
        red: true,
        green: false,
        blue: false,
        alpha: true,
    };
    /// Green and blue only: the right (cyan) lens.
    pub const CYAN: ColorMask = ColorMask {
        red: false,
        green: true,
        blue: true,
        alpha: false,
    };
}

/// Even or odd (rows counted from the top of the output, frames from the first presented).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Parity {
    /// 0, 2, 4, ...
    Even,
    /// 1, 3, 5, ...
    Odd,
}

impl Parity {
    /// Whether `n` has this parity.
    pub fn matches(self, n: u64) -> bool {
        n.is_multiple_of(2) == (self == Parity::Even)
    }
}

/// A pixel rectangle in the output, origin top-left, y down (wgpu `set_viewport` order).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct ViewportPx {
    /// Left edge.
    pub x: u32,
    /// Top edge.
    pub y: u32,
    /// Width.
    pub width: u32,
    /// Height.
    pub height: u32,
}

/// One eye rendered into the output.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct EyePass {
    /// The slot in the output this pass fills (left or right, or centre for mono); with
    /// `swap_eyes` the left slot shows the right eye's view.
    pub slot: Eye,
    /// The view to render (matrices, eye position, near/far).
    pub view: EyeView,
    /// Where in the output.
    pub viewport: ViewportPx,
    /// Which colour channels to write.
    pub color_mask: ColorMask,
    /// Only write output rows of this parity (`None`: all rows).
    pub row_parity: Option<Parity>,
    /// Only run on frames of this parity (`None`: every frame).
    pub frame_parity: Option<Parity>,
    /// Clear the colour attachment before this pass.
    pub clear_color: bool,
    /// Clear the depth attachment before this pass.
    pub clear_depth: bool,
}

/// The whole recipe for one output image.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Composition {
    /// The mode it was made for.
    pub mode: StereoMode,
    /// Size of the output image in pixels (width, height); twice the display's width for
    /// [`StereoMode::SideBySideFull`], the display's size otherwise.
    pub output_size_px: [u32; 2],
    /// Passes in execution order.
    pub passes: Vec<EyePass>,
}

impl Composition {
    /// The passes to execute for presented frame number `frame_index` (frame-sequential mode
    /// alternates; every other mode runs all its passes every frame).
    pub fn passes_for_frame(&self, frame_index: u64) -> impl Iterator<Item = &EyePass> {
        self.passes
            .iter()
            .filter(move |p| p.frame_parity.is_none_or(|f| f.matches(frame_index)))
    }
}

/// The recipe for `settings.mode` on a display of `display_size_px` (width, height) pixels.
/// The views map the whole calibrated screen to each viewport; if the 3D view covers only part
/// of the monitor, pass views computed for that part (`ScreenRect::sub_rect`).
pub fn compose(
    views: &StereoViews,
    settings: &OutputSettings,
    display_size_px: [u32; 2],
) -> Composition {
    let [w, h] = display_size_px;
    let (left_view, right_view) = if settings.swap_eyes {
        (views.right, views.left)
    } else {
        (views.left, views.right)
    };
    let full = ViewportPx {
        x: 0,
        y: 0,
        width: w,
        height: h,
    };
    let pass = |slot, view, viewport, clear_color| EyePass {
        slot,
        view,
        viewport,
        color_mask: ColorMask::ALL,
        row_parity: None,
        frame_parity: None,
        clear_color,
        clear_depth: true,
    };
    let half_w = w / 2;
    let half_h = h / 2;
    let passes = match settings.mode {
        StereoMode::Mono => vec![pass(Eye::Center, views.center, full, true)],
        StereoMode::SideBySideHalf => vec![
            pass(
                Eye::Left,
                left_view,
                ViewportPx {
                    width: half_w,
                    ..full
                },
                true,
            ),
            pass(
                Eye::Right,
                right_view,
                ViewportPx {
                    x: half_w,
                    width: w - half_w,
                    ..full
                },
                false,
            ),
        ],
        StereoMode::SideBySideFull => {
            let w = w.min(u32::MAX / 2);
            let each = ViewportPx { width: w, ..full };
            vec![
                pass(Eye::Left, left_view, each, true),
                pass(Eye::Right, right_view, ViewportPx { x: w, ..each }, false),
            ]
        }
        StereoMode::TopBottom => vec![
            pass(
                Eye::Left,
                left_view,
                ViewportPx {
                    height: half_h,
                    ..full
                },
                true,
            ),
            pass(
                Eye::Right,
                right_view,
                ViewportPx {
                    y: half_h,
                    height: h - half_h,
                    ..full
                },
                false,
            ),
        ],
        StereoMode::AnaglyphRedCyan => vec![
            EyePass {
                color_mask: ColorMask::RED,
                ..pass(Eye::Left, left_view, full, true)
            },
            EyePass {
                color_mask: ColorMask::CYAN,
                ..pass(Eye::Right, right_view, full, false)
            },
        ],
        StereoMode::RowInterleaved => vec![
            EyePass {
                row_parity: Some(Parity::Even),
                ..pass(Eye::Left, left_view, full, true)
            },
            EyePass {
                row_parity: Some(Parity::Odd),
                ..pass(Eye::Right, right_view, full, false)
            },
        ],
        StereoMode::FrameSequential => vec![
            EyePass {
                frame_parity: Some(Parity::Even),
                ..pass(Eye::Left, left_view, full, true)
            },
            EyePass {
                frame_parity: Some(Parity::Odd),
                ..pass(Eye::Right, right_view, full, true)
            },
        ],
    };
    Composition {
        mode: settings.mode,
        output_size_px: settings.mode.output_size_px(display_size_px),
        passes,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calibration::CalibrationProfile;
    use crate::pose::Pose;
    use crate::stereo::view::{ViewSettings, eye_views};
    use glam::Vec3;

    fn views() -> StereoViews {
        let head = Pose::from_translation(Vec3::new(0.02, 0.01, 0.6));
        eye_views(
            &CalibrationProfile::default(),
            &head,
            &ViewSettings::default(),
        )
        .expect("views")
    }

    fn vp(x: u32, y: u32, width: u32, height: u32) -> ViewportPx {
        ViewportPx {
            x,
            y,
            width,
            height,
        }
    }

    fn recipe(mode: StereoMode, swap_eyes: bool) -> Composition {
        compose(&views(), &OutputSettings { mode, swap_eyes }, [1921, 1081])
    }

    /// (slot, eye of the view, viewport, mask, row parity, frame parity, clear colour)
    type Row = (
        Eye,
        Eye,
        ViewportPx,
        ColorMask,
        Option<Parity>,
        Option<Parity>,
        bool,
    );

    fn summary(c: &Composition) -> Vec<Row> {
        c.passes
            .iter()
            .map(|p| {
                assert!(
                    p.clear_depth,
                    "every eye pass starts with a clear depth buffer"
                );
                (
                    p.slot,
                    p.view.eye,
                    p.viewport,
                    p.color_mask,
                    p.row_parity,
                    p.frame_parity,
                    p.clear_color,
                )
            })
            .collect()
    }

    #[test]
    fn every_mode_has_the_expected_passes() {
        use ColorMask as M;
        use Eye::{Center as C, Left as L, Right as R};
        let full = vp(0, 0, 1921, 1081);
        let cases: Vec<(StereoMode, [u32; 2], Vec<Row>)> = vec![
            (
                StereoMode::Mono,
                [1921, 1081],
                vec![(C, C, full, M::ALL, None, None, true)],
            ),
            (
                StereoMode::SideBySideHalf,
                [1921, 1081],
                vec![
                    (L, L, vp(0, 0, 960, 1081), M::ALL, None, None, true),
                    (R, R, vp(960, 0, 961, 1081), M::ALL, None, None, false),
                ],
            ),
            (
                StereoMode::SideBySideFull,
                [3842, 1081],
                vec![
                    (L, L, full, M::ALL, None, None, true),
                    (R, R, vp(1921, 0, 1921, 1081), M::ALL, None, None, false),
                ],
            ),
            (
                StereoMode::TopBottom,
                [1921, 1081],
                vec![
                    (L, L, vp(0, 0, 1921, 540), M::ALL, None, None, true),
                    (R, R, vp(0, 540, 1921, 541), M::ALL, None, None, false),
                ],
            ),
            (
                StereoMode::AnaglyphRedCyan,
                [1921, 1081],
                vec![
                    (L, L, full, M::RED, None, None, true),
                    (R, R, full, M::CYAN, None, None, false),
                ],
            ),
            (
                StereoMode::RowInterleaved,
                [1921, 1081],
                vec![
                    (L, L, full, M::ALL, Some(Parity::Even), None, true),
                    (R, R, full, M::ALL, Some(Parity::Odd), None, false),
                ],
            ),
            (
                StereoMode::FrameSequential,
                [1921, 1081],
                vec![
                    (L, L, full, M::ALL, None, Some(Parity::Even), true),
                    (R, R, full, M::ALL, None, Some(Parity::Odd), true),
                ],
            ),
        ];
        assert_eq!(cases.len(), StereoMode::ALL.len());
        for (mode, size, expected) in cases {
            let c = recipe(mode, false);
            assert_eq!(c.mode, mode);
            assert_eq!(c.output_size_px, size, "{mode:?}");
            assert_eq!(summary(&c), expected, "{mode:?}");
            for p in &c.passes {
                let vp = p.viewport;
                assert!(
                    vp.x + vp.width <= size[0] && vp.y + vp.height <= size[1],
                    "{mode:?}"
                );
            }
        }
    }

    #[test]
    fn output_size_says_what_compose_makes() {
        for mode in StereoMode::ALL {
            let want = if mode == StereoMode::SideBySideFull {
                [3842, 1081]
            } else {
                [1921, 1081]
            };
            assert_eq!(mode.output_size_px([1921, 1081]), want, "{mode:?}");
            assert_eq!(recipe(mode, false).output_size_px, want, "{mode:?}");
        }
    }

    #[test]
    fn swap_eyes_exchanges_views_but_not_slots() {
        for mode in StereoMode::ALL {
            let plain = recipe(mode, false);
            let swapped = recipe(mode, true);
            for (a, b) in plain.passes.iter().zip(&swapped.passes) {
                assert_eq!(
                    (a.slot, a.viewport, a.color_mask),
                    (b.slot, b.viewport, b.color_mask)
                );
                let expect = match a.view.eye {
                    Eye::Left => Eye::Right,
                    Eye::Right => Eye::Left,
                    Eye::Center => Eye::Center,
                };
                assert_eq!(b.view.eye, expect, "{mode:?}");
            }
        }
        let v = views();
        let s = recipe(StereoMode::AnaglyphRedCyan, true);
        assert_eq!(s.passes[0].view, v.right);
        assert_eq!(s.passes[1].view, v.left);
    }

    #[test]
    fn frame_sequential_alternates_and_others_do_not() {
        let c = recipe(StereoMode::FrameSequential, false);
        for n in 0..6u64 {
            let eyes: Vec<Eye> = c.passes_for_frame(n).map(|p| p.view.eye).collect();
            let expect = if n % 2 == 0 { Eye::Left } else { Eye::Right };
            assert_eq!(eyes, vec![expect]);
        }
        let c = recipe(StereoMode::RowInterleaved, false);
        assert_eq!(c.passes_for_frame(7).count(), 2);
    }

    #[test]
    fn tiny_outputs_do_not_overflow() {
        for mode in StereoMode::ALL {
            for size in [[0, 0], [1, 1], [u32::MAX, 3]] {
                let c = compose(
                    &views(),
                    &OutputSettings {
                        mode,
                        swap_eyes: false,
                    },
                    size,
                );
                for p in &c.passes {
                    let vp = p.viewport;
                    assert!(
                        u64::from(vp.x) + u64::from(vp.width) <= u64::from(c.output_size_px[0])
                    );
                    assert!(
                        u64::from(vp.y) + u64::from(vp.height) <= u64::from(c.output_size_px[1])
                    );
                }
            }
        }
    }
}
