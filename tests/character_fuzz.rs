//! Character files from damaged or hostile sources. Whatever the bytes, loading either refuses
//! them with an error that names the file, or gives a character that the simulator either
//! refuses with an error or runs without panicking and without a non-finite position leaving
//! it. The inputs are a saved example with random damage: numbers swapped for extreme values,
//! lines deleted or repeated, the text cut short, bytes inserted.

use std::path::Path;

use leman::character::{Character, Posture, examples};
use leman::sim::surface::SurfaceModel;
use leman::sim::{
    AdvanceEnd, DeformationModel, FixedPosture, IntegratorKind, MaxAttempts, MotionPoses,
    PoseSource,
};
use proptest::prelude::*;

/// Values that break naive code: zeros, signs, overflow of `f32` and the integer types, NaN
/// and the infinities, a step-sized fraction and big counts.
const NASTY: &[&str] = &[
    "0",
    "-0.0",
    "-1",
    "1",
    "0.5",
    "3",
    "1e30",
    "-1e30",
    "1e-30",
    "1e39",
    "nan",
    "inf",
    "-inf",
    "4294967296",
    "-4294967297",
    "18446744073709551616",
    "1000000",
    "\"text\"",
    "[]",
];

/// One piece of damage to a character file's text.
#[derive(Debug, Clone)]
enum Damage {
    /// Replaces the number at this index (modulo the count) with `NASTY[value % len]`; in
    /// the part before the skin's per-point arrays (simulation settings, skeleton, shapes,
    /// motions) when `early`, anywhere otherwise.
    Number {
        index: usize,
        value: usize,
        early: bool,
    },
    /// Deletes the line at this index (modulo the count).
    DeleteLine(usize),
    /// Repeats the line at this index (modulo the count).
    RepeatLine(usize),
    /// Keeps this fraction of the bytes, in thousandths.
    Truncate(u16),
    /// Inserts a byte at this position (modulo the length).
    InsertByte { at: usize, byte: u8 },
}

fn damage() -> impl Strategy<Value = Damage> {
    prop_oneof![
        6 => (any::<usize>(), any::<usize>(), any::<bool>())
            .prop_map(|(index, value, early)| Damage::Number { index, value, early }),
        1 => any::<usize>().prop_map(Damage::DeleteLine),
        1 => any::<usize>().prop_map(Damage::RepeatLine),
        1 => (0u16..1000).prop_map(Damage::Truncate),
        1 => (any::<usize>(), any::<u8>()).prop_map(|(at, byte)| Damage::InsertByte { at, byte }),
    ]
}

/// Byte ranges of the numeric literals in `text` (a digit, optionally after a sign, and the
/// digits, dots, exponents and signs that follow).
fn number_spans(text: &[u8]) -> Vec<(usize, usize)> {
    let mut spans = Vec::new();
    let mut i = 0;
    while i < text.len() {
        let starts_number = text[i].is_ascii_digit()
            || (matches!(text[i], b'-' | b'+') && text.get(i + 1).is_some_and(u8::is_ascii_digit));
        let after_word = i > 0 && (text[i - 1].is_ascii_alphanumeric() || text[i - 1] == b'_');
        if starts_number && !after_word {
            let begin = i;
            i += 1;
            while i < text.len()
                && (text[i].is_ascii_digit() || matches!(text[i], b'.' | b'e' | b'E' | b'-' | b'+'))
            {
                i += 1;
            }
            spans.push((begin, i));
        } else {
            i += 1;
        }
    }
    spans
}

/// Where `needle` first occurs in `haystack`.
fn find(haystack: &[u8], needle: &[u8]) -> Option<usize> {
    haystack.windows(needle.len()).position(|w| w == needle)
}

fn apply(text: &mut Vec<u8>, d: &Damage) {
    match *d {
        Damage::Number {
            index,
            value,
            early,
        } => {
            let mut spans = number_spans(text);
            if early {
                let skin = find(text, b"\n[skin]").unwrap_or(text.len());
                spans.retain(|&(a, _)| a < skin);
            }
            if let Some(&(a, b)) = spans.get(index % spans.len().max(1)) {
                text.splice(a..b, NASTY[value % NASTY.len()].bytes());
            }
        }
        Damage::DeleteLine(k) | Damage::RepeatLine(k) => {
            let starts: Vec<usize> = std::iter::once(0)
                .chain(
                    text.iter()
                        .enumerate()
                        .filter(|(_, c)| **c == b'\n')
                        .map(|(i, _)| i + 1),
                )
                .filter(|&i| i < text.len())
                .collect();
            if starts.is_empty() {
                return;
            }
            let line = k % starts.len();
            let a = starts[line];
            let b = starts.get(line + 1).copied().unwrap_or(text.len());
            if matches!(d, Damage::DeleteLine(_)) {
                text.drain(a..b);
            } else {
                let copy: Vec<u8> = text[a..b].to_vec();
                text.splice(a..a, copy);
            }
        }
        Damage::Truncate(per_mille) => {
            let keep = text.len() * per_mille as usize / 1000;
            text.truncate(keep);
        }
        Damage::InsertByte { at, byte } => {
            let at = at % (text.len() + 1);
            text.insert(at, byte);
        }
    }
}

/// The text of a small saved example: an 8×6 wombat has every kind of shape, deformations tied
/// to joints, tissue springs and a motion, and simulates in milliseconds.
fn original() -> Vec<u8> {
    let c = examples::build("wombat", 8, 6).expect("the wombat example");
    c.to_toml_string().into_bytes()
}

/// Loads `bytes` through a file, as a user's file would be; what loads must survive a save
/// and load unchanged, and is run with `kind`.
fn load_and_run(bytes: &[u8], dir: &Path, kind: IntegratorKind) -> Result<(), TestCaseError> {
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
    let Ok(mut model) = SurfaceModel::new(character, kind) else {
        return Ok(());
    };
    let mut fixed = FixedPosture(neutral);
    let mut playing = motion.as_ref().map(MotionPoses);
    let poses: &mut dyn PoseSource = match playing.as_mut() {
        Some(p) => p,
        None => &mut fixed,
    };
    let report = model.advance(0.05, poses, &mut MaxAttempts(300), None);
    // Either it gets somewhere or it says it cannot: 300 attempts without a step and without
    // the guard giving up is a retry loop that would hang `leman simulate`.
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
    #![proptest_config(ProptestConfig::with_cases(500))]

    #[test]
    fn damaged_character_files_are_refused_or_run_finite(
        damages in proptest::collection::vec(damage(), 1..4),
        kind in prop_oneof![
            Just(IntegratorKind::Euler),
            Just(IntegratorKind::Verlet),
            Just(IntegratorKind::Rk2),
            Just(IntegratorKind::Rk4),
        ],
    ) {
        let mut bytes = original();
        for d in &damages {
            apply(&mut bytes, d);
        }
        let dir = tempfile::tempdir().expect("tempdir");
        load_and_run(&bytes, dir.path(), kind)?;
    }
}
