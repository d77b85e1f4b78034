//! 3Dconnexion USB HID SpaceMouse reports -> axes and buttons, and the vendor/product table.
//!
//! # Input
//! Each [`Decoder::feed`] call is exactly one HID input report as hidapi returns it: byte 0 is
//! the report ID. (`leman decode` reads a file of reports each preceded by its length as one
//! byte: see [`split_length_prefixed`].)
//!
//! | report | bytes | meaning |
//! | --- | --- | --- |
//! | ID 1, split style | 7 | three little-endian i16 translations X, Y, Z |
//! | ID 1, combined style | 13 | translations then rotations (six i16) |
//! | ID 2 | 7 | three little-endian i16 rotations RX, RY, RZ |
//! | ID 3 | ≥ 2 | button bitmap: bit `b` of byte `1 + b/8` is button `b` (0-based) |
//! | other IDs | any | ignored (LED state, battery, ...) |
//!
//! The style is chosen per report by its length (13 or more bytes: combined), so one decoder
//! serves every model. A report too short for its ID is dropped and reported. In split style the
//! decoder holds the last translation and rotation and emits all six after each axis report
//! (the device goes silent when released, after a few zero reports: the last value is held).
//!
//! # Axes
//! `raw` is X, Y, Z, RX, RY, RZ as sent. The device's frame is +X right, +Y toward the user,
//! +Z down (right-handed, rotations by the right-hand rule); ours is +X right, +Y up, +Z toward
//! the user, so `ours = (X, -Z, Y)` for translations and rotations alike. Values are clamped
//! to ±[`HID_FULL_SCALE`] (some units exceed 400) and divided by it.

use super::decoder::{Decoder, DropTally};
use super::sample::{AxesSample, DeviceEvent};

/// Nominal full deflection in raw counts.
pub const HID_FULL_SCALE: i32 = 350;

/// 3Dconnexion's newer vendor ID.
pub const VENDOR_3DCONNEXION: u16 = 0x256F;
/// Logitech's vendor ID (older 3Dconnexion devices).
pub const VENDOR_LOGITECH: u16 = 0x046D;

/// How a model sends its axes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReportStyle {
    /// ID 1 translations, ID 2 rotations (7 bytes each).
    Split,
    /// ID 1 carries all six axes in 13 bytes.
    Combined,
}

/// Known devices: vendor, product, model name, report style.
pub const SUPPORTED_DEVICES: &[(u16, u16, &str, ReportStyle)] = &[
    (
        VENDOR_LOGITECH,
        0xC603,
        "SpaceMouse Plus XT",
        ReportStyle::Split,
    ),
    (VENDOR_LOGITECH, 0xC605, "CADman", ReportStyle::Split),
    (
        VENDOR_LOGITECH,
        0xC606,
        "SpaceMouse Classic",
        ReportStyle::Split,
    ),
    (
        VENDOR_LOGITECH,
        0xC621,
        "SpaceBall 5000",
        ReportStyle::Split,
    ),
    (VENDOR_LOGITECH, 0xC623, "SpaceTraveler", ReportStyle::Split),
    (VENDOR_LOGITECH, 0xC625, "SpacePilot", ReportStyle::Split),
    (
        VENDOR_LOGITECH,
        0xC626,
        "SpaceNavigator",
        ReportStyle::Split,
    ),
    (VENDOR_LOGITECH, 0xC627, "SpaceExplorer", ReportStyle::Split),
    (
        VENDOR_LOGITECH,
        0xC628,
        "SpaceNavigator for Notebooks",
        ReportStyle::Split,
    ),
    (
        VENDOR_LOGITECH,
        0xC629,
        "SpacePilot Pro",
        ReportStyle::Split,
    ),
    (
        VENDOR_LOGITECH,
        0xC62B,
        "SpaceMouse Pro",
        ReportStyle::Split,
    ),
    (
        VENDOR_3DCONNEXION,
        0xC62E,
        "SpaceMouse Wireless (cabled)",
        ReportStyle::Combined,
    ),
    (
        VENDOR_3DCONNEXION,
        0xC62F,
        "SpaceMouse Wireless",
        ReportStyle::Combined,
    ),
    (
        VENDOR_3DCONNEXION,
        0xC631,
        "SpaceMouse Pro Wireless (cabled)",
        ReportStyle::Combined,
    ),
    (
        VENDOR_3DCONNEXION,
        0xC632,
        "SpaceMouse Pro Wireless",
        ReportStyle::Combined,
    ),
    (
        VENDOR_3DCONNEXION,
        0xC633,
        "SpaceMouse Enterprise",
        ReportStyle::Combined,
    ),
    (
        VENDOR_3DCONNEXION,
        0xC635,
        "SpaceMouse Compact",
        ReportStyle::Split,
    ),
    (
        VENDOR_3DCONNEXION,
        0xC652,
        "3Dconnexion Universal Receiver",
        ReportStyle::Combined,
    ),
];

