//! Spaceball serial packets (2003, 3003, 4000FLX, 5000FLX) -> axes, buttons and identification.
//!
//! # Framing
//! A packet is a type byte, a payload and a CR. In the payload `^` escapes: `^Q` = 0x11,
//! `^S` = 0x13, `^M` = 0x0D, `^^` = `^`; lengths are counted after unescaping. Bare 0x11/0x13
//! bytes in the stream are XON/XOFF flow control and are skipped without being counted as
//! dropped. Empty frames (a lone CR) are ignored.
//!
//! | type | payload | event |
//! | --- | --- | --- |
//! | `D` | 2-byte period (1/16 ms), six big-endian i16 Tx Ty Tz Rx Ry Rz | [`AxesSample`] |
//! | `.` | 2 bytes: 12 buttons (4000FLX) | `Buttons` |
//! | `K` | 2 bytes: 8 buttons (older models); ignored once a `.` was seen or the banner named a 4000FLX | `Buttons` |
//! | `@` | banner text (`@1 ...`, `@2 Firmware version 2.43 ...`) | `Status` |
//! | `E` | error text | `Status` |
//!
//! A frame that is not a valid packet (unknown type, bad escape, wrong length) is searched for a
//! valid packet that starts later in it (garbage glued in front of a packet; `D`, `.`, `K`
//! first, then `@` and `E`); what cannot be
//! used is reported as [`DeviceEvent::Dropped`] (the CR included).
//!
//! # Buttons (0-based)
//! `.`: second byte bits 0-5 = buttons 0-5, bit 7 = button 6; first byte bits 0-4 = buttons
//! 7-11 (bit 5 is the right-handed flag, not a button). `K`: second byte bits 0-3 = buttons 0-3,
//! first byte bits 0-3 = buttons 4-7.
//!
//! # Axes
//! `raw` keeps the six i16 exactly as sent. The Spaceball reports in a left-handed frame (+X
//! right, +Y up, +Z into the screen, rotations by the left-hand rule), as Vrui and VRPN read it;
//! we negate Tz and Rz to get our right-handed frame (+Z toward the user) and divide by
//! [`SPACEBALL_FULL_SCALE`], clamping to [-1, 1]. spacenavd passes Z through, so a device that
//! disagrees is fixed by the per-axis sign of the device profile, not here.
//!
//! # Models
//! Firmware 2.43/2.45: Spaceball 4000FLX; 2.35/2.62/2.63: Spaceball 3003; 2.02/2.13/2.15:
//! Spaceball 2003; anything else: "Spaceball (firmware X)".

use super::decoder::{CrFramer, Decoder, DropTally};
use super::sample::{AxesSample, DeviceEvent, StatusEvent};

/// Raw count that maps to a normalised value of 1 (observed peaks are about 20000).
pub const SPACEBALL_FULL_SCALE: f32 = 20000.0;

/// Longest packet we keep before giving up on finding its CR (raw, escaped bytes).
const MAX_FRAME: usize = 128;

/// Our sign for each raw axis (Tx, Ty, Tz, Rx, Ry, Rz).
const SIGNS: [f32; 6] = [1.0, 1.0, -1.0, 1.0, 1.0, -1.0];

/// The model a firmware version string belongs to.
pub fn model_for_firmware(version: &str) -> String {
    match version {
        "2.43" | "2.45" => "Spaceball 4000FLX".to_owned(),
        "2.35" | "2.62" | "2.63" => "Spaceball 3003".to_owned(),
        "2.02" | "2.13" | "2.15" => "Spaceball 2003".to_owned(),
        other => format!("Spaceball (firmware {other})"),
    }
}

/// Removes `^` escapes; `None` on a bad escape.
pub fn unescape(payload: &[u8]) -> Option<Vec<u8>> {
    let mut out = Vec::with_capacity(payload.len());
    let mut it = payload.iter();
    while let Some(&b) = it.next() {
        if b == b'^' {
            out.push(match it.next()? {
                b'Q' => 0x11,
                b'S' => 0x13,
                b'M' => 0x0D,
                b'^' => b'^',
                _ => return None,
            });
        } else {
            out.push(b);
        }
    }
    Some(out)
}

