//! Magellan / SpaceMouse serial packets -> axes, buttons and identification.
//!
//! # Framing
//! Every 4-bit value travels as one character of `0AB3D56GH9:K<MN?` (index = value). Packets
//! end with CR:
//!
//! | packet | meaning | event |
//! | --- | --- | --- |
//! | `d` + 24 characters | X, Y, Z, A, B, C: 4 characters each, most significant first | [`AxesSample`] |
//! | `k` + 3 or 4 characters | button bits | `Buttons` |
//! | `v...` | version reply (contains `MAGELLAN`) | `Status` |
//! | `e...` | error reply | `Status` |
//! | `z`, `m...`, `q...`, `n...`, `b...` | command echoes | nothing |
//!
//! A frame that is not a packet is searched for a valid packet starting later in it (`d` and `k`
//! first, then text replies); the rest is reported as [`DeviceEvent::Dropped`] (CR included).
//!
//! # Axes
//! `raw` is each 16-bit number minus 32768 (the wire's offset encoding removed, nothing else).
//! spacenavd negates Z and C to reach its left-handed convention, which is the Spaceball's raw
//! frame; so the Magellan's own frame is already right-handed with +X right, +Y up, +Z toward
//! the user, and we pass all six through unchanged, dividing by [`MAGELLAN_FULL_SCALE`] and
//! clamping to [-1, 1]. (Unverified on hardware: the device profile's per-axis sign fixes a
//! unit that disagrees.)
//!
//! # Buttons (0-based)
//! Character `i` of a `k` packet carries buttons `4i .. 4i+3` in its bits 0-3 (bit 0 first), so
//! a 3-character packet covers buttons 0-11 and a 4-character one 0-15.

use super::decoder::{CrFramer, Decoder, DropTally};
use super::sample::{AxesSample, DeviceEvent, StatusEvent};

/// The nibble alphabet: character `i` carries value `i`.
pub const NIBBLE_CHARS: &[u8; 16] = b"0AB3D56GH9:K<MN?";

/// Raw count that maps to a normalised value of 1.
pub const MAGELLAN_FULL_SCALE: f32 = 500.0;

const MAX_FRAME: usize = 96;

/// The value a nibble character carries.
pub fn nibble(c: u8) -> Option<u8> {
    NIBBLE_CHARS
        .iter()
        .position(|&n| n == c)
        .and_then(|i| u8::try_from(i).ok())
}

/// Normalised values in our frame from raw Magellan axes.
pub fn value_from_raw(raw: [i32; 6]) -> [f32; 6] {
    raw.map(|r| (r as f32 / MAGELLAN_FULL_SCALE).clamp(-1.0, 1.0))
}

/// Streaming Magellan decoder.
#[derive(Debug, Clone)]
pub struct MagellanDecoder {
    framer: CrFramer,
    drops: DropTally,
}

impl Default for MagellanDecoder {
    fn default() -> Self {
        Self::new()
    }
}

fn printable(bytes: &[u8]) -> bool {
    bytes.iter().all(|b| b.is_ascii_graphic() || *b == b' ')
}

impl MagellanDecoder {
    /// A fresh decoder.
    pub fn new() -> Self {
        Self {
            framer: CrFramer::new(MAX_FRAME),
            drops: DropTally::default(),
        }
    }

