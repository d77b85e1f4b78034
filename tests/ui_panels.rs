//! The workstation's egui panels driven headless with egui_kittest: find widgets by label,
//! click and type, and check that the app state changed (and that parameter changes reach the
//! running simulation at the next frame).

use egui_kittest::Harness;
use egui_kittest::kittest::{NodeT, Queryable};
use leman::app::scheduler::{Pacing, Scheduler, SchedulerConfig};
use leman::app::setup;
use leman::app::state::{AppState, FrameRenderer};
use leman::calibration::CalibrationProfile;
use leman::clock::VirtualClock;
use leman::devices::profile::Profile;
use leman::devices::replay::ClockedReplay;
use leman::devices::session::Session;
use leman::render::scene::Scene;
use leman::sim::{IntegratorKind, ParameterChange};
use leman::stereo::{OutputSettings, StereoMode, StereoViews};
use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

struct CountingRenderer(u64);

impl FrameRenderer for CountingRenderer {
    fn render(
        &mut self,
        scene: &Scene,
        _views: &StereoViews,
        _output: &OutputSettings,
        _frame_index: u64,
    ) -> Result<(), String> {
        assert!(scene.skin.is_some());
        self.0 += 1;
        Ok(())
    }
}

/// A [`CountingRenderer`] that fails while `failing` is set, with the message a too-large
/// stereo output gives.
struct FlakyRenderer {
    failing: bool,
    counting: CountingRenderer,
}

impl FrameRenderer for FlakyRenderer {
    fn render(
        &mut self,
        scene: &Scene,
        views: &StereoViews,
        output: &OutputSettings,
        frame_index: u64,
    ) -> Result<(), String> {
        if self.failing {
            return Err("render target 16384×8192 px is larger than the device's 8192 px".into());
        }
        self.counting.render(scene, views, output, frame_index)
    }
}

fn state() -> (AppState, VirtualClock) {
    state_with(|_| {})
}

/// [`state`] with the loaded character changed by `edit` first.
fn state_with(edit: impl FnOnce(&mut leman::character::Character)) -> (AppState, VirtualClock) {
    state_for(edit, Profile::desktop_default())
}

/// [`state_with`] on a replay of an empty session recorded with `profile`.
fn state_for(
    edit: impl FnOnce(&mut leman::character::Character),
    profile: Profile,
) -> (AppState, VirtualClock) {
    state_replaying(edit, Session::new(profile))
}

/// The torso_16 state of [`state_for`], its devices replaying `session`.
fn state_replaying(
    edit: impl FnOnce(&mut leman::character::Character),
    session: Session,
) -> (AppState, VirtualClock) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/characters/torso_16.toml");
    let mut character = setup::load_character(Some(&path)).expect("character");
    edit(&mut character);
    let model = setup::surface_model(&character, IntegratorKind::Verlet);
    assert!(model.is_ok(), "model: {:?}", model.as_ref().err());
    let clock = VirtualClock::new();
    let devices = ClockedReplay::new(session, Arc::new(clock.clone())).expect("replay");
    let scheduler = Scheduler::new(
        SchedulerConfig {
            pacing: Pacing::Offline,
            ..SchedulerConfig::default()
        },
        0.0,
    )
    .expect("scheduler");
    let state = AppState::new(
        character,
        model,
        CalibrationProfile::default(),
        Box::new(devices),
        scheduler,
    );
    (state, clock)
}

fn harness(state: AppState) -> Harness<'static, AppState> {
    Harness::builder()
        .with_size(egui::vec2(420.0, 1800.0))
        .build_ui_state(
            |ui, state: &mut AppState| {
                leman::ui::toolbar_ui(ui, state);
                leman::ui::panels_ui(ui, state);
            },
            state,
        )
}

#[test]
fn the_simulation_switch_turns_the_simulation_off_and_on() {
    let (state, _clock) = state();
    let mut h = harness(state);
    h.run();
    assert!(h.state().simulation_on);
    h.get_by_label("Simulate the skin").click();
    h.run();
    assert!(!h.state().simulation_on);
    // The toolbar's toggle is the same switch.
    h.get_by_label("Simulate").click();
    h.run();
    assert!(h.state().simulation_on);
}

