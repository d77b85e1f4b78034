//! egui panels of the workstation. Each `*_ui` function draws one panel from the
//! [`AppState`] and writes the user's changes back into it (parameter changes are queued and
//! take effect between simulation steps, while the simulation runs).
//!
//! [`window`] holds the eframe application that lays the panels around the 3D view.

pub mod window;

use crate::app::state::{AppState, CharacterParams};
use crate::devices::hub::DeviceState;
use crate::devices::profile::Role;
use crate::sim::{IntegratorKind, ParameterChange};
use crate::stereo::StereoMode;

/// The tool slots of the toolbar. Only navigation exists yet; the construction tools arrive
/// with issue #6 and are shown disabled, saying so.
pub const TOOL_SLOTS: [(&str, bool); 7] = [
    ("Navigate", true),
    ("Select", false),
    ("Sphere", false),
    ("Superellipse", false),
    ("IK", false),
    ("Attach skin", false),
    ("Liposuction", false),
];

/// A slider over `range` that leaves the value it is given alone until the user moves it.
/// egui's default clamps every shown value into the range and rounds it to the decimals shown,
/// and reports that as a change, so drawing the panels rewrote what the character file says
/// (at the first frame the torso's point mass 0.0078125 kg became 0.00781 kg, its tissue
/// stiffness 15.8203125 N/m 15.82, and a second tolerance change was queued). With clamping of
/// edits only, a loaded value stays exact; what the user sets stays within the range.
fn slider<Num: egui::emath::Numeric>(
    value: &mut Num,
    range: std::ops::RangeInclusive<Num>,
) -> egui::Slider<'_> {
    egui::Slider::new(value, range).clamping(egui::SliderClamping::Edits)
}

/// Labels of the fixed-step methods' step sliders (a stall names the one to shorten).
const EULER_STEP_LABEL: &str = "Euler step (ms)";
const RK4_STEP_LABEL: &str = "RK4 step (ms)";

/// A logarithmic slider over a step held in seconds and shown in milliseconds; whether it
/// changed (only then is the step written back).
fn step_ms_slider(
    ui: &mut egui::Ui,
    step_s: &mut f64,
    range_ms: std::ops::RangeInclusive<f64>,
    label: &str,
) -> bool {
    let mut ms = *step_s * 1e3;
    let changed = ui
        .add(slider(&mut ms, range_ms).logarithmic(true).text(label))
        .changed();
    if changed {
        *step_s = ms * 1e-3;
    }
    changed
}

/// The toolbar: tool slots (only navigation works yet) and the simulation switch.
pub fn toolbar_ui(ui: &mut egui::Ui, state: &mut AppState) {
    ui.horizontal_wrapped(|ui| {
        ui.label("Tools:");
        for (name, available) in TOOL_SLOTS {
            let button = egui::Button::selectable(available, name);
            let response = ui.add_enabled(available, button);
            if available {
                response.on_hover_text(
                    "Fly with the keyboard (W/S forward/back, A/D left/right, R/F up/down, \
                     arrows pitch/yaw, Q/E roll) or a Spaceball; the mouse moves the wand.",
                );
            } else {
                response.on_disabled_hover_text("Not built yet: the tools arrive in issue #6.");
            }
        }
        ui.separator();
        ui.toggle_value(&mut state.simulation_on, "Simulate");
    });
}

/// Character parameters: skin elasticity, mass, damping, tissue stiffness and damping, fat.
pub fn character_ui(ui: &mut egui::Ui, state: &mut AppState) {
    let mut p: CharacterParams = state.params;
    ui.label(format!("Character: {}", state.character.name));
    let (around, along) = state.skin_grid();
    ui.label(format!(
        "Skin: {around} × {along} = {} points",
        around * along
    ));
    ui.add(
        slider(&mut p.elasticity_scale, 0.1..=10.0)
            .logarithmic(true)
            .text("Skin elasticity ×"),
    );
    ui.add(
        slider(&mut p.point_mass_kg, 1e-4..=0.1)
            .logarithmic(true)
            .max_decimals(5)
            .text("Point mass (kg)"),
    );
    ui.add(
        slider(&mut p.point_damping_n_s_per_m, 0.0..=1.0)
            .max_decimals(4)
            .text("Point damping (N·s/m)"),
    );
    ui.add(
        slider(&mut p.tissue_stiffness_n_per_m, 0.0..=500.0)
            .max_decimals(2)
            .text("Tissue stiffness (N/m)"),
    );
    ui.add(
        slider(&mut p.tissue_damping_n_s_per_m, 0.0..=5.0)
            .max_decimals(3)
            .text("Tissue damping (N·s/m)"),
    );
    ui.add(
        slider(&mut p.fat_m, 0.0..=0.05)
            .max_decimals(4)
            .step_by(0.001)
            .text("Fat (m)"),
    );
    if p != state.params {
        state.set_params(p);
    }
    let names: Vec<String> = state
        .character
        .motions
        .iter()
        .map(|m| m.name.clone())
        .collect();
    let current = state
        .motion
        .and_then(|m| names.get(m).cloned())
        .unwrap_or_else(|| "neutral posture".into());
    egui::ComboBox::from_label("Motion")
        .selected_text(current)
        .show_ui(ui, |ui| {
            ui.selectable_value(&mut state.motion, None, "neutral posture");
            for (k, name) in names.iter().enumerate() {
                ui.selectable_value(&mut state.motion, Some(k), name);
            }
        });
    ui.label("Layers:");
    ui.horizontal_wrapped(|ui| {
        let l = &mut state.layers;
        ui.checkbox(&mut l.skin, "skin");
        ui.checkbox(&mut l.muscles, "muscles");
        ui.checkbox(&mut l.bones, "bones");
        ui.checkbox(&mut l.skeleton, "skeleton");
        ui.checkbox(&mut l.springs, "tissue");
        ui.checkbox(&mut l.fat, "fat");
        ui.checkbox(&mut l.floor_grid, "floor");
    });
    ui.add(slider(&mut state.skin_opacity, 0.1..=1.0).text("skin opacity"));
}

