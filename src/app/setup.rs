//! Putting a workstation together from files: the character, its surface model, the
//! calibration, and where the default files live.

use crate::calibration::CalibrationProfile;
use crate::character::Character;
use crate::sim::IntegratorKind;
use crate::sim::surface::SurfaceModel;
use crate::stereo::StereoMode;
use std::path::{Path, PathBuf};

use super::state::ModelResult;

/// Failure to put the workstation together; names the file.
#[derive(Debug, thiserror::Error)]
pub enum SetupError {
    /// The character file could not be loaded.
    #[error(transparent)]
    Character(#[from] crate::character::CharacterFileError),
    /// The calibration file could not be loaded.
    #[error(transparent)]
    Calibration(#[from] crate::calibration::profile::ProfileError),
    /// No default character was found.
    #[error("no default character: looked for {0}")]
    NoDefaultCharacter(String),
    /// An unknown stereo mode name.
    #[error("unknown stereo mode \"{0}\" (one of: {1})")]
    StereoMode(String, String),
    /// A bad `WIDTHxHEIGHT`.
    #[error("bad size \"{0}\": expected WIDTHxHEIGHT, e.g. 1280x720")]
    Size(String),
    /// A `WIDTHxHEIGHT` outside 1..=[`MAX_SIZE_PX`] pixels in either direction.
    #[error("size \"{0}\": width and height must each be 1 to {MAX_SIZE_PX} pixels")]
    SizeOutOfRange(String),
}

/// Largest window or frame width and height accepted, pixels.
pub const MAX_SIZE_PX: u32 = 8192;

/// Names of the default characters, first found wins.
pub const DEFAULT_CHARACTERS: [&str; 2] = ["torso.toml", "penguin.toml"];

/// Folders searched for `assets/characters/`: the working directory, then the crate's folder
/// (where the binary was built).
pub fn asset_roots() -> Vec<PathBuf> {
    let mut roots = vec![PathBuf::from(".")];
    roots.push(PathBuf::from(env!("CARGO_MANIFEST_DIR")));
    roots
}

/// The default character file.
pub fn default_character_path() -> Result<PathBuf, SetupError> {
    let mut tried = Vec::new();
    for root in asset_roots() {
        for name in DEFAULT_CHARACTERS {
            let p = root.join("assets/characters").join(name);
            if p.is_file() {
                return Ok(p);
            }
            tried.push(p.display().to_string());
        }
    }
    Err(SetupError::NoDefaultCharacter(tried.join(", ")))
}

/// Loads a character (or the default one).
pub fn load_character(path: Option<&Path>) -> Result<Character, SetupError> {
    let path = match path {
        Some(p) => p.to_path_buf(),
        None => default_character_path()?,
    };
    Ok(Character::load(&path)?)
}

/// Loads a calibration profile, or the built-in default desktop.
pub fn load_calibration(path: Option<&Path>) -> Result<CalibrationProfile, SetupError> {
    match path {
        Some(p) => Ok(CalibrationProfile::load(p)?),
        None => Ok(CalibrationProfile::default()),
    }
}

/// The LEMAN surface model of `character` with `integrator`, or why it cannot be built.
pub fn surface_model(character: &Character, integrator: IntegratorKind) -> ModelResult {
    SurfaceModel::new(character.clone(), integrator)
        .map(|m| Box::new(m) as Box<dyn crate::sim::DeformationModel + Send>)
        .map_err(|e| e.to_string())
}

/// Parses a stereo mode: its snake_case name (`side_by_side_half`) or a short alias
/// (`mono`, `sbs`, `sbs-full`, `top-bottom`, `anaglyph`, `rows`, `sequential`).
pub fn parse_stereo_mode(text: &str) -> Result<StereoMode, SetupError> {
    let t = text.trim().to_ascii_lowercase().replace('-', "_");
    let mode = match t.as_str() {
        "mono" => StereoMode::Mono,
        "sbs" | "side_by_side" | "side_by_side_half" => StereoMode::SideBySideHalf,
        "sbs_full" | "side_by_side_full" => StereoMode::SideBySideFull,
        "top_bottom" | "tb" => StereoMode::TopBottom,
        "anaglyph" | "anaglyph_red_cyan" => StereoMode::AnaglyphRedCyan,
        "rows" | "row_interleaved" => StereoMode::RowInterleaved,
        "sequential" | "frame_sequential" => StereoMode::FrameSequential,
        _ => {
            let names = "mono, side_by_side_half (sbs), side_by_side_full (sbs-full), \
                         top_bottom, anaglyph_red_cyan (anaglyph), row_interleaved (rows), \
                         frame_sequential (sequential)";
            return Err(SetupError::StereoMode(text.to_owned(), names.to_owned()));
        }
    };
    Ok(mode)
}

/// Parses `WIDTHxHEIGHT` (both 1..=8192).
pub fn parse_size(text: &str) -> Result<[u32; 2], SetupError> {
    let bad = || SetupError::Size(text.to_owned());
    let (w, h) = text.trim().split_once(['x', 'X']).ok_or_else(bad)?;
    let w: u32 = w.trim().parse().map_err(|_| bad())?;
    let h: u32 = h.trim().parse().map_err(|_| bad())?;
    if !(1..=MAX_SIZE_PX).contains(&w) || !(1..=MAX_SIZE_PX).contains(&h) {
        return Err(SetupError::SizeOutOfRange(text.to_owned()));
    }
    Ok([w, h])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stereo_modes_and_sizes_parse_and_bad_ones_are_named() {
        assert_eq!(
            parse_stereo_mode("sbs").ok(),
            Some(StereoMode::SideBySideHalf)
        );
        assert_eq!(
            parse_stereo_mode("Anaglyph-Red-Cyan").ok(),
            Some(StereoMode::AnaglyphRedCyan)
        );
        let e = parse_stereo_mode("holo").expect_err("unknown");
        assert!(e.to_string().contains("holo"));
        assert_eq!(parse_size("1280x720").ok(), Some([1280, 720]));
        assert!(parse_size("1280").is_err());
        assert!(
            parse_size("1280xwide").is_err_and(|e| e.to_string().contains("expected WIDTHxHEIGHT"))
        );
        for big in ["0x5", "20000x20000", "8193x100"] {
            let e = parse_size(big).expect_err(big).to_string();
            assert!(e.contains("must each be 1 to 8192 pixels"), "{e}");
        }
        assert_eq!(parse_size("8192x8192").ok(), Some([8192, 8192]));
    }
}
