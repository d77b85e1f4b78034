//! Calibration and device profiles from damaged sources. Whatever the bytes, loading either
//! refuses them with an error naming the file, or gives a profile that survives a save and
//! load unchanged; a calibration profile that loads gives finite eye views for its own default
//! head pose, or an error (never a non-finite matrix for the renderer). Nothing panics.

use std::path::Path;

use leman::calibration::CalibrationProfile;
use leman::devices::profile::Profile;
use leman::stereo::view::{ViewSettings, eye_views};
use proptest::prelude::*;

mod common;
use common::damage::{damage, damaged};

/// Profiles have no bulk data: every number is a setting.
const NO_BULK: &[u8] = b"\0";

/// Writes `bytes` to a file named `name` in `dir` and returns its path.
fn write(dir: &Path, name: &str, bytes: &[u8]) -> std::path::PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, bytes).expect("write the damaged file");
    path
}

fn calibration_text() -> Vec<u8> {
    CalibrationProfile::default().to_toml_string().into_bytes()
}

fn devices_text() -> Vec<u8> {
    Profile::desktop_default()
        .to_toml()
        .expect("the desktop profile serialises")
        .into_bytes()
}

#[test]
fn the_undamaged_profiles_load() {
    let dir = tempfile::tempdir().expect("tempdir");
    let c = CalibrationProfile::load(&write(dir.path(), "c.toml", &calibration_text()));
    assert_eq!(c.expect("loads"), CalibrationProfile::default());
    let d = Profile::load(&write(dir.path(), "d.toml", &devices_text()));
    assert_eq!(d.expect("loads"), Profile::desktop_default());
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(common::cases_or(400)))]

    #[test]
    fn damaged_calibration_profiles_are_refused_or_give_finite_views(
        damages in prop::collection::vec(damage(), 1..4),
    ) {
        let bytes = damaged(calibration_text(), &damages, NO_BULK);
        let dir = tempfile::tempdir().expect("tempdir");
        let path = write(dir.path(), "damaged_calibration.toml", &bytes);
        match CalibrationProfile::load(&path) {
            Err(e) => {
                let message = e.to_string();
                prop_assert!(message.contains("damaged_calibration.toml"), "{message}");
            }
            Ok(profile) => {
                let again = CalibrationProfile::from_toml_str(&profile.to_toml_string(), &path);
                prop_assert!(again.as_ref().ok() == Some(&profile), "a save and load changed it");
                if let Ok(views) = eye_views(&profile, &profile.default_head, &ViewSettings::default()) {
                    for v in [&views.left, &views.right, &views.center] {
                        prop_assert!(v.clip_from_world.is_finite(), "a non-finite projection");
                        prop_assert!(v.position_m.is_finite());
                    }
                }
            }
        }
    }

    #[test]
    fn damaged_device_profiles_are_refused_or_round_trip(
        damages in prop::collection::vec(damage(), 1..4),
    ) {
        let bytes = damaged(devices_text(), &damages, NO_BULK);
        let dir = tempfile::tempdir().expect("tempdir");
        let path = write(dir.path(), "damaged_devices.toml", &bytes);
        match Profile::load(&path) {
            Err(e) => {
                let message = e.to_string();
                prop_assert!(message.contains("damaged_devices.toml"), "{message}");
            }
            Ok(profile) => {
                let text = profile.to_toml();
                prop_assert!(text.is_ok(), "a loaded profile does not serialise: {:?}", text.err());
                let again = Profile::parse(&text.unwrap_or_default(), &path);
                prop_assert!(again.as_ref().ok() == Some(&profile), "a save and load changed it: {:?}", again.err());
            }
        }
    }
}
