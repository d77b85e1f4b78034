//! Character files from damaged or hostile sources. Whatever the bytes, loading either refuses
//! them with an error that names the file, or gives a character that the simulator either
//! refuses with an error or runs without panicking and without a non-finite position leaving
//! it. The inputs are a saved example with random damage: numbers swapped for extreme values,
//! lines deleted or repeated, the text cut short, bytes inserted.

use std::path::Path;

use leman::character::{Character, Motion, Posture, examples};
use leman::sim::surface::SurfaceModel;
use leman::sim::{
    AdvanceEnd, DeformationModel, FixedPosture, IntegratorKind, MaxAttempts, MotionPoses,
    PoseSource,
};
use proptest::prelude::*;

mod common;
use common::damage::{damage, damaged, find, number_spans};

/// The text of a small saved example: an 8×6 wombat has every kind of shape, deformations tied
/// to joints, tissue springs and a motion, and simulates in milliseconds.
fn original() -> Vec<u8> {
    let c = examples::build("wombat", 8, 6).expect("the wombat example");
    c.to_toml_string().into_bytes()
}

/// Loads `bytes` through a file, as a user's file would be; what loads must survive a save
/// and load unchanged, is run with `kind`, and is run again after a change of resolution to
/// `resolution`, both as `leman simulate --resolution` makes it (a resampled character) and
/// as the workstation does (the running model resampled).
fn load_and_run(
    bytes: &[u8],
    dir: &Path,
    kind: IntegratorKind,
    resolution: (u32, u32),
) -> Result<(), TestCaseError> {
    let path = dir.join("damaged.toml");
    std::fs::write(&path, bytes).expect("write the damaged file");
    let character = match Character::load(&path) {
        Ok(c) => c,
        Err(e) => {
            let message = e.to_string();
            prop_assert!(
                message.contains("damaged.toml"),
                "the error names the file: {message}"
            );
            return Ok(());
        }
    };
    match Character::from_toml_str(&character.to_toml_string(), &path) {
        Ok(again) => prop_assert!(again == character, "a save and load changed what loaded"),
        Err(e) => prop_assert!(false, "what loaded does not load again once saved: {e}"),
    }
    let motion = character.motions.first().cloned();
    let neutral = Posture::neutral(&character.skeleton);
    let (around, along) = resolution;
    // As `leman simulate --resolution` makes it: a resampled character (or an error).
    if let Ok(resampled) = character.with_resolution(around, along)
        && let Ok(mut model) = SurfaceModel::new(resampled, kind)
    {
        run_until(&mut model, 0.03, motion.as_ref(), &neutral)?;
    }
    let Ok(mut model) = SurfaceModel::new(character, kind) else {
        return Ok(());
    };
    run_until(&mut model, 0.05, motion.as_ref(), &neutral)?;
    // As the workstation does: the running model resampled (or an error).
    if model.set_resolution(around, along).is_ok() {
        run_until(&mut model, 0.08, motion.as_ref(), &neutral)?;
    }
    Ok(())
}

/// Advances `model` to `time_s` playing `motion` (or holding `neutral`): it must get somewhere
/// or say it cannot, and no non-finite position may come out.
fn run_until(
    model: &mut SurfaceModel,
    time_s: f64,
    motion: Option<&Motion>,
    neutral: &Posture,
) -> Result<(), TestCaseError> {
    let mut fixed = FixedPosture(neutral.clone());
    let mut playing = motion.map(MotionPoses);
    let poses: &mut dyn PoseSource = match playing.as_mut() {
        Some(p) => p,
        None => &mut fixed,
    };
    let report = model.advance(time_s, poses, &mut MaxAttempts(300), None);
    // 300 attempts without a step and without the guard giving up is a retry loop that would
    // hang `leman simulate`.
    prop_assert!(
        report.end != AdvanceEnd::BudgetSpent || report.steps > 0,
        "attempts without progress: {report:?}"
    );
    for p in model.positions_m() {
        prop_assert!(
            p.is_finite(),
            "a non-finite skin position left the simulator"
        );
    }
    Ok(())
}

#[test]
fn the_undamaged_file_loads_and_runs() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("whole.toml");
    std::fs::write(&path, original()).expect("write");
    let c = Character::load(&path).expect("the saved example loads");
    let mut model = SurfaceModel::new(c, IntegratorKind::Verlet).expect("and simulates");
    let motion = model.character().motions[0].clone();
    let r = model.advance(0.05, &mut MotionPoses(&motion), &mut MaxAttempts(60), None);
    assert!(r.steps > 0, "it takes steps");
    // The scanner finds the numbers the damage works on.
    let text = original();
    let skin = find(&text, b"\n[skin]").expect("a skin table");
    let early = number_spans(&text).iter().filter(|s| s.0 < skin).count();
    assert!(early > 100, "{early} numbers before the skin");
    assert!(number_spans(&text).len() > early + 500);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(common::cases_or(500)))]

    #[test]
    fn damaged_character_files_are_refused_or_run_finite(
        damages in proptest::collection::vec(damage(), 1..4),
        kind in prop_oneof![
            Just(IntegratorKind::Euler),
            Just(IntegratorKind::Verlet),
            Just(IntegratorKind::Rk2),
            Just(IntegratorKind::Rk4),
        ],
        resolution in (prop_oneof![0u32..3, 3u32..24], prop_oneof![0u32..3, 3u32..24]),
    ) {
        let bytes = damaged(original(), &damages, b"\n[skin]");
        let dir = tempfile::tempdir().expect("tempdir");
        load_and_run(&bytes, dir.path(), kind, resolution)?;
    }
}
