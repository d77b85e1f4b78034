//! Logitech 3D Mouse and Head Tracker (ultrasonic, 1998) 16-byte reports -> [`PoseSample`]s.
//!
//! # Report
//! 16 bytes; only the first has bit 7 set, which is how the stream is framed. Byte 1: bit 6
//! fringe, bit 5 out of range, bit 4 on the mouse stand, bit 3 suspend, bits 2/1/0 left /
//! middle / right button. Bytes 2-4, 5-7, 8-10: X, Y, Z as 21-bit two's complement, 7 bits per
//! byte, high group first, in 1/1000 inch. Bytes 11-12, 13-14, 15-16: pitch, yaw, roll as
//! 14-bit unsigned, 40 counts per degree.
//!
//! Bytes before a header byte, and a report cut short by the next header byte, are reported as
//! [`DeviceEvent::Dropped`].
//!
//! # Events
//! A pose per report (station 1). Buttons go into `pressed` (left 0, middle 1, right 2). The
//! status is the most serious flag: `'O'` out of range, `'F'` fringe, `'S'` suspend, `'M'` on
//! the mouse stand, none when healthy. The pose is sent even when flagged; consumers decide.
//!
//! # Units and axes
//! Positions: 1/1000 inch -> metres. The transmitter frame is taken as ours (+X right, +Y up,
//! +Z toward the user) and orientation as `Ry(yaw)·Rx(pitch)·Rz(roll)`; angles are used as sent
//! (0 to 409.6°, rotations are periodic). Mounting is a calibration matter and axis signs are
//! the device profile's.

use super::decoder::{Decoder, DropTally};
use super::sample::{DeviceEvent, PoseSample, RawOrientation};
use crate::pose::Pose;
use glam::{DQuat, DVec3, EulerRot};

/// Bytes in one report.
pub const REPORT_LEN: usize = 16;
/// Metres per position count (1/1000 inch).
pub const METRES_PER_COUNT: f64 = 0.0254 / 1000.0;
/// Angle counts per degree.
pub const COUNTS_PER_DEGREE: f64 = 40.0;

/// Flag bits of byte 1.
pub mod flags {
    /// Header marker.
    pub const HEADER: u8 = 0x80;
    /// Near the edge of the tracking volume.
    pub const FRINGE: u8 = 0x40;
    /// Out of range.
    pub const OUT_OF_RANGE: u8 = 0x20;
    /// Resting on the mouse stand.
    pub const MOUSE_STAND: u8 = 0x10;
    /// Suspended.
    pub const SUSPEND: u8 = 0x08;
    /// Left button.
    pub const LEFT: u8 = 0x04;
    /// Middle button.
    pub const MIDDLE: u8 = 0x02;
    /// Right button.
    pub const RIGHT: u8 = 0x01;
}

/// Position (1/1000 inch) and pitch, yaw, roll (degrees) -> our pose.
pub fn pose_from_raw(position_counts: [f64; 3], pyr_deg: [f64; 3]) -> Pose {
    let [pitch, yaw, roll] = pyr_deg.map(f64::to_radians);
    Pose::new(
        (DVec3::from_array(position_counts) * METRES_PER_COUNT).as_vec3(),
        DQuat::from_euler(EulerRot::YXZ, yaw, pitch, roll)
            .normalize()
            .as_quat(),
    )
}

/// Decodes a 21-bit two's complement number from three 7-bit groups.
fn i21(b: &[u8]) -> i32 {
    let v = (i32::from(b[0] & 0x7F) << 14) | (i32::from(b[1] & 0x7F) << 7) | i32::from(b[2] & 0x7F);
    if v & (1 << 20) != 0 { v - (1 << 21) } else { v }
}

/// Decodes a 14-bit unsigned number from two 7-bit groups.
fn u14(b: &[u8]) -> u16 {
    (u16::from(b[0] & 0x7F) << 7) | u16::from(b[1] & 0x7F)
}

/// Parses one framed report (header first, the rest without bit 7).
pub fn parse_report(r: &[u8; REPORT_LEN]) -> PoseSample {
    let f = r[0];
    let raw_position = [i21(&r[1..4]), i21(&r[4..7]), i21(&r[7..10])].map(f64::from);
    let angles = [u14(&r[10..12]), u14(&r[12..14]), u14(&r[14..16])]
        .map(|c| f64::from(c) / COUNTS_PER_DEGREE);
    let mut pressed = Vec::new();
    for (bit, button) in [(flags::LEFT, 0), (flags::MIDDLE, 1), (flags::RIGHT, 2)] {
        if f & bit != 0 {
            pressed.push(button);
        }
    }
    let status = [
        (flags::OUT_OF_RANGE, 'O'),
        (flags::FRINGE, 'F'),
        (flags::SUSPEND, 'S'),
        (flags::MOUSE_STAND, 'M'),
    ]
    .into_iter()
    .find(|(bit, _)| f & bit != 0)
    .map(|(_, c)| c);
    PoseSample {
        station: 1,
        pose: pose_from_raw(raw_position, angles),
        raw_position,
        raw_orientation: RawOrientation::EulerDeg(angles),
        pressed,
        status,
    }
}