/// The model name if `vendor`/`product` is a supported 3D mouse.
pub fn is_supported(vendor: u16, product: u16) -> Option<&'static str> {
    device_info(vendor, product).map(|(name, _)| name)
}

/// Model name and report style of a supported device.
pub fn device_info(vendor: u16, product: u16) -> Option<(&'static str, ReportStyle)> {
    SUPPORTED_DEVICES
        .iter()
        .find(|(v, p, _, _)| *v == vendor && *p == product)
        .map(|(_, _, name, style)| (*name, *style))
}

/// Splits a capture of reports each preceded by its length (one byte) into the reports, plus
/// the number of trailing bytes that do not form a whole report.
pub fn split_length_prefixed(bytes: &[u8]) -> (Vec<&[u8]>, usize) {
    let mut reports = Vec::new();
    let mut at = 0;
    while let Some(&len) = bytes.get(at) {
        let Some(report) = bytes.get(at + 1..at + 1 + usize::from(len)) else {
            return (reports, bytes.len() - at);
        };
        reports.push(report);
        at += 1 + usize::from(len);
    }
    (reports, 0)
}

/// Normalised, signed values in our frame from raw HID axes.
pub fn value_from_raw(raw: [i32; 6]) -> [f32; 6] {
    let n = |v: i32| v.clamp(-HID_FULL_SCALE, HID_FULL_SCALE) as f32 / HID_FULL_SCALE as f32;
    // `+ 0.0` turns the -0.0 of a negated zero into 0.0.
    [
        n(raw[0]),
        -n(raw[2]) + 0.0,
        n(raw[1]),
        n(raw[3]),
        -n(raw[5]) + 0.0,
        n(raw[4]),
    ]
}

fn three_i16(bytes: &[u8]) -> [i32; 3] {
    let v = |i: usize| i32::from(i16::from_le_bytes([bytes[2 * i], bytes[2 * i + 1]]));
    [v(0), v(1), v(2)]
}

/// HID report decoder (one report per feed).
#[derive(Debug, Clone, Default)]
pub struct SpacemouseHidDecoder {
    raw: [i32; 6],
    drops: DropTally,
}

impl SpacemouseHidDecoder {
    /// A fresh decoder (axes held at zero).
    pub fn new() -> Self {
        Self::default()
    }

    fn axes(&self) -> DeviceEvent {
        DeviceEvent::Axes(AxesSample {
            raw: self.raw,
            value: value_from_raw(self.raw),
        })
    }
}

impl Decoder for SpacemouseHidDecoder {
    fn feed(&mut self, report: &[u8], out: &mut Vec<DeviceEvent>) {
        let Some((&id, body)) = report.split_first() else {
            return;
        };
        match id {
            1 if body.len() >= 12 => {
                let t = three_i16(&body[..6]);
                let r = three_i16(&body[6..12]);
                self.raw = [t[0], t[1], t[2], r[0], r[1], r[2]];
                out.push(self.axes());
            }
            1 if body.len() >= 6 => {
                self.raw[..3].copy_from_slice(&three_i16(&body[..6]));
                out.push(self.axes());
            }
            2 if body.len() >= 6 => {
                self.raw[3..].copy_from_slice(&three_i16(&body[..6]));
                out.push(self.axes());
            }
            3 if !body.is_empty() => {
                let mut pressed = Vec::new();
                for (byte_index, &byte) in body.iter().enumerate().take(32) {
                    for bit in 0..8 {
                        if byte & (1 << bit) != 0 {
                            pressed.push((8 * byte_index + bit) as u8);
                        }
                    }
                }
                out.push(DeviceEvent::Buttons { pressed });
            }
            1..=3 => {
                self.drops.add(report.len());
                self.drops.flush(out);
            }
            _ => {}
        }
    }

