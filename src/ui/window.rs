//! The workstation window (eframe, wgpu): a toolbar on top, the panels on the left and the 3D
//! view filling the rest. Each egui frame runs one frame of the scheduler, which renders the
//! stereo composition offscreen on eframe's own wgpu device; the image is shown as an egui
//! texture. Mouse and keyboard over the 3D view go to the desktop stand-ins (the mouse drives
//! the wand on a plane in front of the screen, the keyboard flies the vehicle).

use crate::app::gpu::OffscreenStereo;
use crate::app::state::AppState;
use crate::clock::{Clock, RealClock, VirtualClock};
use crate::devices::desktop::DesktopEvent;

/// The eframe application.
pub struct WorkstationApp {
    /// The workstation state.
    pub state: AppState,
    renderer: Option<OffscreenStereo>,
    texture: Option<(egui::TextureId, u64)>,
    clock: RealClock,
    error: Option<String>,
    pointer_inside: bool,
    /// Quit after this many frames (tests, screenshots); none: run until closed.
    pub quit_after_frames: Option<u64>,
    /// When replaying in the window: the session clock and the real clock it follows.
    pub replay_clock: Option<(VirtualClock, RealClock)>,
    /// Write the per-frame log (JSON lines) here when the window closes.
    pub log_path: Option<std::path::PathBuf>,
    records: Vec<crate::app::scheduler::FrameRecord>,
    frames: u64,
}

impl std::fmt::Debug for WorkstationApp {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("WorkstationApp")
            .field("state", &self.state)
            .field("frames", &self.frames)
            .finish_non_exhaustive()
    }
}

impl WorkstationApp {
    /// The app on eframe's wgpu device (when eframe runs on wgpu).
    pub fn new(cc: &eframe::CreationContext<'_>, state: AppState) -> Self {
        let (renderer, error) = match cc.wgpu_render_state.as_ref() {
            Some(rs) => match OffscreenStereo::new(&rs.device, &rs.queue, [640, 480]) {
                Ok(r) => (Some(r), None),
                Err(e) => (None, Some(format!("renderer: {e}"))),
            },
            None => (None, Some("eframe is not running on wgpu".to_owned())),
        };
        Self::with_renderer(state, renderer, error)
    }

    /// The app with a given renderer (tests pass none).
    pub fn with_renderer(
        state: AppState,
        renderer: Option<OffscreenStereo>,
        error: Option<String>,
    ) -> Self {
        Self {
            state,
            renderer,
            texture: None,
            clock: RealClock::new(),
            error,
            pointer_inside: false,
            quit_after_frames: None,
            replay_clock: None,
            log_path: None,
            records: Vec::new(),
            frames: 0,
        }
    }

    /// Frames run so far.
    pub fn frames(&self) -> u64 {
        self.frames
    }

    fn forward_input(&mut self, ctx: &egui::Context, view: egui::Rect) {
        let wants_keys = ctx.egui_wants_keyboard_input();
        let events = ctx.input(|i| i.events.clone());
        for event in events {
            let desktop = match event {
                egui::Event::PointerMoved(pos) => {
                    self.pointer_inside = view.contains(pos);
                    self.pointer_inside.then(|| DesktopEvent::MouseMove {
                        x: (pos.x - view.min.x) / view.width().max(1.0),
                        y: (pos.y - view.min.y) / view.height().max(1.0),
                    })
                }
                egui::Event::PointerButton {
                    pos,
                    button,
                    pressed,
                    ..
                } if view.contains(pos) || !pressed => Some(DesktopEvent::MouseButton {
                    button: match button {
                        egui::PointerButton::Primary => 0,
                        egui::PointerButton::Secondary => 1,
                        egui::PointerButton::Middle => 2,
                        egui::PointerButton::Extra1 => 3,
                        egui::PointerButton::Extra2 => 4,
                    },
                    pressed,
                }),
                egui::Event::MouseWheel { delta, .. } if self.pointer_inside => {
                    Some(DesktopEvent::Wheel {
                        delta_lines: delta.y,
                    })
                }
                egui::Event::Key {
                    key,
                    pressed,
                    repeat: false,
                    ..
                } if !wants_keys || !pressed => Some(DesktopEvent::Key {
                    name: key.name().to_owned(),
                    pressed,
                }),
                egui::Event::WindowFocused(false) => Some(DesktopEvent::FocusLost),
                _ => None,
            };
            if let Some(e) = desktop {
                self.state.devices.feed_desktop(e);
            }
        }
    }

    fn view_ui(&mut self, ui: &mut egui::Ui, frame: &eframe::Frame) {
        let rect = ui.available_rect_before_wrap();
        self.forward_input(ui.ctx(), rect);
        let ppp = ui.ctx().pixels_per_point();
        let size_px = [
            ((rect.width() * ppp).round() as u32).max(16),
            ((rect.height() * ppp).round() as u32).max(16),
        ];
        let Some(renderer) = self.renderer.as_mut() else {
            ui.label(
                self.error
                    .clone()
                    .unwrap_or_else(|| "no renderer".to_owned()),
            );
            return;
        };
        renderer.set_display_size(size_px);
        if let Some((session, real)) = &self.replay_clock {
            session.set(real.now());
        }
        let record = self.state.run_frame(&self.clock, renderer);
        if self.log_path.is_some() {
            self.records.push(record);
        }
        self.frames += 1;
        let (Some(rs), Some(target)) = (frame.wgpu_render_state(), renderer.target()) else {
            return;
        };
        let generation = renderer.target_generation();
        let id = match self.texture {
            Some((id, g)) if g == generation => id,
            Some((id, _)) => {
                rs.renderer.write().update_egui_texture_from_wgpu_texture(
                    &rs.device,
                    &target.color_view,
                    wgpu::FilterMode::Linear,
                    id,
                );
                self.texture = Some((id, generation));
                id
            }
            None => {
                let id = rs.renderer.write().register_native_texture(
                    &rs.device,
                    &target.color_view,
                    wgpu::FilterMode::Linear,
                );
                self.texture = Some((id, generation));
                id
            }
        };
        ui.add(
            egui::Image::new(egui::load::SizedTexture::new(id, rect.size()))
                .sense(egui::Sense::hover()),
        );
    }
}

impl eframe::App for WorkstationApp {
    fn ui(&mut self, ui: &mut egui::Ui, frame: &mut eframe::Frame) {
        egui::Panel::top("toolbar").show(ui, |ui| {
            super::toolbar_ui(ui, &mut self.state);
        });
        egui::Panel::left("panels")
            .default_size(340.0)
            .show(ui, |ui| {
                egui::ScrollArea::vertical().show(ui, |ui| {
                    super::panels_ui(ui, &mut self.state);
                });
            });
        egui::CentralPanel::no_frame().show(ui, |ui| {
            self.view_ui(ui, frame);
        });
        if let Some(n) = self.quit_after_frames
            && self.frames >= n
        {
            ui.ctx().send_viewport_cmd(egui::ViewportCommand::Close);
        }
        ui.ctx().request_repaint();
    }

    fn on_exit(&mut self) {
        if let Some(path) = &self.log_path {
            match crate::app::replay::write_log(path, &self.records) {
                Ok(()) => eprintln!(
                    "frame log: {} frames in {}",
                    self.records.len(),
                    path.display()
                ),
                Err(e) => eprintln!("error: {e}"),
            }
        }
    }
}