/// The simulation: on/off, integrator, tolerances, sim/real ratio and adapt, and the live
/// Table-1 figures.
pub fn simulation_ui(ui: &mut egui::Ui, state: &mut AppState) {
    ui.checkbox(&mut state.simulation_on, "Simulate the skin");
    if let Some(e) = &state.sim_error {
        ui.colored_label(egui::Color32::from_rgb(230, 120, 60), e);
    }
    if let Some(t) = state.sim_stalled_at_s {
        // A fixed step too long for the skin diverges slowly, after a good start.
        let step_slider = match state.integrator {
            IntegratorKind::Euler => Some(EULER_STEP_LABEL),
            IntegratorKind::Rk4 => Some(RK4_STEP_LABEL),
            IntegratorKind::Verlet | IntegratorKind::Rk2 => None,
        };
        let hint = step_slider
            .map(|label| format!(" Or shorten the {label} below, or pick an adaptive integrator."))
            .unwrap_or_default();
        ui.colored_label(
            egui::Color32::from_rgb(230, 80, 60),
            format!(
                "Stalled at t = {t:.3} s: every step, down to the minimum, was non-finite or \
                 exploding, so the skin is held at its last good state ({}).{hint}",
                crate::sim::surface::STALL_FORCES_ADVICE
            ),
        );
    }
    let mut integrator = state.integrator;
    egui::ComboBox::from_label("Integrator")
        .selected_text(integrator_label(integrator))
        .show_ui(ui, |ui| {
            for k in IntegratorKind::ALL {
                ui.selectable_value(&mut integrator, k, integrator_label(k));
            }
        });
    if integrator != state.integrator {
        state.integrator = integrator;
        state.queue_change(ParameterChange::Integrator(integrator));
    }
    let mut t = state.tolerances;
    let mut changed = ui
        .add(
            slider(&mut t.position_tolerance, 1e-6..=1e-2)
                .logarithmic(true)
                .max_decimals(6)
                .text("position tolerance ε_r"),
        )
        .changed();
    changed |= step_ms_slider(ui, &mut t.min_step_s, 0.01..=5.0, "min step (ms)");
    changed |= step_ms_slider(ui, &mut t.max_step_s, 0.1..=40.0, "max step (ms)");
    changed |= step_ms_slider(ui, &mut t.euler_step_s, 0.05..=10.0, EULER_STEP_LABEL);
    changed |= step_ms_slider(ui, &mut t.rk4_step_s, 0.05..=10.0, RK4_STEP_LABEL);
    if changed {
        t.max_step_s = t.max_step_s.max(t.min_step_s);
        state.tolerances = t;
        state.queue_change(ParameterChange::Tolerances(t));
    }
    let mut eps_mm = state.epsilon_c_m * 1e3;
    if ui
        .add(slider(&mut eps_mm, 0.1..=20.0).text("constraint tolerance ε_c (mm)"))
        .changed()
    {
        state.epsilon_c_m = eps_mm * 1e-3;
        state.queue_change(ParameterChange::ConstraintTolerance(state.epsilon_c_m));
    }
    let mut recheck = state.recheck_fraction;
    if ui
        .add(
            slider(&mut recheck, 0.05..=0.5)
                .logarithmic(true)
                .text("re-check above (× ε_c)"),
        )
        .on_hover_text(
            "Corrections longer than this re-test their neighbours in the same step. \
             Larger is faster and leaves fat points deeper: above 0.2 the arm's fat points \
             reach past ε_c.",
        )
        .changed()
    {
        state.recheck_fraction = recheck;
        state.queue_change(ParameterChange::RecheckFraction(recheck));
    }
    let mut hold = state.hold_contacts;
    if ui
        .checkbox(&mut hold, "muscles hold resting skin")
        .on_hover_text(
            "A point pushed out of a muscle keeps resting on it (the muscle bears what presses \
             it in) instead of sinking in and being pushed out again every step. Off is the \
             paper's projection alone, with the same constraints: slower on 32×32 skins, \
             faster on skins of 64×64 and finer.",
        )
        .changed()
    {
        state.hold_contacts = hold;
        state.queue_change(ParameterChange::HoldContacts(hold));
    }

    ui.separator();
    let mut ratio = state.scheduler.config().sim_per_real;
    if ui
        .add(
            slider(&mut ratio, 0.01..=1.0)
                .logarithmic(true)
                .text("sim / real time"),
        )
        .changed()
    {
        // A ratio from the slider is always positive and finite.
        let _ = state.scheduler.set_sim_per_real(ratio);
    }
    let mut adapt = state.scheduler.config().adapt;
    if ui
        .checkbox(&mut adapt, "Adapt skin resolution to hold the ratio")
        .changed()
    {
        state.scheduler.set_adapt(adapt);
    }
    if let Some(r) = &state.last_record {
        let window = state.scheduler.config().ratio_window_frames as u64;
        let held = if r.frame < window {
            "measuring"
        } else if r.ratio_held {
            "held"
        } else if r.sim_stalled {
            "NOT held: the simulation stalled"
        } else {
            "NOT held: machine too slow"
        };
        ui.label(format!(
            "ratio achieved {:.3} of {:.3} ({held}); skin {} points",
            r.ratio_achieved, r.ratio_set, r.skin_points
        ));
        ui.label(format!(
            "last frame: {} steps, sim {:.1} ms, render {:.1} ms, frame {:.1} ms, dropped {}",
            r.sim_steps,
            r.sim_wall_s * 1e3,
            r.render_wall_s * 1e3,
            r.frame_wall_s * 1e3,
            r.dropped_frames
        ));
    }
    ui.separator();
    ui.label("Table 1 (live, since reset):");
    let t1 = state.table1;
    egui::Grid::new("table1").num_columns(2).show(ui, |ui| {
        ui.label("Simulation slowdown");
        ui.label(t1.slowdown().map_or("–".into(), |s| format!("{s:.2}×")));
        ui.end_row();
        ui.label("Timestep interval (ms)");
        ui.label(
            t1.step_interval_ms()
                .map_or("–".into(), |(a, b)| format!("[{a:.2}–{b:.2}]")),
        );
        ui.end_row();
        let (f, c, o) = t1.percent();
        ui.label("% force evaluation");
        ui.label(format!("{f:.1}"));
        ui.end_row();
        ui.label("% constraints");
        ui.label(format!("{c:.1}"));
        ui.end_row();
        ui.label("% other");
        ui.label(format!("{o:.1}"));
        ui.end_row();
        ui.label("Steps / rejected");
        ui.label(format!(
            "{} / {}",
            t1.totals.steps, t1.totals.rejected_steps
        ));
        ui.end_row();
        ui.label("Points pushed out / step");
        ui.label(
            t1.totals
                .pushed_per_step()
                .map_or("–".into(), |p| format!("{p:.0}")),
        );
        ui.end_row();
        ui.label("Points held on muscles / step");
        ui.label(
            t1.totals
                .held_per_step()
                .map_or("–".into(), |p| format!("{p:.0}")),
        );
        ui.end_row();
    });
    if ui.button("Reset figures").clicked() {
        state.table1 = Default::default();
    }
}