    fn reset(&mut self) {
        self.raw = [0; 6];
        self.drops.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::devices::encode::spacemouse_hid::{
        buttons_report, combined_report, length_prefixed, split_reports,
    };
    use crate::devices::test_util::{axes, buttons, feed_all};

    #[test]
    fn split_style_holds_the_other_half() {
        let mut dec = SpacemouseHidDecoder::new();
        let [t, r] = split_reports([100, -50, 350, 7, -8, 9]);
        assert_eq!((t.len(), r.len()), (7, 7));
        let a = axes(&feed_all(&mut dec, &t));
        assert_eq!(a[0].raw, [100, -50, 350, 0, 0, 0]);
        let a = axes(&feed_all(&mut dec, &r));
        assert_eq!(a[0].raw, [100, -50, 350, 7, -8, 9]);
        // ours: x = X, y = -Z, z = Y.
        assert_eq!(&a[0].value[..3], &[100.0 / 350.0, -1.0, -50.0 / 350.0]);
        assert_eq!(&a[0].value[3..], &[7.0 / 350.0, -9.0 / 350.0, -8.0 / 350.0]);
    }

    #[test]
    fn combined_style_carries_all_six_and_clamps() {
        let report = combined_report([500, -420, 1, 2, 3, -32768]);
        assert_eq!(report.len(), 13);
        let a = axes(&feed_all(&mut SpacemouseHidDecoder::new(), &report));
        assert_eq!(a[0].raw, [500, -420, 1, 2, 3, -32768]);
        assert_eq!(a[0].value[0], 1.0);
        assert_eq!(a[0].value[2], -1.0);
        assert_eq!(a[0].value[4], 1.0);
        assert!(a[0].value.iter().all(|v| (-1.0..=1.0).contains(v)));
    }

    #[test]
    fn reading_only_seven_bytes_of_a_combined_report_loses_rotation() {
        // The documented common bug, shown as behaviour: a truncated combined report is taken
        // as translation only.
        let report = combined_report([1, 2, 3, 4, 5, 6]);
        let a = axes(&feed_all(&mut SpacemouseHidDecoder::new(), &report[..7]));
        assert_eq!(a[0].raw, [1, 2, 3, 0, 0, 0]);
    }

    #[test]
    fn buttons_unknown_ids_and_short_reports() {
        let mut dec = SpacemouseHidDecoder::new();
        assert_eq!(
            buttons(&feed_all(&mut dec, &buttons_report(&[0, 1, 9, 30], 4))),
            vec![vec![0, 1, 9, 30]]
        );
        assert!(feed_all(&mut dec, &[4, 1]).is_empty());
        assert!(feed_all(&mut dec, &[23, 1, 2, 3]).is_empty());
        assert!(feed_all(&mut dec, &[]).is_empty());
        assert_eq!(
            feed_all(&mut dec, &[1, 2, 3]),
            vec![DeviceEvent::Dropped { bytes: 3 }]
        );
        assert_eq!(
            feed_all(&mut dec, &[2, 2]),
            vec![DeviceEvent::Dropped { bytes: 2 }]
        );
        assert_eq!(
            feed_all(&mut dec, &[3]),
            vec![DeviceEvent::Dropped { bytes: 1 }]
        );
    }

    #[test]
    fn vendor_product_table() {
        assert_eq!(is_supported(0x046D, 0xC626), Some("SpaceNavigator"));
        assert_eq!(
            device_info(0x256F, 0xC652),
            Some(("3Dconnexion Universal Receiver", ReportStyle::Combined))
        );
        assert_eq!(is_supported(0x046D, 0xC52B), None);
        assert_eq!(is_supported(0x1234, 0xC626), None);
    }

    #[test]
    fn length_prefixed_captures_split_back_into_reports() {
        let [t, r] = split_reports([1, 2, 3, 4, 5, 6]);
        let reports = vec![t.clone(), r.clone(), buttons_report(&[2], 2)];
        let mut bytes = length_prefixed(&reports);
        let (split, rest) = split_length_prefixed(&bytes);
        assert_eq!(split, reports.iter().map(Vec::as_slice).collect::<Vec<_>>());
        assert_eq!(rest, 0);
        bytes.extend([9, 1, 2]);
        let (split, rest) = split_length_prefixed(&bytes);
        assert_eq!((split.len(), rest), (3, 3));
    }
}