    /// Parses a frame that must be exactly one packet; `Some(None)` for a valid packet with no
    /// event.
    fn parse(frame: &[u8]) -> Option<Option<DeviceEvent>> {
        let (&kind, payload) = frame.split_first()?;
        match kind {
            b'd' => {
                (payload.len() == 24).then_some(())?;
                let mut raw = [0i32; 6];
                for (i, r) in raw.iter_mut().enumerate() {
                    let mut v: i32 = 0;
                    for &c in &payload[4 * i..4 * i + 4] {
                        v = (v << 4) | i32::from(nibble(c)?);
                    }
                    *r = v - 32768;
                }
                Some(Some(DeviceEvent::Axes(AxesSample {
                    raw,
                    value: value_from_raw(raw),
                })))
            }
            b'k' => {
                (payload.len() == 3 || payload.len() == 4).then_some(())?;
                let mut pressed = Vec::new();
                for (i, &c) in payload.iter().enumerate() {
                    let n = nibble(c)?;
                    for bit in 0..4u8 {
                        if n & (1 << bit) != 0 {
                            pressed.push(4 * i as u8 + bit);
                        }
                    }
                }
                Some(Some(DeviceEvent::Buttons { pressed }))
            }
            b'v' => {
                printable(payload).then_some(())?;
                let text = String::from_utf8_lossy(frame).trim_end().to_owned();
                Some(Some(DeviceEvent::Status(
                    if text.to_ascii_uppercase().contains("MAGELLAN") {
                        StatusEvent::Identified {
                            model: "Magellan/SpaceMouse".to_owned(),
                            text,
                        }
                    } else {
                        StatusEvent::Report { text }
                    },
                )))
            }
            b'e' => {
                printable(payload).then_some(())?;
                Some(Some(DeviceEvent::Status(StatusEvent::Report {
                    text: format!("Magellan error: {}", String::from_utf8_lossy(frame)),
                })))
            }
            b'z' if payload.is_empty() => Some(None),
            b'm' | b'q' | b'n' | b'b' if payload.len() <= 4 && printable(payload) => Some(None),
            _ => None,
        }
    }

    fn frame(&mut self, frame: &[u8], out: &mut Vec<DeviceEvent>) {
        if frame.is_empty() {
            return;
        }
        // Fixed-form packets first (anywhere in the frame, even behind a leading `e` or `v`:
        // garbage ending in one of those would otherwise turn the `d` packet glued behind it
        // into an error or version text), then the frame's own start, then text replies.
        let fixed = |s: usize| matches!(frame[s], b'd' | b'k');
        let starts = (0..frame.len())
            .filter(|&s| fixed(s))
            .chain((!fixed(0)).then_some(0))
            .chain((1..frame.len()).filter(|&s| matches!(frame[s], b'v' | b'e')));
        for start in starts {
            if let Some(event) = Self::parse(&frame[start..]) {
                self.drops.add(start);
                if let Some(e) = event {
                    self.drops.push(e, out);
                }
                return;
            }
        }
        self.drops.add(frame.len() + 1);
    }
}

impl Decoder for MagellanDecoder {
    fn feed(&mut self, bytes: &[u8], out: &mut Vec<DeviceEvent>) {
        for &b in bytes {
            if let Some(frame) = self.framer.push(b, &mut self.drops) {
                self.frame(&frame, out);
            }
        }
        self.drops.flush(out);
    }

    fn reset(&mut self) {
        self.framer.clear();
        self.drops.clear();
    }

