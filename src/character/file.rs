//! The character file format: TOML, `format_version = 1` (documented in
//! `docs/character-format.md`).
//!
//! Reading goes through serde and `toml`; writing is done here by hand so that the large
//! per-point arrays come out one value per line (and a per-point array whose values are all
//! equal is written as one value). Floats are written in Rust's shortest round-trip form, so
//! save → load gives back exactly the same [`Character`]. Loading validates everything
//! ([`Character::validate`]); a bad file gives an error naming the file and the problem.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use glam::Vec3;
use serde::{Deserialize, Serialize};

use super::skeleton::{Joint, JointId};
use super::{Character, Motion, Shape, ShapeId, SimulationDefaults, Skin, Sym2, TissueSpring};

/// The only file format version this build reads and writes.
pub const FORMAT_VERSION: u32 = 1;

/// Why a character file could not be loaded or saved. Every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum CharacterFileError {
    /// The file could not be read.
    #[error("cannot read character file {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// Not valid TOML, or a field is missing, unknown or of the wrong type.
    #[error("character file {path}: {message}")]
    Syntax {
        /// The file.
        path: PathBuf,
        /// What the parser said (with line and column).
        message: String,
    },
    /// `format_version` is missing or not one this build understands.
    #[error("character file {path}: {message}")]
    Version {
        /// The file.
        path: PathBuf,
        /// Which version was found.
        message: String,
    },
    /// The content parses but is not a valid character.
    #[error("character file {path}: {problem}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        problem: super::ValidationError,
    },
    /// Saving failed (the old file, if any, is untouched).
    #[error(transparent)]
    Write(#[from] crate::files::WriteError),
    /// Refused to save an invalid character.
    #[error("refusing to save character to {path}: {problem}")]
    SaveInvalid {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        problem: super::ValidationError,
    },
}

/// A per-point (or per-spring) array in the file: one value for all, or one each.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(
    untagged,
    expecting = "one value for all items, or a list with one value per item (numbers; [a, b, c] for tensors and vectors)"
)]
enum PerItem<T> {
    Uniform(T),
    Each(Vec<T>),
}

impl<T: Clone> PerItem<T> {
    fn expand(self, count: usize) -> Vec<T> {
        match self {
            PerItem::Uniform(v) => vec![v; count],
            PerItem::Each(v) => v,
        }
    }
}