fn integrator_label(k: IntegratorKind) -> &'static str {
    match k {
        IntegratorKind::Euler => "Euler (fixed step)",
        IntegratorKind::Verlet => "Leapfrog Verlet 2(1)",
        IntegratorKind::Rk2 => "Runge-Kutta 2(1)",
        IntegratorKind::Rk4 => "Runge-Kutta 4 (fixed step)",
    }
}

/// Devices: each role's device (the desktop's marked "standing in" while it serves a role
/// whose own device is lost or opening), state, sample rate and the age of its newest sample;
/// then each lost device with the reason.
pub fn devices_ui(ui: &mut egui::Ui, state: &AppState) {
    let Some(snapshot) = &state.last_snapshot else {
        ui.label("no device snapshot yet");
        return;
    };
    egui::Grid::new("devices")
        .num_columns(5)
        .striped(true)
        .show(ui, |ui| {
            ui.strong("role");
            ui.strong("device");
            ui.strong("state");
            ui.strong("rate");
            ui.strong("age");
            ui.end_row();
            for role in Role::ALL {
                let sample = snapshot.role(role);
                let device = sample.device.and_then(|d| snapshot.devices.get(d));
                ui.label(role.name());
                ui.label(device.map_or_else(
                    || "none (default)".to_owned(),
                    |d| {
                        let stand_in = if sample.stand_in { ", standing in" } else { "" };
                        format!("{} ({}{stand_in})", d.name, d.protocol)
                    },
                ));
                ui.label(state_label(device.map_or(sample.state, |d| d.state)));
                ui.label(device.map_or("–".into(), |d| format!("{:.0} Hz", d.rate_hz)));
                ui.label(sample.at.map_or("–".into(), |at| {
                    format!(
                        "{:.0} ms",
                        snapshot.now.saturating_sub(at).as_secs_f64() * 1e3
                    )
                }));
                ui.end_row();
            }
        });
    // Why a device is not serving (the stand-ins' rows name only the desktop).
    for d in &snapshot.devices {
        if d.state == DeviceState::Lost
            && let Some(error) = &d.last_error
        {
            ui.label(format!("{} ({}) lost: {error}", d.name, d.protocol));
        }
    }
    if snapshot.role(Role::Head).pose.is_none() {
        ui.label("No head pose: viewing from the calibrated position.");
    }
}