/// Streaming Logitech decoder.
#[derive(Debug, Clone, Default)]
pub struct LogitechDecoder {
    buf: Vec<u8>,
    drops: DropTally,
}

impl LogitechDecoder {
    /// A fresh decoder.
    pub fn new() -> Self {
        Self::default()
    }
}

impl Decoder for LogitechDecoder {
    fn feed(&mut self, bytes: &[u8], out: &mut Vec<DeviceEvent>) {
        for &b in bytes {
            if b & flags::HEADER != 0 {
                // A header starts a new report; whatever was pending is cut short.
                self.drops.add(self.buf.len());
                self.buf.clear();
                self.buf.push(b);
            } else if self.buf.is_empty() {
                self.drops.add(1);
            } else {
                self.buf.push(b);
                if self.buf.len() == REPORT_LEN {
                    let mut r = [0u8; REPORT_LEN];
                    r.copy_from_slice(&self.buf);
                    self.buf.clear();
                    self.drops.push(DeviceEvent::Pose(parse_report(&r)), out);
                }
            }
        }
        self.drops.flush(out);
    }

    fn reset(&mut self) {
        self.buf.clear();
        self.drops.clear();
    }

    fn pending(&self) -> usize {
        self.buf.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::devices::encode::logitech::report;
    use crate::devices::test_util::{assert_every_split, dropped, feed_all, poses};
    use glam::{Quat, Vec3};

    #[test]
    fn hand_made_report_decodes() {
        // X = -1 (all 21 bits set), Y = 1000 (0b111_1101000: groups 0, 7, 104),
        // Z = -1_048_576 (only the sign bit), pitch 90° = 3600 counts (28, 16), yaw 0, roll 1.
        let r = [
            0x80 | flags::FRINGE | flags::LEFT | flags::RIGHT,
            0x7F,
            0x7F,
            0x7F,
            0,
            7,
            104,
            0x40,
            0,
            0,
            28,
            16,
            0,
            0,
            0,
            1,
        ];
        let events = feed_all(&mut LogitechDecoder::new(), &r);
        let p = poses(&events);
        assert_eq!(p.len(), 1, "{events:?}");
        assert_eq!(p[0].raw_position, [-1.0, 1000.0, -1_048_576.0]);
        assert_eq!(
            p[0].raw_orientation,
            RawOrientation::EulerDeg([90.0, 0.0, 0.025])
        );
        assert_eq!(p[0].pressed, vec![0, 2]);
        assert_eq!(p[0].status, Some('F'));
        assert!((p[0].pose.position_m.y - 0.0254).abs() < 1e-7);
        let p = pose_from_raw([0.0; 3], [90.0, 0.0, 0.0]);
        assert!(
            p.orientation
                .dot(Quat::from_rotation_x(std::f32::consts::FRAC_PI_2))
                .abs()
                > 1.0 - 1e-6
        );
        assert_eq!(report(r[0] & 0x7F, [-1, 1000, -1_048_576], [3600, 0, 1]), r);
    }

    #[test]
    fn every_split_point() {
        let mut bytes = report(0, [1000, -2000, 3000], [100, 200, 300]).to_vec();
        bytes.extend(report(flags::OUT_OF_RANGE, [-5, 5, 0], [16383, 0, 40]));
        assert_every_split(|| Box::new(LogitechDecoder::new()), &bytes, 2);
    }

    #[test]
    fn garbage_and_truncated_reports_are_dropped() {
        let good = report(flags::MIDDLE, [12, 34, 56], [1, 2, 3]);
        let mut stream = vec![0x01, 0x7F, 0x00];
        stream.extend(&good[..9]);
        stream.extend(&good);
        stream.push(0x55);
        stream.extend(&good);
        let events = feed_all(&mut LogitechDecoder::new(), &stream);
        let p = poses(&events);
        assert_eq!(p.len(), 2, "{events:?}");
        assert_eq!(p[0].pressed, vec![1]);
        assert_eq!(events[0], DeviceEvent::Dropped { bytes: 12 });
        assert_eq!(dropped(&events), 13);
        assert!((p[1].pose.position_m - Vec3::new(12.0, 34.0, 56.0) * 2.54e-5).length() < 1e-9);
    }

    #[test]
    fn garbage_inside_a_report() {
        // A stray header byte inside a report cuts it short: it is dropped, the next is found.
        let good = report(0, [1, 2, 3], [4, 5, 6]);
        let mut stream = good[..7].to_vec();
        stream.push(0x80);
        stream.extend(&good);
        let events = feed_all(&mut LogitechDecoder::new(), &stream);
        assert_eq!(poses(&events).len(), 1, "{events:?}");
        // The stray header began a report of its own that the real header cut short.
        assert_eq!(dropped(&events), 8);
        // A stray non-header byte cannot be seen (no checksum): that report decodes shifted and
        // the byte left over is dropped; the report after it is exact again.
        let mut stream = good[..7].to_vec();
        stream.push(0x11);
        stream.extend(&good[7..]);
        stream.extend(&good);
        let events = feed_all(&mut LogitechDecoder::new(), &stream);
        let p = poses(&events);
        assert_eq!(p.len(), 2, "{events:?}");
        assert_eq!(dropped(&events), 1);
        assert_eq!(p[1].raw_position, [1.0, 2.0, 3.0]);
    }
}