#[test]
fn choosing_a_stereo_mode_and_an_integrator_changes_the_state() {
    let (state, _clock) = state();
    let mut h = harness(state);
    h.run();
    h.get_by_role_and_label(egui::accesskit::Role::ComboBox, "Stereo mode")
        .click();
    h.run();
    h.get_by_label("anaglyph red-cyan").click();
    h.run();
    assert_eq!(h.state().output.mode, StereoMode::AnaglyphRedCyan);

    h.get_by_role_and_label(egui::accesskit::Role::ComboBox, "Integrator")
        .click();
    h.run();
    h.get_by_label("Runge-Kutta 2(1)").click();
    h.run();
    assert_eq!(h.state().integrator, IntegratorKind::Rk2);
    assert!(
        h.state()
            .pending_changes
            .contains(&ParameterChange::Integrator(IntegratorKind::Rk2))
    );
}

#[test]
fn a_parameter_changed_in_the_panel_reaches_the_running_simulation() {
    let (state, clock) = state();
    let mut h = harness(state);
    h.run();
    let fat_before = h.state().params.fat_m;
    let slider = h.get_by_role_and_label(egui::accesskit::Role::Slider, "Fat (m)");
    slider.focus();
    h.run();
    h.key_press(egui::Key::ArrowRight);
    h.run();
    let fat_after = h.state().params.fat_m;
    assert!(fat_after > fat_before, "{fat_before} -> {fat_after}");
    assert!(
        h.state()
            .pending_changes
            .iter()
            .any(|c| matches!(c, ParameterChange::Fat(_, v) if (*v - fat_after).abs() < 1e-6)),
        "{:?}",
        h.state().pending_changes
    );
    // Run simulation frames: the change is applied between steps and the queue empties.
    let mut renderer = CountingRenderer(0);
    for n in 0..3u32 {
        clock.set(Duration::from_millis(17) * n);
        let record = h.state_mut().run_frame(&clock, &mut renderer);
        assert!(record.sim_steps > 0);
    }
    assert!(h.state().pending_changes.is_empty());
    assert!(h.state().sim_error.is_none(), "{:?}", h.state().sim_error);
    assert_eq!(renderer.0, 3);
    // The live Table 1 counts the points the constraint phase pushed out (the skin rests on
    // the muscles) and shows the row.
    let t1 = h.state().table1;
    assert!(
        t1.totals.pushed_per_step().is_some_and(|p| p > 0.0),
        "{:?}",
        t1.totals
    );
    h.run();
    assert!(h.query_by_label("Points pushed out / step").is_some());
}

#[test]
fn the_recheck_slider_changes_the_running_simulation_threshold() {
    let (state, clock) = state();
    let mut h = harness(state);
    h.run();
    let before = h.state().recheck_fraction;
    assert_eq!(before, 0.1, "the character file's default");
    let slider = h.get_by_role_and_label(egui::accesskit::Role::Slider, "re-check above (× ε_c)");
    slider.focus();
    h.run();
    h.key_press(egui::Key::ArrowRight);
    h.run();
    let after = h.state().recheck_fraction;
    assert!(after > before && after <= 1.0, "{before} -> {after}");
    assert!(
        h.state()
            .pending_changes
            .contains(&ParameterChange::RecheckFraction(after)),
        "{:?}",
        h.state().pending_changes
    );
    let mut renderer = CountingRenderer(0);
    for n in 0..2u32 {
        clock.set(Duration::from_millis(17) * n);
        h.state_mut().run_frame(&clock, &mut renderer);
    }
    assert!(h.state().pending_changes.is_empty());
    assert!(h.state().sim_error.is_none(), "{:?}", h.state().sim_error);
}