fn state_label(s: DeviceState) -> &'static str {
    match s {
        DeviceState::Opening => "opening",
        DeviceState::Running => "running",
        DeviceState::Stale => "stale",
        DeviceState::Lost => "lost",
        DeviceState::Stopped => "stopped",
    }
}

/// Calibration: the screen rectangle and the default viewing position (the corner-touching
/// calibration tool arrives with the tools).
pub fn calibration_ui(ui: &mut egui::Ui, state: &AppState) {
    let c = &state.calibration;
    ui.label(format!("Profile: {}", c.name));
    ui.label(format!(
        "Screen {:.3} × {:.3} m, centre {:.3?}, residual {:.1} mm",
        c.screen.width_m(),
        c.screen.height_m(),
        c.screen.center_m().to_array(),
        c.residual_m * 1e3
    ));
    ui.label(format!(
        "Viewing position {:.3?} m; IPD {:.1} mm",
        c.default_head.position_m.to_array(),
        c.head_eyes.ipd_m * 1e3
    ));
}

/// Stereo: output mode, eye swap and IPD, and why rendering fails if it does.
pub fn stereo_ui(ui: &mut egui::Ui, state: &mut AppState) {
    if let Some(e) = &state.render_failure {
        ui.colored_label(
            egui::Color32::from_rgb(230, 80, 60),
            format!("Rendering failed: {e}"),
        );
    }
    let mut mode = state.output.mode;
    egui::ComboBox::from_label("Stereo mode")
        .selected_text(mode.label())
        .show_ui(ui, |ui| {
            for m in StereoMode::ALL {
                ui.selectable_value(&mut mode, m, m.label());
            }
        });
    state.output.mode = mode;
    ui.checkbox(&mut state.output.swap_eyes, "Swap eyes");
    let profile_ipd_mm = state.calibration.head_eyes.ipd_m * 1e3;
    let mut ipd_mm = state
        .view_settings
        .ipd_override_m
        .map_or(profile_ipd_mm, |v| v * 1e3);
    if ui
        .add(slider(&mut ipd_mm, 0.0..=80.0).text("IPD (mm)"))
        .changed()
    {
        state.view_settings.ipd_override_m = Some(ipd_mm * 1e-3);
    }
    if let Some(v) = &state.last_views {
        ui.label(format!(
            "IPD used {:.1} mm{}",
            v.ipd_used_m * 1e3,
            if v.clamped {
                " (eye clamped to the screen)"
            } else {
                ""
            }
        ));
    }
}

/// Every panel, stacked (the side panel of the window).
pub fn panels_ui(ui: &mut egui::Ui, state: &mut AppState) {
    egui::CollapsingHeader::new("Character")
        .default_open(true)
        .show(ui, |ui| character_ui(ui, state));
    egui::CollapsingHeader::new("Simulation")
        .default_open(true)
        .show(ui, |ui| simulation_ui(ui, state));
    egui::CollapsingHeader::new("Devices")
        .default_open(true)
        .show(ui, |ui| devices_ui(ui, state));
    egui::CollapsingHeader::new("Stereo")
        .default_open(true)
        .show(ui, |ui| stereo_ui(ui, state));
    egui::CollapsingHeader::new("Calibration")
        .default_open(false)
        .show(ui, |ui| calibration_ui(ui, state));
}
