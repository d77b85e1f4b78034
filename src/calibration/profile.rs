//! Calibration profiles: the screen rectangle, tracker frames, eye offsets and filter settings,
//! kept in a versioned TOML file (format in docs/calibration.md).

use super::frames::{BaselineMode, HeadEyes, TrackerFrames};
use super::screen::ScreenRect;
use crate::pose::Pose;
use crate::tracking::FilterConfig;
use glam::{Quat, Vec3};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The file format version this build reads and writes.
pub const PROFILE_VERSION: u32 = 1;

/// The default desktop monitor's width (a typical 24" 16:9 panel).
pub const DEFAULT_SCREEN_WIDTH_M: f32 = 0.53;
/// The default desktop monitor's height.
pub const DEFAULT_SCREEN_HEIGHT_M: f32 = 0.30;
/// The default viewer distance from the screen.
pub const DEFAULT_VIEWER_DISTANCE_M: f32 = 0.6;

/// Everything the stereo code needs to know about the room: screen, trackers, eyes.
#[derive(Debug, Clone, PartialEq)]
pub struct CalibrationProfile {
    /// Free-form name.
    pub name: String,
    /// The screen rectangle in the world frame.
    pub screen: ScreenRect,
    /// RMS distance of the measured corners from the fitted rectangle (0 for a typed-in screen).
    pub residual_m: f32,
    /// Head sensor to eyes.
    pub head_eyes: HeadEyes,
    /// Whether the eye baseline follows the head's rotation.
    pub baseline: BaselineMode,
    /// Where the head sensor is assumed to be (world frame) when no head tracker is present.
    pub default_head: Pose,
    /// Tracker base in the world and the wand's tip offset.
    pub tracker: TrackerFrames,
    /// Filter for the head sensor.
    pub head_filter: FilterConfig,
    /// Filter for the wand (3D mouse) sensor.
    pub wand_filter: FilterConfig,
}

impl Default for CalibrationProfile {
    /// The default desktop: a 0.53 m × 0.30 m monitor centred on the world origin in the plane
    /// z = 0 (facing +Z), the viewer's eye midpoint 0.6 m in front of its centre.
    fn default() -> Self {
        let screen = ScreenRect {
            lower_left_m: Vec3::new(
                -DEFAULT_SCREEN_WIDTH_M / 2.0,
                -DEFAULT_SCREEN_HEIGHT_M / 2.0,
                0.0,
            ),
            lower_right_m: Vec3::new(
                DEFAULT_SCREEN_WIDTH_M / 2.0,
                -DEFAULT_SCREEN_HEIGHT_M / 2.0,
                0.0,
            ),
            upper_left_m: Vec3::new(
                -DEFAULT_SCREEN_WIDTH_M / 2.0,
                DEFAULT_SCREEN_HEIGHT_M / 2.0,
                0.0,
            ),
        };
        Self {
            name: "default desktop".to_owned(),
            screen,
            residual_m: 0.0,
            head_eyes: HeadEyes::default(),
            baseline: BaselineMode::FollowHead,
            default_head: Pose::from_translation(Vec3::new(0.0, 0.0, DEFAULT_VIEWER_DISTANCE_M)),
            tracker: TrackerFrames::default(),
            head_filter: FilterConfig::HEAD,
            wand_filter: FilterConfig::WAND,
        }
    }
}

/// Loading or saving a profile failed; every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum ProfileError {
    /// The file could not be read.
    #[error("cannot read calibration profile {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// The file is not valid TOML or does not match the format.
    #[error("calibration profile {path}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// The parser's message (with line, column and key).
        message: String,
    },
    /// A field has a value that makes no sense.
    #[error("calibration profile {path}: field `{field}`: {message}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// Dotted field name, e.g. `screen.lower_left_m`.
        field: String,
        /// What is wrong.
        message: String,
    },
    /// The file could not be written.
    #[error(transparent)]
    Write(#[from] crate::files::WriteError),
}