#[derive(Deserialize)]
struct VersionOnly {
    format_version: Option<toml::Value>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileDoc {
    #[allow(dead_code)] // checked first, through `VersionOnly`
    format_version: u32,
    name: String,
    simulation: SimulationDefaults,
    joints: Vec<Joint>,
    #[serde(default)]
    shapes: Vec<Shape>,
    #[serde(default)]
    motions: Vec<Motion>,
    skin: SkinDoc,
    #[serde(default)]
    tissue: Option<TissueDoc>,
}

#[derive(Serialize)]
struct HeadDoc<'a> {
    format_version: u32,
    name: &'a str,
    simulation: &'a SimulationDefaults,
    joints: &'a [Joint],
    shapes: &'a [Shape],
    motions: &'a [Motion],
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SkinDoc {
    around: u32,
    along: u32,
    bottom_joint: JointId,
    top_joint: JointId,
    bottom_ring_m: Vec<Vec3>,
    top_ring_m: Vec<Vec3>,
    positions_m: Vec<Vec3>,
    mass_kg: PerItem<f32>,
    damping_n_s_per_m: PerItem<f32>,
    rest_metric: PerItem<Sym2>,
    stretch: PerItem<Sym2>,
    bending: PerItem<Sym2>,
    fat_m: PerItem<f32>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct TissueDoc {
    skin_point: Vec<u32>,
    shape: PerItem<ShapeId>,
    anchor_rest_m: Vec<Vec3>,
    stiffness_n_per_m: PerItem<f32>,
    damping_n_s_per_m: PerItem<f32>,
    rest_length_m: PerItem<f32>,
}

impl Character {
    /// Parses a character from TOML text; `path` is only used in error messages. Validates
    /// the result.
    pub fn from_toml_str(text: &str, path: &Path) -> Result<Character, CharacterFileError> {
        let syntax = |message: String| CharacterFileError::Syntax {
            path: path.to_path_buf(),
            message,
        };
        let version: VersionOnly = toml::from_str(text).map_err(|e| syntax(e.to_string()))?;
        match version.format_version {
            Some(toml::Value::Integer(v)) if v == i64::from(FORMAT_VERSION) => {}
            Some(other) => {
                return Err(CharacterFileError::Version {
                    path: path.to_path_buf(),
                    message: format!(
                        "unknown format_version {other} (this build reads format_version = {FORMAT_VERSION})"
                    ),
                });
            }
            None => {
                return Err(CharacterFileError::Version {
                    path: path.to_path_buf(),
                    message: format!(
                        "format_version is missing (expected format_version = {FORMAT_VERSION})"
                    ),
                });
            }
        }
        let doc: FileDoc = toml::from_str(text).map_err(|e| syntax(e.to_string()))?;
        let s = doc.skin;
        // The listed positions bound the per-point arrays a single value is expanded to: a
        // resolution the positions do not match is refused before anything is allocated for
        // it (`along = 1000000000` asked for 64 GB and aborted).
        let points = s.around as usize * s.along as usize;
        super::skin::check_len(
            "positions_m",
            s.positions_m.len(),
            points,
            s.around,
            s.along,
        )
        .map_err(|problem| CharacterFileError::Invalid {
            path: path.to_path_buf(),
            problem: super::ValidationError(problem),
        })?;
        let skin = Skin {
            around: s.around,
            along: s.along,
            bottom_joint: s.bottom_joint,
            top_joint: s.top_joint,
            bottom_ring_m: s.bottom_ring_m,
            top_ring_m: s.top_ring_m,
            positions_m: s.positions_m,
            mass_kg: s.mass_kg.expand(points),
            damping_n_s_per_m: s.damping_n_s_per_m.expand(points),
            rest_metric: s.rest_metric.expand(points),
            stretch: s.stretch.expand(points),
            bending: s.bending.expand(points),
            fat_m: s.fat_m.expand(points),
        };
        let tissue = match doc.tissue {
            None => Vec::new(),
            Some(t) => {
                let count = t.skin_point.len();
                let shape = t.shape.expand(count);
                let stiffness = t.stiffness_n_per_m.expand(count);
                let damping = t.damping_n_s_per_m.expand(count);
                let rest = t.rest_length_m.expand(count);
                for (what, len) in [
                    ("shape", shape.len()),
                    ("anchor_rest_m", t.anchor_rest_m.len()),
                    ("stiffness_n_per_m", stiffness.len()),
                    ("damping_n_s_per_m", damping.len()),
                    ("rest_length_m", rest.len()),
                ] {
                    if len != count {
                        return Err(CharacterFileError::Invalid {
                            path: path.to_path_buf(),
                            problem: super::ValidationError(format!(
                                "tissue: {what} has {len} values but skin_point has {count}"
                            )),
                        });
                    }
                }
                (0..count)
                    .map(|k| TissueSpring {
                        skin_point: t.skin_point[k],
                        shape: shape[k],
                        anchor_rest_m: t.anchor_rest_m[k],
                        stiffness_n_per_m: stiffness[k],
                        damping_n_s_per_m: damping[k],
                        rest_length_m: rest[k],
                    })
                    .collect()
            }
        };
        let character = Character {
            name: doc.name,
            skeleton: super::Skeleton { joints: doc.joints },
            shapes: doc.shapes,
            skin,
            tissue,
            simulation: doc.simulation,
            motions: doc.motions,
        };
        character
            .validate()
            .map_err(|problem| CharacterFileError::Invalid {
                path: path.to_path_buf(),
                problem,
            })?;
        Ok(character)
    }

    /// Loads and validates a character file. On error nothing is returned.
    pub fn load(path: &Path) -> Result<Character, CharacterFileError> {
        let text = std::fs::read_to_string(path).map_err(|source| CharacterFileError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_toml_str(&text, path)
    }

    /// The character as TOML text (format version [`FORMAT_VERSION`]).
    pub fn to_toml_string(&self) -> String {
        let head = HeadDoc {
            format_version: FORMAT_VERSION,
            name: &self.name,
            simulation: &self.simulation,
            joints: &self.skeleton.joints,
            shapes: &self.shapes,
            motions: &self.motions,
        };
        let mut out = String::new();
        out.push_str("# leman character file; see docs/character-format.md\n");
        // Serialising plain data to TOML cannot fail except for non-finite floats or map
        // keys, which these types do not have; fall back to an explanatory comment.
        match toml::to_string(&head) {
            Ok(text) => out.push_str(&text),
            Err(e) => {
                let _ = writeln!(out, "# could not serialise the head: {e}");
            }
        }
        let s = &self.skin;
        out.push_str("\n[skin]\n");
        let _ = writeln!(out, "around = {}", s.around);
        let _ = writeln!(out, "along = {}", s.along);
        let _ = writeln!(out, "bottom_joint = {}", s.bottom_joint.0);
        let _ = writeln!(out, "top_joint = {}", s.top_joint.0);
        write_vec3s(&mut out, "bottom_ring_m", &s.bottom_ring_m);
        write_vec3s(&mut out, "top_ring_m", &s.top_ring_m);
        write_vec3s(&mut out, "positions_m", &s.positions_m);
        write_scalars(&mut out, "mass_kg", &s.mass_kg);
        write_scalars(&mut out, "damping_n_s_per_m", &s.damping_n_s_per_m);
        write_sym2s(&mut out, "rest_metric", &s.rest_metric);
        write_sym2s(&mut out, "stretch", &s.stretch);
        write_sym2s(&mut out, "bending", &s.bending);
        write_scalars(&mut out, "fat_m", &s.fat_m);
        if !self.tissue.is_empty() {
            out.push_str("\n[tissue]\n");
            let points: Vec<u32> = self.tissue.iter().map(|t| t.skin_point).collect();
            write_ints(&mut out, "skin_point", &points);
            let shapes: Vec<u32> = self.tissue.iter().map(|t| t.shape.0).collect();
            if shapes.windows(2).all(|w| w[0] == w[1]) {
                let _ = writeln!(out, "shape = {}", shapes[0]);
            } else {
                write_ints(&mut out, "shape", &shapes);
            }
            let anchors: Vec<Vec3> = self.tissue.iter().map(|t| t.anchor_rest_m).collect();
            write_vec3s(&mut out, "anchor_rest_m", &anchors);
            let f = |g: fn(&TissueSpring) -> f32| self.tissue.iter().map(g).collect::<Vec<f32>>();
            write_scalars(&mut out, "stiffness_n_per_m", &f(|t| t.stiffness_n_per_m));
            write_scalars(&mut out, "damping_n_s_per_m", &f(|t| t.damping_n_s_per_m));
            write_scalars(&mut out, "rest_length_m", &f(|t| t.rest_length_m));
        }
        out
    }

    /// Validates and saves atomically ([`crate::files::write_atomic`]): a crash never leaves a
    /// half-written file, and an invalid character is not written at all.
    pub fn save(&self, path: &Path) -> Result<(), CharacterFileError> {
        self.validate()
            .map_err(|problem| CharacterFileError::SaveInvalid {
                path: path.to_path_buf(),
                problem,
            })?;
        crate::files::write_atomic(path, self.to_toml_string().as_bytes())?;
        Ok(())
    }
}

/// A float in TOML: Rust's shortest round-trip form, which TOML reads back exactly.
fn float(out: &mut String, v: f32) {
    if v.is_nan() {
        out.push_str("nan");
    } else if v.is_infinite() {
        out.push_str(if v > 0.0 { "inf" } else { "-inf" });
    } else {
        let _ = write!(out, "{v:?}");
    }
}

fn write_vec3s(out: &mut String, key: &str, values: &[Vec3]) {
    let _ = writeln!(out, "{key} = [");
    for v in values {
        out.push_str("  [");
        float(out, v.x);
        out.push_str(", ");
        float(out, v.y);
        out.push_str(", ");
        float(out, v.z);
        out.push_str("],\n");
    }
    out.push_str("]\n");
}

fn write_sym2s(out: &mut String, key: &str, values: &[Sym2]) {
    let one = |out: &mut String, t: &Sym2| {
        out.push('[');
        float(out, t[0]);
        out.push_str(", ");
        float(out, t[1]);
        out.push_str(", ");
        float(out, t[2]);
        out.push(']');
    };
    if let Some(first) = values.first()
        && values
            .iter()
            .all(|v| v.iter().zip(first).all(|(a, b)| a.to_bits() == b.to_bits()))
    {
        let _ = write!(out, "{key} = ");
        one(out, first);
        out.push('\n');
        return;
    }
    let _ = writeln!(out, "{key} = [");
    for v in values {
        out.push_str("  ");
        one(out, v);
        out.push_str(",\n");
    }
    out.push_str("]\n");
}

fn write_scalars(out: &mut String, key: &str, values: &[f32]) {
    if let Some(first) = values.first()
        && values.iter().all(|v| v.to_bits() == first.to_bits())
    {
        let _ = write!(out, "{key} = ");
        float(out, *first);
        out.push('\n');
        return;
    }
    let _ = writeln!(out, "{key} = [");
    for chunk in values.chunks(8) {
        out.push(' ');
        for v in chunk {
            out.push(' ');
            float(out, *v);
            out.push(',');
        }
        out.push('\n');
    }
    out.push_str("]\n");
}

fn write_ints(out: &mut String, key: &str, values: &[u32]) {
    let _ = writeln!(out, "{key} = [");
    for chunk in values.chunks(16) {
        out.push(' ');
        for v in chunk {
            let _ = write!(out, " {v},");
        }
        out.push('\n');
    }
    out.push_str("]\n");
}

#[cfg(test)]
mod tests {
    use super::*;

    fn arm_text() -> String {
        super::super::examples::build("arm", 8, 6)
            .expect("arm")
            .to_toml_string()
    }

    /// Loads `text` from a file in a temporary folder and returns the error message.
    fn load_error(text: &str) -> String {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("broken_character.toml");
        std::fs::write(&path, text).expect("write");
        let err = Character::load(&path).expect_err("must be rejected");
        let message = err.to_string();
        assert!(
            message.contains("broken_character.toml"),
            "names the file: {message}"
        );
        message
    }

    #[test]
    fn save_then_load_is_exact_and_atomic() {
        let c = super::super::examples::build("wombat", 8, 6).expect("wombat");
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("w.toml");
        c.save(&path).expect("save");
        assert_eq!(Character::load(&path).expect("load"), c);
        // Overwriting leaves exactly one file (the temporary is renamed away).
        c.save(&path).expect("save again");
        assert_eq!(std::fs::read_dir(dir.path()).expect("list").count(), 1);
        // An invalid character is refused and the old file is untouched.
        let mut bad = c.clone();
        bad.skin.mass_kg[3] = -1.0;
        let before = std::fs::read(&path).expect("read");
        let err = bad.save(&path).expect_err("invalid");
        assert!(err.to_string().contains("mass_kg[3]"), "{err}");
        assert_eq!(std::fs::read(&path).expect("read"), before);
    }

    #[test]
    fn missing_file_names_it() {
        let err = Character::load(Path::new("/no/such/dir/ghost.toml")).expect_err("missing");
        assert!(err.to_string().contains("ghost.toml"));
    }

    #[test]
    fn unknown_or_missing_version_is_rejected() {
        let text = arm_text().replace("format_version = 1", "format_version = 7");
        let m = load_error(&text);
        assert!(m.contains("unknown format_version 7"), "{m}");
        let text = arm_text().replace("format_version = 1\n", "");
        let m = load_error(&text);
        assert!(m.contains("format_version is missing"), "{m}");
    }

    #[test]
    fn syntax_and_unknown_fields_are_rejected() {
        let m = load_error("format_version = 1\nname = \"x\"\n[skin\n");
        assert!(m.contains("line"), "{m}");
        let text = arm_text().replace("radius_m = 0.06", "radius_m = 0.06\nradius_cm = 6.0");
        let m = load_error(&text);
        assert!(m.contains("radius_cm"), "{m}");
    }

    #[test]
    fn bad_joint_reference_is_named() {
        let text = arm_text().replace("name = \"elbow\"\njoint = 1", "name = \"elbow\"\njoint = 9");
        let m = load_error(&text);
        assert!(
            m.contains("shape 2 \"elbow\": joint 9 does not exist"),
            "{m}"
        );
        let text = arm_text().replace("parent = 1", "parent = 2");
        let m = load_error(&text);
        assert!(
            m.contains("joint 2 \"wrist\": parent 2 must be an earlier joint"),
            "{m}"
        );
    }

    #[test]
    fn negative_radius_is_named() {
        let text = arm_text().replace("radius_m = 0.06", "radius_m = -0.06");
        let m = load_error(&text);
        assert!(
            m.contains("shape 2 \"elbow\": radius_m must be > 0, got -0.06"),
            "{m}"
        );
    }

    #[test]
    fn wrong_per_point_length_is_named() {
        let text = arm_text();
        // Replace the fat (one value or a per-point array) by a short explicit list.
        let start = text.find("fat_m = ").expect("fat");
        let value_end = if text[start..].starts_with("fat_m = [") {
            start + text[start..].find(']').expect("array end")
        } else {
            start
        };
        let end = value_end + text[value_end..].find('\n').expect("eol");
        let text = format!("{}fat_m = [0.01, 0.02]{}", &text[..start], &text[end..]);
        let m = load_error(&text);
        assert!(m.contains("skin: fat_m has 2 values, expected 48"), "{m}");
    }

    #[test]
    fn a_resolution_the_positions_do_not_match_is_refused_before_allocating() {
        let text = arm_text();
        assert!(text.contains("\nalong = 6\n"));
        // 8 × 10⁹ points would be 32 GB for one per-point array expanded from a single value.
        let m = load_error(&text.replace("\nalong = 6\n", "\nalong = 1000000000\n"));
        assert!(
            m.contains(
                "skin: positions_m has 48 values, expected 8000000000 (resolution 8×1000000000)"
            ),
            "{m}"
        );
    }

    #[test]
    fn wrong_type_of_per_point_value_is_explained() {
        let text = arm_text();
        let start = text.find("mass_kg = ").expect("mass");
        let end = start + text[start..].find('\n').expect("eol");
        let text = format!("{}mass_kg = \"heavy\"{}", &text[..start], &text[end..]);
        let m = load_error(&text);
        assert!(
            m.contains("mass_kg") && m.contains("one value per item"),
            "{m}"
        );
    }

    #[test]
    fn nan_is_named() {
        let text = arm_text().replace("radius_m = 0.06", "radius_m = nan");
        let m = load_error(&text);
        assert!(m.contains("radius_m must be > 0, got NaN"), "{m}");
        let text = arm_text().replace("time_s = 1.0", "time_s = nan");
        let m = load_error(&text);
        assert!(
            m.contains("motion \"bend\": key 1 time is not finite"),
            "{m}"
        );
    }

    /// The re-check threshold is optional (files written before it existed load with the
    /// default), written on save, and refused outside (0, 1].
    #[test]
    fn recheck_fraction_is_optional_and_checked() {
        let text = arm_text();
        assert!(text.contains("recheck_fraction = 0.1\n"), "saved: {text}");
        let old = text.replace("recheck_fraction = 0.1\n", "");
        let here = Path::new("recheck.toml");
        let c = Character::from_toml_str(&old, here).expect("an older file loads");
        assert_eq!(
            c.simulation.recheck_fraction,
            super::super::DEFAULT_RECHECK_FRACTION
        );
        let c = Character::from_toml_str(
            &text.replace("recheck_fraction = 0.1", "recheck_fraction = 0.4"),
            here,
        )
        .expect("0.4 is fine");
        assert_eq!(c.simulation.recheck_fraction, 0.4);
        for (bad, says) in [
            ("0.0", "recheck_fraction must be in (0, 1], got 0"),
            ("1.5", "recheck_fraction must be in (0, 1], got 1.5"),
            ("-0.1", "recheck_fraction must be finite and >= 0, got -0.1"),
            ("nan", "recheck_fraction must be finite and >= 0, got NaN"),
        ] {
            let m = load_error(&text.replace(
                "recheck_fraction = 0.1",
                &format!("recheck_fraction = {bad}"),
            ));
            assert!(m.contains(says), "{bad}: {m}");
        }
    }

    /// k∥ and k⊥ are fractions of a velocity component: [0, 1], refused outside it by name.
    #[test]
    fn contact_velocity_fractions_are_checked() {
        let text = arm_text();
        assert!(text.contains("k_perpendicular = 1.0\n"), "saved: {text}");
        for (field, bad, says) in [
            (
                "k_perpendicular = 1.0",
                "k_perpendicular = 1e30",
                "k_perpendicular must be in [0, 1], got 1000000000000000000000000000000",
            ),
            (
                "k_perpendicular = 1.0",
                "k_perpendicular = 1.01",
                "k_perpendicular must be in [0, 1], got 1.01",
            ),
            (
                "k_parallel = 0.0",
                "k_parallel = 2",
                "k_parallel must be in [0, 1], got 2",
            ),
        ] {
            let m = load_error(&text.replace(field, bad));
            assert!(m.contains(says), "{bad}: {m}");
        }
        let fine = text
            .replace("k_parallel = 0.0", "k_parallel = 1.0")
            .replace("k_perpendicular = 1.0", "k_perpendicular = 0.0");
        Character::from_toml_str(&fine, Path::new("k.toml")).expect("the ends of [0, 1] are fine");
    }

    /// A zero error threshold loaded, then stalled every run (the scaled error of a coordinate at
    /// exactly 0 is infinite): refused by name at load, as the simulator's tolerances are.
    #[test]
    fn zero_error_thresholds_are_refused() {
        let text = arm_text();
        for field in ["r_threshold_m", "v_threshold_m_per_s"] {
            assert!(text.contains(&format!("{field} = 1.0\n")), "saved: {text}");
            let m = load_error(&text.replace(&format!("{field} = 1.0"), &format!("{field} = 0.0")));
            assert!(m.contains(&format!("{field} must be > 0, got 0")), "{m}");
        }
    }

    /// Holding resting skin is optional (files written before it existed load with it on),
    /// written on save, and must be a boolean.
    #[test]
    fn hold_contacts_is_optional_and_checked() {
        let text = arm_text();
        assert!(text.contains("hold_contacts = true\n"), "saved: {text}");
        let here = Path::new("hold.toml");
        let old = text.replace("hold_contacts = true\n", "");
        let c = Character::from_toml_str(&old, here).expect("an older file loads");
        assert!(c.simulation.hold_contacts);
        let off = text.replace("hold_contacts = true", "hold_contacts = false");
        let c = Character::from_toml_str(&off, here).expect("false is fine");
        assert!(!c.simulation.hold_contacts);
        let m = load_error(&text.replace("hold_contacts = true", "hold_contacts = 1"));
        assert!(m.contains("hold_contacts"), "{m}");
    }

    /// RK4's own step is optional (a file without it steps RK4 at `euler_step_s`, as files
    /// written before it existed did), written on save, and refused by name when not positive.
    #[test]
    fn rk4_step_is_optional_and_checked() {
        let text = arm_text();
        assert!(text.contains("rk4_step_s = 0.002\n"), "saved: {text}");
        let here = Path::new("rk4.toml");
        let old = text.replace("rk4_step_s = 0.002\n", "");
        let c = Character::from_toml_str(&old, here).expect("an older file loads");
        assert_eq!(c.simulation.rk4_step_s, None);
        let t = crate::sim::surface::tolerances_of(&c.simulation);
        assert_eq!(t.rk4_step_s, t.euler_step_s, "RK4 takes Euler's step");
        let c = Character::from_toml_str(&text, here).expect("the arm loads");
        let t = crate::sim::surface::tolerances_of(&c.simulation);
        assert_eq!(
            (t.euler_step_s, t.rk4_step_s),
            (0.000_25f32.into(), 0.002f32.into())
        );
        for (bad, says) in [
            ("0.0", "rk4_step_s must be > 0, got 0"),
            ("-1e-3", "rk4_step_s must be finite and >= 0, got -0.001"),
            ("inf", "rk4_step_s must be finite and >= 0, got inf"),
        ] {
            let m = load_error(&text.replace("rk4_step_s = 0.002", &format!("rk4_step_s = {bad}")));
            assert!(m.contains(says), "{bad}: {m}");
        }
    }

    #[test]
    fn bad_spring_reference_is_named() {
        let text = arm_text();
        let start = text.find("[tissue]").expect("tissue");
        let shape_at = start + text[start..].find("shape = ").expect("shape");
        let end = shape_at + text[shape_at..].find("\nanchor_rest_m").expect("anchor");
        let text = format!("{}shape = 42{}", &text[..shape_at], &text[end..]);
        let m = load_error(&text);
        assert!(
            m.contains("tissue spring 0: shape 42 does not exist"),
            "{m}"
        );
    }

    #[test]
    fn fixed_rows_must_match_their_joints() {
        let mut c = super::super::examples::build("arm", 8, 6).expect("arm");
        c.skin.bottom_ring_m[0].x += 0.1;
        let err = c.validate().expect_err("moved ring");
        assert!(err.0.contains("fixed point (0, 0)"), "{err}");
    }
}