#[test]
fn the_hold_checkbox_switches_resting_contact_in_the_running_simulation() {
    let (state, clock) = state();
    let mut h = harness(state);
    h.run();
    assert!(h.state().hold_contacts, "the character file's default");
    h.get_by_label("muscles hold resting skin").click();
    h.run();
    assert!(!h.state().hold_contacts);
    assert!(
        h.state()
            .pending_changes
            .contains(&ParameterChange::HoldContacts(false)),
        "{:?}",
        h.state().pending_changes
    );
    let mut renderer = CountingRenderer(0);
    for n in 0..3u32 {
        clock.set(Duration::from_millis(17) * n);
        h.state_mut().run_frame(&clock, &mut renderer);
    }
    assert!(h.state().pending_changes.is_empty());
    assert!(h.state().sim_error.is_none(), "{:?}", h.state().sim_error);
    assert_eq!(
        h.state().table1.totals.held_points,
        0,
        "nothing held once switched off"
    );
    h.run();
    assert!(h.query_by_label("Points held on muscles / step").is_some());
}

#[test]
fn a_stalled_simulation_says_so_in_the_panel_and_a_running_one_does_not() {
    let stalled = |moved_m: f32, kind: IntegratorKind| {
        let (state, clock) = state_with(|c| {
            // Every tissue spring stretched by `moved_m`: out of range at any step size.
            for s in &mut c.shapes {
                s.joint_from_shape.position_m.y -= moved_m;
            }
        });
        let mut h = harness(state);
        // As the panel's integrator menu does.
        h.state_mut().integrator = kind;
        h.state_mut()
            .queue_change(ParameterChange::Integrator(kind));
        let mut renderer = CountingRenderer(0);
        // Past the scheduler's ratio window, so the ratio line gives its verdict.
        let window = h.state().scheduler.config().ratio_window_frames as u32;
        for n in 0..=window {
            clock.set(Duration::from_millis(17) * n);
            h.state_mut().run_frame(&clock, &mut renderer);
        }
        h.run();
        let shown = h
            .query_by_label_contains("Stalled at t = 0.000 s")
            .is_some();
        // The ratio is not held, and not for want of machine.
        let said = h
            .query_by_label_contains("NOT held: the simulation stalled")
            .is_some();
        let blamed = h.query_by_label_contains("machine too slow").is_some();
        // Only a fixed-step method is told about its step.
        let step = h
            .query_by_label_contains("shorten the Euler step")
            .is_some();
        (h.state().sim_stalled_at_s, shown, said, blamed, step)
    };
    let verlet = IntegratorKind::Verlet;
    assert_eq!(
        stalled(1000.0, verlet),
        (Some(0.0), true, true, false, false)
    );
    assert_eq!(stalled(0.0, verlet), (None, false, false, false, false));
    let euler = IntegratorKind::Euler;
    assert_eq!(stalled(1000.0, euler), (Some(0.0), true, true, false, true));
}

/// Drawing the panels changes nothing by itself: values the character file may hold that a
/// slider's range does not cover (re-check at 0.8 ε_c, ε_c of 30 mm) or that are finer than
/// the slider shows (the torso's point mass 0.0078125 kg, shown to 5 decimals) are not clamped
/// or rounded into the slider and sent to the simulation. Only what the state queued when it
/// was made is pending.
#[test]
fn drawing_the_panels_does_not_rewrite_loaded_values() {
    let (state, _clock) = state_with(|c| {
        c.simulation.recheck_fraction = 0.8;
        c.simulation.epsilon_c_m = 0.03;
    });
    let queued = state.pending_changes.clone();
    let params = state.params;
    let mut h = harness(state);
    h.run();
    h.run();
    assert_eq!(h.state().recheck_fraction, 0.8);
    assert_eq!(h.state().epsilon_c_m, 0.03);
    assert_eq!(h.state().params, params);
    assert_eq!(h.state().pending_changes, queued);
}

#[test]
fn the_devices_panel_lists_the_roles_after_a_frame_and_tools_say_they_are_not_built() {
    let (state, clock) = state();
    let mut h = harness(state);
    h.run();
    assert!(h.query_by_label("no device snapshot yet").is_some());
    let mut renderer = CountingRenderer(0);
    h.state_mut().run_frame(&clock, &mut renderer);
    h.run();
    assert!(h.query_by_label("no device snapshot yet").is_none());
    for role in ["head", "wand", "navigation"] {
        assert!(h.query_by_label(role).is_some(), "{role} row missing");
    }
    // The tool slots exist; the construction tools are disabled until issue #6.
    let sphere = h.get_by_label("Sphere");
    assert!(sphere.accesskit_node().is_disabled());
    assert!(!h.get_by_label("Navigate").accesskit_node().is_disabled());
}