#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct ProfileFile {
    version: u32,
    #[serde(default)]
    name: String,
    screen: ScreenSection,
    #[serde(default)]
    head: HeadSection,
    #[serde(default)]
    tracker: TrackerSection,
    #[serde(default)]
    filter: FilterSection,
}

#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct ScreenSection {
    lower_left_m: [f32; 3],
    lower_right_m: [f32; 3],
    upper_left_m: [f32; 3],
    #[serde(default)]
    residual_m: f32,
}

#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct HeadSection {
    eye_midpoint_in_sensor_m: [f32; 3],
    interocular_axis_in_sensor: [f32; 3],
    ipd_m: f32,
    baseline: BaselineMode,
    default_position_m: [f32; 3],
    default_orientation_xyzw: [f32; 4],
}

impl Default for HeadSection {
    fn default() -> Self {
        let p = CalibrationProfile::default();
        Self {
            eye_midpoint_in_sensor_m: p.head_eyes.eye_midpoint_in_sensor_m.to_array(),
            interocular_axis_in_sensor: p.head_eyes.interocular_axis_in_sensor.to_array(),
            ipd_m: p.head_eyes.ipd_m,
            baseline: p.baseline,
            default_position_m: p.default_head.position_m.to_array(),
            default_orientation_xyzw: p.default_head.orientation.to_array(),
        }
    }
}

#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct TrackerSection {
    world_from_tracker_position_m: [f32; 3],
    world_from_tracker_orientation_xyzw: [f32; 4],
    wand_tip_in_sensor_m: [f32; 3],
}

impl Default for TrackerSection {
    fn default() -> Self {
        Self {
            world_from_tracker_position_m: [0.0; 3],
            world_from_tracker_orientation_xyzw: [0.0, 0.0, 0.0, 1.0],
            wand_tip_in_sensor_m: [0.0; 3],
        }
    }
}

#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct FilterSection {
    head: FilterConfig,
    wand: FilterConfig,
}

impl Default for FilterSection {
    fn default() -> Self {
        Self {
            head: FilterConfig::HEAD,
            wand: FilterConfig::WAND,
        }
    }
}

fn vec3(path: &Path, field: &str, a: [f32; 3]) -> Result<Vec3, ProfileError> {
    let v = Vec3::from_array(a);
    if v.is_finite() {
        Ok(v)
    } else {
        Err(invalid(path, field, "must be finite".to_owned()))
    }
}

fn unit_quat(path: &Path, field: &str, a: [f32; 4]) -> Result<Quat, ProfileError> {
    let q = Quat::from_array(a);
    if !q.is_finite() || (q.length() - 1.0).abs() > 1e-3 {
        return Err(invalid(
            path,
            field,
            format!("must be a unit quaternion [x, y, z, w], got {a:?}"),
        ));
    }
    // Renormalise only when needed, so a saved profile loads back bit for bit.
    Ok(if (q.length() - 1.0).abs() > 1e-6 {
        q.normalize()
    } else {
        q
    })
}

fn invalid(path: &Path, field: &str, message: String) -> ProfileError {
    ProfileError::Invalid {
        path: path.to_path_buf(),
        field: field.to_owned(),
        message,
    }
}