/// Buttons of a `.` packet, 0-based, and the right-handed flag.
pub fn dot_buttons(payload: [u8; 2]) -> (Vec<u8>, bool) {
    let [first, second] = payload;
    let mut pressed = Vec::new();
    for bit in 0..6 {
        if second & (1 << bit) != 0 {
            pressed.push(bit);
        }
    }
    if second & 0x80 != 0 {
        pressed.push(6);
    }
    for bit in 0..5 {
        if first & (1 << bit) != 0 {
            pressed.push(7 + bit);
        }
    }
    (pressed, first & 0x20 != 0)
}

/// Buttons of a `K` packet, 0-based.
pub fn k_buttons(payload: [u8; 2]) -> Vec<u8> {
    let [first, second] = payload;
    let mut pressed = Vec::new();
    for bit in 0..4 {
        if second & (1 << bit) != 0 {
            pressed.push(bit);
        }
    }
    for bit in 0..4 {
        if first & (1 << bit) != 0 {
            pressed.push(4 + bit);
        }
    }
    pressed
}

/// Normalised, signed values in our frame from raw Spaceball axes.
pub fn value_from_raw(raw: [i32; 6]) -> [f32; 6] {
    let mut value = [0.0; 6];
    for i in 0..6 {
        // `+ 0.0` turns the -0.0 of a negated zero into 0.0.
        value[i] = (SIGNS[i] * raw[i] as f32 / SPACEBALL_FULL_SCALE).clamp(-1.0, 1.0) + 0.0;
    }
    value
}

/// Streaming Spaceball decoder.
#[derive(Debug, Clone)]
pub struct SpaceballDecoder {
    framer: CrFramer,
    drops: DropTally,
    seen_dot: bool,
}

impl Default for SpaceballDecoder {
    fn default() -> Self {
        Self::new()
    }
}

/// What one frame means.
enum Packet {
    Events(Vec<DeviceEvent>),
    /// A `K` packet after `.` packets: valid but not used.
    Ignored,
}

impl SpaceballDecoder {
    /// A fresh decoder.
    pub fn new() -> Self {
        Self {
            framer: CrFramer::new(MAX_FRAME),
            drops: DropTally::default(),
            seen_dot: false,
        }
    }

    /// Parses a frame that must be exactly one packet.
    fn parse(&mut self, frame: &[u8]) -> Option<Packet> {
        let (&kind, payload) = frame.split_first()?;
        let payload = unescape(payload)?;
        match kind {
            b'D' => {
                (payload.len() == 14).then_some(())?;
                let mut raw = [0; 6];
                for (i, r) in raw.iter_mut().enumerate() {
                    let at = 2 + 2 * i;
                    *r = i32::from(i16::from_be_bytes([payload[at], payload[at + 1]]));
                }
                Some(Packet::Events(vec![DeviceEvent::Axes(AxesSample {
                    raw,
                    value: value_from_raw(raw),
                })]))
            }
            b'.' => {
                let two: [u8; 2] = payload.as_slice().try_into().ok()?;
                self.seen_dot = true;
                let (pressed, _right_handed) = dot_buttons(two);
                Some(Packet::Events(vec![DeviceEvent::Buttons { pressed }]))
            }
            b'K' => {
                let two: [u8; 2] = payload.as_slice().try_into().ok()?;
                if self.seen_dot {
                    return Some(Packet::Ignored);
                }
                Some(Packet::Events(vec![DeviceEvent::Buttons {
                    pressed: k_buttons(two),
                }]))
            }
            b'@' | b'E' => {
                payload
                    .iter()
                    .all(|b| b.is_ascii_graphic() || *b == b' ')
                    .then_some(())?;
                let text = String::from_utf8_lossy(frame).trim_end().to_owned();
                let status = if kind == b'E' {
                    StatusEvent::Report {
                        text: format!("Spaceball error: {text}"),
                    }
                } else if let Some(version) = firmware_version(&text) {
                    let model = model_for_firmware(version);
                    // A 4000FLX sends `.` packets; its `K` packets are only for compatibility.
                    if model.contains("4000FLX") {
                        self.seen_dot = true;
                    }
                    StatusEvent::Identified { model, text }
                } else {
                    StatusEvent::Report { text }
                };
                Some(Packet::Events(vec![DeviceEvent::Status(status)]))
            }
            _ => None,
        }
    }