/// With a SpaceMouse in the profile that never delivers, the keyboard flies in its place and
/// the devices panel says so; the desktop default's rows say nothing of standing in.
#[test]
fn the_devices_panel_shows_the_keyboard_standing_in_for_a_missing_spacemouse() {
    let found = leman::devices::found::default_profile();
    // (profile, rows of the desktop's own roles, rows it stands in for)
    for (profile, own, standing_in) in [(found, 2, 1), (Profile::desktop_default(), 3, 0)] {
        let (state, clock) = state_for(|_| {}, profile);
        let mut h = harness(state);
        let mut renderer = CountingRenderer(0);
        h.state_mut().run_frame(&clock, &mut renderer);
        h.run();
        let rows = |label| h.query_all_by_label(label).count();
        assert_eq!(rows("desktop (desktop)"), own);
        assert_eq!(rows("desktop (desktop, standing in)"), standing_in);
    }
}

/// A lost device's row says why it is lost (the role's row names only the desktop standing
/// in for it).
#[test]
fn the_devices_panel_says_why_a_device_is_lost() {
    use leman::devices::session::Record;
    let found = leman::devices::found::default_profile();
    let spacemouse = found
        .device_index(leman::devices::found::SPACEMOUSE_DEVICE)
        .expect("a SpaceMouse entry");
    let error = "cannot open hid any:any: no such HID device is plugged in";
    let mut session = Session::new(found);
    session.records.push(Record::Lost {
        at: Duration::from_millis(5),
        device: spacemouse,
        error: error.into(),
    });
    let (state, clock) = state_replaying(|_| {}, session);
    let mut h = harness(state);
    let mut renderer = CountingRenderer(0);
    clock.set(Duration::from_millis(20));
    h.state_mut().run_frame(&clock, &mut renderer);
    h.run();
    let line = format!("spacemouse (spacemouse-hid) lost: {error}");
    assert!(h.query_by_label(&line).is_some(), "no line {line:?}");
    assert_eq!(
        h.query_all_by_label("desktop (desktop, standing in)")
            .count(),
        1
    );
    // Nothing lost, no such line.
    let (state, clock) = state_for(|_| {}, Profile::desktop_default());
    let mut h = harness(state);
    clock.set(Duration::from_millis(20));
    h.state_mut().run_frame(&clock, &mut renderer);
    h.run();
    assert!(h.query_by_label_contains(" lost: ").is_none());
}

/// A render failure shows in the stereo panel while it lasts (not only in the log) and goes
/// away with the next frame that renders.
#[test]
fn a_failing_render_says_why_in_the_panel_until_a_frame_renders() {
    let (state, clock) = state();
    let mut h = harness(state);
    let mut renderer = FlakyRenderer {
        failing: true,
        counting: CountingRenderer(0),
    };
    let mut frame = 0u32;
    let mut run = |h: &mut Harness<'static, AppState>, r: &mut FlakyRenderer| {
        frame += 1;
        clock.set(Duration::from_millis(17) * frame);
        h.state_mut().run_frame(&clock, r);
        h.run();
    };
    let shown = |h: &Harness<'static, AppState>| {
        h.query_by_label_contains("Rendering failed: render target 16384×8192 px")
            .is_some()
    };
    run(&mut h, &mut renderer);
    assert!(shown(&h), "the failure is not in the panel");
    assert_eq!(
        h.state().render_failure.as_deref(),
        Some("render target 16384×8192 px is larger than the device's 8192 px")
    );
    run(&mut h, &mut renderer);
    assert!(shown(&h), "a second failing frame hid it");
    renderer.failing = false;
    run(&mut h, &mut renderer);
    assert!(renderer.counting.0 > 0, "no frame rendered");
    assert_eq!(h.state().render_failure, None);
    assert!(!shown(&h), "still shown after a frame rendered");
}