impl CalibrationProfile {
    /// Reads and checks a profile file.
    pub fn load(path: &Path) -> Result<Self, ProfileError> {
        let text = std::fs::read_to_string(path).map_err(|source| ProfileError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_toml_str(&text, path)
    }

    /// Parses and checks a profile; `path` is only used in error messages.
    pub fn from_toml_str(text: &str, path: &Path) -> Result<Self, ProfileError> {
        // Check the version first, so a future file gets a clear message rather than a field
        // error.
        #[derive(Deserialize)]
        struct VersionOnly {
            version: Option<toml::Value>,
        }
        let parse_err = |e: toml::de::Error| ProfileError::Parse {
            path: path.to_path_buf(),
            message: e.to_string().trim_end().to_owned(),
        };
        let v: VersionOnly = toml::from_str(text).map_err(parse_err)?;
        match v.version {
            Some(toml::Value::Integer(n)) if n == i64::from(PROFILE_VERSION) => {}
            Some(other) => {
                return Err(invalid(
                    path,
                    "version",
                    format!("this build reads version {PROFILE_VERSION}, found {other}"),
                ));
            }
            None => return Err(invalid(path, "version", "missing".to_owned())),
        }
        let f: ProfileFile = toml::from_str(text).map_err(parse_err)?;
        let screen = ScreenRect::new(
            vec3(path, "screen.lower_left_m", f.screen.lower_left_m)?,
            vec3(path, "screen.lower_right_m", f.screen.lower_right_m)?,
            vec3(path, "screen.upper_left_m", f.screen.upper_left_m)?,
        )
        .map_err(|e| invalid(path, "screen", e.to_string()))?;
        if !(f.screen.residual_m.is_finite() && f.screen.residual_m >= 0.0) {
            return Err(invalid(
                path,
                "screen.residual_m",
                "must be >= 0".to_owned(),
            ));
        }
        let axis = vec3(
            path,
            "head.interocular_axis_in_sensor",
            f.head.interocular_axis_in_sensor,
        )?;
        if (axis.length() - 1.0).abs() > 1e-3 {
            return Err(invalid(
                path,
                "head.interocular_axis_in_sensor",
                format!("must be a unit vector, length is {}", axis.length()),
            ));
        }
        if !(f.head.ipd_m.is_finite() && (0.0..=0.1).contains(&f.head.ipd_m)) {
            return Err(invalid(
                path,
                "head.ipd_m",
                format!("{} m is outside 0..0.1 m", f.head.ipd_m),
            ));
        }
        for (field, cfg) in [
            ("filter.head", f.filter.head),
            ("filter.wand", f.filter.wand),
        ] {
            cfg.validate().map_err(|m| invalid(path, field, m))?;
        }
        Ok(Self {
            name: f.name,
            screen,
            residual_m: f.screen.residual_m,
            head_eyes: HeadEyes {
                eye_midpoint_in_sensor_m: vec3(
                    path,
                    "head.eye_midpoint_in_sensor_m",
                    f.head.eye_midpoint_in_sensor_m,
                )?,
                interocular_axis_in_sensor: if (axis.length() - 1.0).abs() > 1e-6 {
                    axis.normalize()
                } else {
                    axis
                },
                ipd_m: f.head.ipd_m,
            },
            baseline: f.head.baseline,
            default_head: Pose::new(
                vec3(path, "head.default_position_m", f.head.default_position_m)?,
                unit_quat(
                    path,
                    "head.default_orientation_xyzw",
                    f.head.default_orientation_xyzw,
                )?,
            ),
            tracker: TrackerFrames {
                world_from_tracker: Pose::new(
                    vec3(
                        path,
                        "tracker.world_from_tracker_position_m",
                        f.tracker.world_from_tracker_position_m,
                    )?,
                    unit_quat(
                        path,
                        "tracker.world_from_tracker_orientation_xyzw",
                        f.tracker.world_from_tracker_orientation_xyzw,
                    )?,
                ),
                wand_tip_in_sensor_m: vec3(
                    path,
                    "tracker.wand_tip_in_sensor_m",
                    f.tracker.wand_tip_in_sensor_m,
                )?,
            },
            head_filter: f.filter.head,
            wand_filter: f.filter.wand,
        })
    }

    /// The profile as TOML text (with a short header comment).
    pub fn to_toml_string(&self) -> String {
        let f = ProfileFile {
            version: PROFILE_VERSION,
            name: self.name.clone(),
            screen: ScreenSection {
                lower_left_m: self.screen.lower_left_m.to_array(),
                lower_right_m: self.screen.lower_right_m.to_array(),
                upper_left_m: self.screen.upper_left_m.to_array(),
                residual_m: self.residual_m,
            },
            head: HeadSection {
                eye_midpoint_in_sensor_m: self.head_eyes.eye_midpoint_in_sensor_m.to_array(),
                interocular_axis_in_sensor: self.head_eyes.interocular_axis_in_sensor.to_array(),
                ipd_m: self.head_eyes.ipd_m,
                baseline: self.baseline,
                default_position_m: self.default_head.position_m.to_array(),
                default_orientation_xyzw: self.default_head.orientation.to_array(),
            },
            tracker: TrackerSection {
                world_from_tracker_position_m: self
                    .tracker
                    .world_from_tracker
                    .position_m
                    .to_array(),
                world_from_tracker_orientation_xyzw: self
                    .tracker
                    .world_from_tracker
                    .orientation
                    .to_array(),
                wand_tip_in_sensor_m: self.tracker.wand_tip_in_sensor_m.to_array(),
            },
            filter: FilterSection {
                head: self.head_filter,
                wand: self.wand_filter,
            },
        };
        let body = toml::to_string(&f).unwrap_or_default();
        format!(
            "# leman calibration profile (format: docs/calibration.md). Metres, world frame, +Y up.\n{body}"
        )
    }

    /// Writes the profile atomically.
    pub fn save(&self, path: &Path) -> Result<(), ProfileError> {
        crate::files::write_atomic(path, self.to_toml_string().as_bytes())?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_profile_round_trips_through_toml() {
        let p = CalibrationProfile::default();
        let text = p.to_toml_string();
        let back = CalibrationProfile::from_toml_str(&text, Path::new("x.toml")).expect("parse");
        assert_eq!(back, p);
    }

    #[test]
    fn committed_default_profile_matches_the_built_in_one() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("calibration/desktop.toml");
        let p = CalibrationProfile::load(&path).expect("calibration/desktop.toml loads");
        assert_eq!(p, CalibrationProfile::default());
    }

    #[test]
    fn save_then_load() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("p.toml");
        let mut p = CalibrationProfile {
            name: "bench".into(),
            head_filter: FilterConfig::Raw,
            ..CalibrationProfile::default()
        };
        p.head_eyes.ipd_m = 0.058;
        p.save(&path).expect("save");
        assert_eq!(CalibrationProfile::load(&path).expect("load"), p);
    }