    fn frame(&mut self, frame: &[u8], out: &mut Vec<DeviceEvent>) {
        if frame.is_empty() {
            return;
        }
        // Binary packets first (anywhere in the frame), then text packets.
        let starts = (0..frame.len())
            .filter(|&s| s == 0 || matches!(frame[s], b'D' | b'.' | b'K'))
            .chain((1..frame.len()).filter(|&s| matches!(frame[s], b'@' | b'E')));
        for start in starts {
            if let Some(packet) = self.parse(&frame[start..]) {
                self.drops.add(start);
                if let Packet::Events(events) = packet {
                    for e in events {
                        self.drops.push(e, out);
                    }
                }
                return;
            }
        }
        self.drops.add(frame.len() + 1);
    }
}

/// The version number in an `@2 Firmware version 2.43 ...` line.
fn firmware_version(text: &str) -> Option<&str> {
    let after = &text[text.find("version")? + "version".len()..];
    after.split_whitespace().next()
}

impl Decoder for SpaceballDecoder {
    fn feed(&mut self, bytes: &[u8], out: &mut Vec<DeviceEvent>) {
        for &b in bytes {
            if b == 0x11 || b == 0x13 {
                continue;
            }
            if let Some(frame) = self.framer.push(b, &mut self.drops) {
                self.frame(&frame, out);
            }
        }
        self.drops.flush(out);
    }

    fn reset(&mut self) {
        self.framer.clear();
        self.drops.clear();
        self.seen_dot = false;
    }

