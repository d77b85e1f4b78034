//! The protocols `leman` can decode, their names (as used on the command line, in session files
//! and in device profiles) and a constructor for each protocol's [`Decoder`].

use super::decoder::Decoder;
use super::fastrak::{FastrakDecoder, FastrakFormat, FastrakSettings, FastrakSettingsError};
use super::logitech::LogitechDecoder;
use super::magellan::MagellanDecoder;
use super::opentrack::OpentrackDecoder;
use super::spaceball::SpaceballDecoder;
use super::spacemouse_hid::SpacemouseHidDecoder;
use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

/// A device protocol. The names (`fastrak-ascii`, ...) are stable: they appear in session files,
/// device profiles and on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Protocol {
    /// Polhemus FASTRAK, ASCII records (`F` mode).
    FastrakAscii,
    /// Polhemus FASTRAK, binary records (`f` mode).
    FastrakBinary,
    /// Spaceball serial (2003, 3003, 4000FLX, 5000FLX).
    Spaceball,
    /// Magellan / SpaceMouse serial (nibble-encoded packets).
    Magellan,
    /// 3Dconnexion USB HID SpaceMouse family (one HID report per feed).
    SpacemouseHid,
    /// OpenTrack "UDP over network" (one 48-byte datagram per feed).
    Opentrack,
    /// Logitech 3D Mouse and Head Tracker (16-byte reports).
    Logitech,
}

/// How a protocol's bytes must be handed to [`Decoder::feed`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Framing {
    /// A byte stream (serial): feed chunks exactly as they arrived, split anywhere.
    Stream,
    /// Whole messages (a HID report, a UDP datagram): each `feed` call is exactly one message.
    Message,
}

impl Protocol {
    /// Every protocol, in the order of the documentation.
    pub const ALL: [Protocol; 7] = [
        Protocol::FastrakAscii,
        Protocol::FastrakBinary,
        Protocol::Spaceball,
        Protocol::Magellan,
        Protocol::SpacemouseHid,
        Protocol::Opentrack,
        Protocol::Logitech,
    ];

    /// The stable name (`fastrak-ascii`, `spacemouse-hid`, ...).
    pub fn name(self) -> &'static str {
        match self {
            Protocol::FastrakAscii => "fastrak-ascii",
            Protocol::FastrakBinary => "fastrak-binary",
            Protocol::Spaceball => "spaceball",
            Protocol::Magellan => "magellan",
            Protocol::SpacemouseHid => "spacemouse-hid",
            Protocol::Opentrack => "opentrack",
            Protocol::Logitech => "logitech",
        }
    }

    /// Whether the decoder takes a byte stream or one whole message per feed.
    pub fn framing(self) -> Framing {
        match self {
            Protocol::SpacemouseHid | Protocol::Opentrack => Framing::Message,
            _ => Framing::Stream,
        }
    }
}

impl fmt::Display for Protocol {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A protocol name that is not one of [`Protocol::ALL`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "unknown protocol {given:?} (expected one of: fastrak-ascii, fastrak-binary, spaceball, magellan, spacemouse-hid, opentrack, logitech)"
)]
pub struct UnknownProtocol {
    /// The name that was given.
    pub given: String,
}

impl FromStr for Protocol {
    type Err = UnknownProtocol;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Protocol::ALL
            .into_iter()
            .find(|p| p.name().eq_ignore_ascii_case(s.trim()))
            .ok_or_else(|| UnknownProtocol {
                given: s.to_owned(),
            })
    }
}

/// Per-protocol decoder settings (what the device was told to send). Serialisable so a session
/// header or device profile can carry them; every field has a documented default.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default)]
pub struct DecoderSettings {
    /// FASTRAK output list, units and stylus width (ignored by other protocols).
    pub fastrak: FastrakSettings,
}

/// Settings that no decoder can work with.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SettingsError {
    /// Bad FASTRAK settings.
    #[error(transparent)]
    Fastrak(#[from] FastrakSettingsError),
}

/// A decoder for `protocol` with default settings (FASTRAK: output list `2,4,1`, inches,
/// 2-byte stylus item).
pub fn decoder_for(protocol: Protocol) -> Box<dyn Decoder> {
    match protocol {
        Protocol::FastrakAscii => Box::new(FastrakDecoder::with_defaults(FastrakFormat::Ascii)),
        Protocol::FastrakBinary => Box::new(FastrakDecoder::with_defaults(FastrakFormat::Binary)),
        Protocol::Spaceball => Box::new(SpaceballDecoder::new()),
        Protocol::Magellan => Box::new(MagellanDecoder::new()),
        Protocol::SpacemouseHid => Box::new(SpacemouseHidDecoder::new()),
        Protocol::Opentrack => Box::new(OpentrackDecoder::new()),
        Protocol::Logitech => Box::new(LogitechDecoder::new()),
    }
}

/// A decoder for `protocol` with the given settings; fails when the settings cannot describe a
/// real record layout (unknown FASTRAK item, stylus width other than 1 or 2, ...).
pub fn decoder_with_settings(
    protocol: Protocol,
    settings: &DecoderSettings,
) -> Result<Box<dyn Decoder>, SettingsError> {
    Ok(match protocol {
        Protocol::FastrakAscii => Box::new(FastrakDecoder::new(
            FastrakFormat::Ascii,
            settings.fastrak.clone(),
        )?),
        Protocol::FastrakBinary => Box::new(FastrakDecoder::new(
            FastrakFormat::Binary,
            settings.fastrak.clone(),
        )?),
        other => decoder_for(other),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_through_fromstr_display_and_serde() {
        for p in Protocol::ALL {
            assert_eq!(p.to_string().parse::<Protocol>(), Ok(p));
            let json = serde_json::to_string(&p).unwrap_or_default();
            assert_eq!(json, format!("\"{}\"", p.name()));
            let back: Protocol = serde_json::from_str(&json).unwrap_or(Protocol::Logitech);
            assert_eq!(back, p);
        }
        assert!("spaceorb".parse::<Protocol>().is_err());
        assert_eq!(
            "SpaceMouse-HID".parse::<Protocol>(),
            Ok(Protocol::SpacemouseHid)
        );
    }

    #[test]
    fn bad_fastrak_settings_are_refused() {
        let mut settings = DecoderSettings::default();
        settings.fastrak.stylus_bytes = 3;
        assert!(decoder_with_settings(Protocol::FastrakAscii, &settings).is_err());
        settings.fastrak.stylus_bytes = 1;
        settings.fastrak.items = vec![2, 7];
        assert!(decoder_with_settings(Protocol::FastrakBinary, &settings).is_err());
        // Other protocols ignore FASTRAK settings.
        assert!(decoder_with_settings(Protocol::Spaceball, &settings).is_ok());
    }
}