    #[test]
    fn errors_name_the_file_and_field() {
        let good = CalibrationProfile::default().to_toml_string();
        let f = Path::new("bench.toml");
        let err = |text: &str| {
            CalibrationProfile::from_toml_str(text, f)
                .expect_err("must fail")
                .to_string()
        };
        let e = err(&good.replace("version = 1", "version = 7"));
        assert!(e.contains("bench.toml") && e.contains("version"), "{e}");
        let e = err(&good.replace("ipd_m = 0.063", "ipd_m = 6.3"));
        assert!(e.contains("bench.toml") && e.contains("head.ipd_m"), "{e}");
        let e = err(&good.replace("ipd_m = 0.063", "ipd_mm = 63"));
        assert!(e.contains("bench.toml") && e.contains("ipd_mm"), "{e}");
        let e = err(&good.replace("lower_right_m = [0.265", "lower_right_m = [26.5"));
        assert!(e.contains("bench.toml") && e.contains("screen"), "{e}");
        let e = err("version = 1\n[screen]\nlower_left_m = [0, 0]\n");
        assert!(
            e.contains("bench.toml") && e.contains("lower_left_m"),
            "{e}"
        );
        let e = err("not toml at all [");
        assert!(e.contains("bench.toml"), "{e}");
        let missing = CalibrationProfile::load(Path::new("/no/such/profile.toml"))
            .expect_err("missing")
            .to_string();
        assert!(missing.contains("/no/such/profile.toml"), "{missing}");
    }
}
