//! FASTRAK records (ASCII or binary) and the `S` status record.

use crate::devices::fastrak::{
    FastrakFormat, FastrakItem, FastrakSettings, LengthUnit, STATUS_RECORD_LEN,
    euler_deg_from_orientation, quaternion_from_orientation, raw_from_position_m,
};
use crate::pose::Pose;

/// The values of one record, in the device's units and transmitter frame.
#[derive(Debug, Clone, PartialEq)]
pub struct FastrakRecord {
    /// Station 1..=4.
    pub station: u8,
    /// Status byte: `b' '` when healthy, a letter otherwise.
    pub status: u8,
    /// Position x, y, z in the device unit.
    pub position: [f64; 3],
    /// Azimuth, elevation, roll in degrees.
    pub euler_deg: [f64; 3],
    /// Quaternion q0 (scalar), q1, q2, q3.
    pub quaternion: [f64; 4],
    /// Stylus switch pressed.
    pub stylus: bool,
}

impl FastrakRecord {
    /// The record a FASTRAK would send for a sensor at `pose` (our frame, metres).
    pub fn from_pose(station: u8, pose: &Pose, units: LengthUnit, stylus: bool) -> Self {
        let q = pose.orientation.as_dquat();
        Self {
            station,
            status: b' ',
            position: raw_from_position_m(pose.position_m.as_dvec3(), units),
            euler_deg: euler_deg_from_orientation(q),
            quaternion: quaternion_from_orientation(q),
            stylus,
        }
    }
}

/// A fixed-width ASCII number (`width` characters, `decimals` places), clamped so it fits.
fn ascii_field(v: f64, width: usize, decimals: usize) -> String {
    let limit = 10f64.powi((width - decimals - 2) as i32) - 10f64.powi(-(decimals as i32));
    let v = if v.is_finite() {
        v.clamp(-limit, limit)
    } else {
        0.0
    };
    format!("{v:width$.decimals$}")
}

/// Encodes one data record with `settings`' output list, in `format`.
pub fn encode_record(
    format: FastrakFormat,
    settings: &FastrakSettings,
    record: &FastrakRecord,
) -> Vec<u8> {
    let mut out = vec![b'0', b'0' + record.station.clamp(1, 4), record.status];
    let put = |values: &[f64], decimals: usize, out: &mut Vec<u8>| {
        for &v in values {
            match format {
                FastrakFormat::Ascii => out.extend(ascii_field(v, 7, decimals).bytes()),
                FastrakFormat::Binary => out.extend((v as f32).to_le_bytes()),
            }
        }
    };
    for item in settings
        .items
        .iter()
        .filter_map(|&n| FastrakItem::from_number(n))
    {
        match item {
            FastrakItem::Space => out.push(b' '),
            FastrakItem::CrLf => out.extend(b"\r\n"),
            FastrakItem::Position => put(&record.position, 2, &mut out),
            FastrakItem::Euler => put(&record.euler_deg, 2, &mut out),
            FastrakItem::Quaternion => put(&record.quaternion, 4, &mut out),
            FastrakItem::Stylus => {
                if settings.stylus_bytes >= 2 {
                    out.push(b'0');
                }
                out.push(if record.stylus { b'1' } else { b'0' });
            }
        }
    }
    out
}

/// The 55-byte `S` status record for `station`, carrying `text` (padded or cut to fit).
pub fn encode_status_record(station: u8, text: &str) -> Vec<u8> {
    let mut out = vec![b'2', b'0' + station.clamp(1, 4), b'S'];
    let body: Vec<u8> = text
        .bytes()
        .map(|b| if b.is_ascii_graphic() { b } else { b' ' })
        .chain(std::iter::repeat(b' '))
        .take(STATUS_RECORD_LEN - 5)
        .collect();
    out.extend(body);
    out.extend(b"\r\n");
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ascii_fields_are_seven_characters_even_when_clamped() {
        assert_eq!(ascii_field(12.0, 7, 2), "  12.00");
        assert_eq!(ascii_field(-123.456, 7, 2), "-123.46");
        assert_eq!(ascii_field(5000.0, 7, 2), " 999.99");
        assert_eq!(ascii_field(-0.61237, 7, 4), "-0.6124");
        assert_eq!(ascii_field(f64::NAN, 7, 4), " 0.0000");
    }

    #[test]
    fn status_record_is_55_bytes() {
        let r = encode_status_record(1, "a very long text that goes past the end of the record");
        assert_eq!(r.len(), STATUS_RECORD_LEN);
        assert!(r.ends_with(b"\r\n"));
    }
}