    fn pending(&self) -> usize {
        self.framer.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::devices::encode::magellan::{encode_d, encode_k, encode_version};
    use crate::devices::test_util::{assert_every_split, axes, buttons, dropped, feed_all};

    #[test]
    fn a_data_packet_behind_a_stray_e_or_v_is_not_taken_for_text() {
        // Found by the property test: garbage ending in `e` glued to a `d` packet became the
        // error text "edH000…" and the axes were lost.
        for stray in [b"e".as_slice(), b"v", b"xxe", b"e12"] {
            let mut bytes = stray.to_vec();
            bytes.extend(encode_d([0, 5, -7, 100, -100, 32767]));
            let events = feed_all(&mut MagellanDecoder::new(), &bytes);
            let a = axes(&events);
            assert_eq!(a.len(), 1, "{stray:?}: {events:?}");
            assert_eq!(a[0].raw, [0, 5, -7, 100, -100, 32767]);
        }
    }

    #[test]
    fn nibble_alphabet_carries_the_low_four_bits() {
        for (i, &c) in NIBBLE_CHARS.iter().enumerate() {
            assert_eq!(nibble(c), Some(i as u8));
            assert_eq!(usize::from(c & 0x0F), i);
        }
        assert_eq!(nibble(b'1'), None);
    }

    #[test]
    fn d_packet_decodes_offset_values() {
        // Hand-made: X = 0x8000 + 1 = "H001"? 0x8001 -> nibbles 8,0,0,1 -> "H00A".
        let mut bytes = b"dH00A".to_vec();
        bytes.extend(b"?NNN"); // 0xFEEE - 32768 = 32494
        bytes.extend(b"H000"); // 0
        bytes.extend(b"GNNN"); // 0x7EEE - 32768 = -274
        bytes.extend(b"0000"); // -32768
        bytes.extend(b"????"); // 32767
        bytes.push(b'\r');
        let events = feed_all(&mut MagellanDecoder::new(), &bytes);
        let a = axes(&events);
        assert_eq!(a.len(), 1, "{events:?}");
        assert_eq!(a[0].raw, [1, 32494, 0, -274, -32768, 32767]);
        assert_eq!(
            a[0].value,
            [1.0 / 500.0, 1.0, 0.0, -274.0 / 500.0, -1.0, 1.0]
        );
        assert_eq!(encode_d([1, 32494, 0, -274, -32768, 32767]), bytes);
    }

    #[test]
    fn k_packets_with_three_and_four_characters() {
        let mut dec = MagellanDecoder::new();
        assert_eq!(
            buttons(&feed_all(&mut dec, b"kA0?\r")),
            vec![vec![0, 8, 9, 10, 11]]
        );
        assert_eq!(buttons(&feed_all(&mut dec, b"k00BH\r")), vec![vec![9, 15]]);
        assert_eq!(
            buttons(&feed_all(&mut dec, &encode_k(&[3, 7, 13], 4))),
            vec![vec![3, 7, 13]]
        );
        // Two or five characters, or a character outside the alphabet: not a packet.
        for bad in [&b"kAA\r"[..], b"kAAAAA\r", b"kA1A\r"] {
            let events = feed_all(&mut dec, bad);
            assert!(buttons(&events).is_empty(), "{events:?}");
            assert_eq!(dropped(&events), bad.len());
        }
    }

    #[test]
    fn version_reply_identifies_and_echoes_are_silent() {
        let mut dec = MagellanDecoder::new();
        let events = feed_all(&mut dec, &encode_version());
        assert!(
            matches!(&events[..], [DeviceEvent::Status(StatusEvent::Identified { model, .. })] if model.contains("Magellan"))
        );
        assert!(feed_all(&mut dec, b"z\rm3\r").is_empty());
    }

    #[test]
    fn every_split_point() {
        let mut bytes = encode_version();
        bytes.extend(encode_d([100, -200, 300, -400, 500, -600]));
        bytes.extend(encode_k(&[0, 5], 3));
        assert_every_split(|| Box::new(MagellanDecoder::new()), &bytes, 3);
    }

    #[test]
    fn garbage_truncation_and_wrong_lengths() {
        let d = encode_d([1, 2, 3, 4, 5, 6]);
        let mut stream = b"\x00\xffgarbage".to_vec();
        stream.extend(&d);
        stream.extend(&d[..10]);
        stream.push(b'\r');
        let mut inside = d.clone();
        inside[5] = b'x';
        stream.extend(&inside);
        stream.extend(b"dAAAA\r");
        stream.extend(&d);
        let events = feed_all(&mut MagellanDecoder::new(), &stream);
        assert_eq!(axes(&events).len(), 2, "{events:?}");
        assert_eq!(events[0], DeviceEvent::Dropped { bytes: 9 });
        assert_eq!(dropped(&events), stream.len() - 2 * d.len());
    }
}