    fn pending(&self) -> usize {
        self.framer.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::devices::encode::spaceball::{encode_banner, encode_d, encode_dot, encode_k};
    use crate::devices::test_util::{assert_every_split, axes, buttons, dropped, feed_all};

    #[test]
    fn d_packet_decodes_raw_and_signed_values() {
        let bytes = encode_d(100, [1000, -2000, 3000, -4000, 5000, 20000]);
        let events = feed_all(&mut SpaceballDecoder::new(), &bytes);
        let a = axes(&events);
        assert_eq!(a.len(), 1, "{events:?}");
        assert_eq!(a[0].raw, [1000, -2000, 3000, -4000, 5000, 20000]);
        assert_eq!(a[0].value, [0.05, -0.1, -0.15, -0.2, 0.25, -1.0]);
    }

    #[test]
    fn escapes_are_removed_before_counting() {
        // 0x11, 0x13, 0x0D and '^' inside the payload must all be escaped.
        let axes_in = [0x1113, 0x0D5E, 0x5E0D, 0x1311, 0x0D0D, -1];
        let bytes = encode_d(0x5E11, axes_in);
        assert!(bytes.windows(2).any(|w| w == b"^Q"));
        assert!(bytes.windows(2).any(|w| w == b"^S"));
        assert!(bytes.windows(2).any(|w| w == b"^M"));
        assert!(bytes.windows(2).any(|w| w == b"^^"));
        assert!(bytes.len() > 16);
        let events = feed_all(&mut SpaceballDecoder::new(), &bytes);
        assert_eq!(axes(&events)[0].raw, axes_in.map(i32::from));
        // A bad escape makes the packet invalid (and it is reported as dropped).
        let mut bad = encode_d(0, [0; 6]);
        bad[3] = b'^';
        bad[4] = b'x';
        let events = feed_all(&mut SpaceballDecoder::new(), &bad);
        assert!(axes(&events).is_empty());
        assert_eq!(dropped(&events), bad.len());
    }

    #[test]
    fn xon_xoff_flow_control_bytes_are_skipped() {
        let mut bytes = vec![0x13];
        let d = encode_d(1, [1, 2, 3, 4, 5, 6]);
        bytes.extend(&d[..5]);
        bytes.push(0x11);
        bytes.extend(&d[5..]);
        let events = feed_all(&mut SpaceballDecoder::new(), &bytes);
        assert_eq!(events.len(), 1, "{events:?}");
        assert_eq!(axes(&events)[0].raw, [1, 2, 3, 4, 5, 6]);
    }

    #[test]
    fn every_split_point() {
        let mut bytes = encode_banner("2.43");
        bytes.extend(encode_d(0x0D0D, [0x0D5E, -1, 2, 0x1113, 4, -5]));
        bytes.extend(encode_dot(&[0, 6, 11], false));
        bytes.extend(encode_k([0, 1]));
        assert_every_split(|| Box::new(SpaceballDecoder::new()), &bytes, 4);
    }

    #[test]
    fn banner_identifies_models() {
        for (fw, model) in [
            ("2.43", "Spaceball 4000FLX"),
            ("2.45", "Spaceball 4000FLX"),
            ("2.62", "Spaceball 3003"),
            ("2.15", "Spaceball 2003"),
            ("9.99", "Spaceball (firmware 9.99)"),
        ] {
            let events = feed_all(&mut SpaceballDecoder::new(), &encode_banner(fw));
            assert_eq!(events.len(), 2, "{events:?}");
            assert!(
                matches!(&events[0], DeviceEvent::Status(StatusEvent::Report { text }) if text.starts_with("@1"))
            );
            match &events[1] {
                DeviceEvent::Status(StatusEvent::Identified { model: m, text }) => {
                    assert_eq!(m, model);
                    assert!(text.contains(fw));
                }
                other => panic!("{other:?}"),
            }
        }
    }

    #[test]
    fn dot_buttons_and_k_is_ignored_after_dot() {
        let mut dec = SpaceballDecoder::new();
        let events = feed_all(&mut dec, &encode_k([0x01, 0x02]));
        assert_eq!(buttons(&events), vec![vec![1, 4]]);
        let all: Vec<u8> = (0..12).collect();
        let events = feed_all(&mut dec, &encode_dot(&all, true));
        assert_eq!(buttons(&events), vec![all]);
        let events = feed_all(&mut dec, &encode_k([0x01, 0x02]));
        assert!(events.is_empty(), "{events:?}");
        // Right-handed flag is not a button.
        let events = feed_all(&mut dec, &encode_dot(&[], true));
        assert_eq!(buttons(&events), vec![Vec::<u8>::new()]);
        let (pressed, right) = dot_buttons([0x20, 0x80]);
        assert_eq!((pressed, right), (vec![6], true));
    }

    #[test]
    fn k_is_ignored_after_a_4000flx_banner_but_not_after_a_2003_banner() {
        let mut bytes = encode_banner("2.45");
        bytes.extend(encode_k([0, 1]));
        assert!(buttons(&feed_all(&mut SpaceballDecoder::new(), &bytes)).is_empty());
        let mut bytes = encode_banner("2.15");
        bytes.extend(encode_k([0, 1]));
        assert_eq!(
            buttons(&feed_all(&mut SpaceballDecoder::new(), &bytes)),
            vec![vec![0]]
        );
    }

    #[test]
    fn garbage_before_between_and_inside_packets() {
        let d = encode_d(7, [10, 20, 30, 40, 50, 60]);
        let mut stream = b"xyz\x00\xff".to_vec();
        stream.extend(&d);
        stream.extend(b"junk\r");
        let mut corrupted = d.clone();
        corrupted.insert(6, b'Q');
        stream.extend(&corrupted);
        stream.extend(&d);
        let events = feed_all(&mut SpaceballDecoder::new(), &stream);
        assert_eq!(axes(&events).len(), 2, "{events:?}");
        assert_eq!(events[0], DeviceEvent::Dropped { bytes: 5 });
        assert_eq!(dropped(&events), 5 + 5 + corrupted.len());
    }

    #[test]
    fn truncated_and_wrong_length_packets_are_dropped() {
        let d = encode_d(7, [10, 20, 30, 40, 50, 60]);
        let mut stream = d[..8].to_vec();
        stream.push(b'\r');
        stream.extend(b"D\x00\x01\r");
        stream.extend(b".\x01\r");
        stream.extend(&d);
        let events = feed_all(&mut SpaceballDecoder::new(), &stream);
        assert_eq!(axes(&events).len(), 1, "{events:?}");
        assert!(buttons(&events).is_empty());
        assert_eq!(dropped(&events), 9 + 4 + 3);
    }

    #[test]
    fn endless_garbage_without_cr_stays_bounded_and_is_counted() {
        let mut dec = SpaceballDecoder::new();
        let mut out = Vec::new();
        for _ in 0..100 {
            dec.feed(&[b'x'; 100], &mut out);
        }
        assert!(dec.pending() <= 2 * MAX_FRAME);
        dec.feed(&encode_d(0, [1; 6]), &mut out);
        assert_eq!(axes(&out).len(), 1);
        assert_eq!(dropped(&out), 100 * 100);
    }
}
