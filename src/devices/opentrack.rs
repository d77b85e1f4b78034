//! OpenTrack "UDP over network" datagrams -> [`PoseSample`]s.
//!
//! # Input
//! Each [`Decoder::feed`] call is exactly one UDP datagram: 48 bytes, six little-endian f64:
//! X, Y, Z in centimetres, then yaw, pitch, roll in degrees. (`leman decode` reads a file of
//! consecutive 48-byte datagrams.) A datagram of any other length, or holding NaN or ±∞, is
//! rejected loudly: a [`StatusEvent::Report`] naming the reason, then `Dropped` with its
//! length; never a pose.
//!
//! # Units and axes
//! Positions become metres. OpenTrack's output frame is taken as ours (+X right, +Y up, +Z
//! toward the user, i.e. away from the camera), and orientation is
//! `Ry(yaw)·Rx(pitch)·Rz(roll)` in radians. OpenTrack's sign conventions depend on its own
//! mapping settings, so per-axis sign, scale and offset belong to the device profile, not here.
//! The station is always 1.

use super::decoder::Decoder;
use super::sample::{DeviceEvent, PoseSample, RawOrientation, StatusEvent};
use crate::pose::Pose;
use glam::{DQuat, DVec3, EulerRot};

/// Bytes in one datagram.
pub const DATAGRAM_LEN: usize = 48;

/// Position (cm) and Euler angles (yaw, pitch, roll in degrees) -> our pose.
pub fn pose_from_raw(position_cm: [f64; 3], ypr_deg: [f64; 3]) -> Pose {
    let [yaw, pitch, roll] = ypr_deg.map(f64::to_radians);
    Pose::new(
        (DVec3::from_array(position_cm) / 100.0).as_vec3(),
        DQuat::from_euler(EulerRot::YXZ, yaw, pitch, roll)
            .normalize()
            .as_quat(),
    )
}

/// Our pose -> position (cm) and yaw, pitch, roll (degrees). Inverse of [`pose_from_raw`].
pub fn raw_from_pose(pose: &Pose) -> ([f64; 3], [f64; 3]) {
    let (yaw, pitch, roll) = pose.orientation.as_dquat().to_euler(EulerRot::YXZ);
    (
        (pose.position_m.as_dvec3() * 100.0).to_array(),
        [yaw, pitch, roll].map(f64::to_degrees),
    )
}

/// OpenTrack datagram decoder (one datagram per feed).
#[derive(Debug, Clone, Default)]
pub struct OpentrackDecoder;

impl OpentrackDecoder {
    /// A decoder.
    pub fn new() -> Self {
        Self
    }
}

fn reject(text: String, bytes: usize, out: &mut Vec<DeviceEvent>) {
    out.push(DeviceEvent::Status(StatusEvent::Report { text }));
    out.push(DeviceEvent::Dropped { bytes });
}

impl Decoder for OpentrackDecoder {
    fn feed(&mut self, datagram: &[u8], out: &mut Vec<DeviceEvent>) {
        if datagram.len() != DATAGRAM_LEN {
            reject(
                format!(
                    "opentrack: datagram of {} bytes rejected (expected {DATAGRAM_LEN})",
                    datagram.len()
                ),
                datagram.len(),
                out,
            );
            return;
        }
        let mut v = [0.0f64; 6];
        for (i, chunk) in datagram.chunks_exact(8).enumerate() {
            let mut b = [0u8; 8];
            b.copy_from_slice(chunk);
            v[i] = f64::from_le_bytes(b);
        }
        const NAMES: [&str; 6] = ["x", "y", "z", "yaw", "pitch", "roll"];
        if let Some(i) = v.iter().position(|x| !x.is_finite()) {
            reject(
                format!("opentrack: datagram rejected, {} is {}", NAMES[i], v[i]),
                datagram.len(),
                out,
            );
            return;
        }
        let position = [v[0], v[1], v[2]];
        let ypr = [v[3], v[4], v[5]];
        let pose = pose_from_raw(position, ypr);
        if !pose.is_valid() {
            reject(
                "opentrack: datagram rejected, values out of range".to_owned(),
                datagram.len(),
                out,
            );
            return;
        }
        out.push(DeviceEvent::Pose(PoseSample {
            station: 1,
            pose,
            raw_position: position,
            raw_orientation: RawOrientation::EulerDeg(ypr),
            pressed: Vec::new(),
            status: None,
        }));
    }

    fn reset(&mut self) {}
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::devices::encode::opentrack::datagram;
    use crate::devices::test_util::{dropped, feed_all, poses};
    use glam::{Quat, Vec3};

    #[test]
    fn datagram_decodes_to_metres_and_radians() {
        let d = datagram([10.0, -5.0, 60.0, 90.0, 0.0, 0.0]);
        let events = feed_all(&mut OpentrackDecoder::new(), &d);
        let p = poses(&events);
        assert_eq!(p.len(), 1);
        assert!((p[0].pose.position_m - Vec3::new(0.1, -0.05, 0.6)).length() < 1e-6);
        let q = Quat::from_rotation_y(std::f32::consts::FRAC_PI_2);
        assert!(p[0].pose.orientation.dot(q).abs() > 1.0 - 1e-6);
        assert_eq!(
            p[0].raw_orientation,
            RawOrientation::EulerDeg([90.0, 0.0, 0.0])
        );
        // Yaw, then pitch, then roll.
        let d = datagram([0.0, 0.0, 0.0, 30.0, 20.0, 10.0]);
        let p = poses(&feed_all(&mut OpentrackDecoder::new(), &d));
        let expect = Quat::from_rotation_y(30f32.to_radians())
            * Quat::from_rotation_x(20f32.to_radians())
            * Quat::from_rotation_z(10f32.to_radians());
        assert!(p[0].pose.orientation.dot(expect).abs() > 1.0 - 1e-6);
    }

    #[test]
    fn round_trip_through_raw() {
        let pose = Pose::new(Vec3::new(0.1, 0.2, -0.3), Quat::from_rotation_x(0.4));
        let (p, a) = raw_from_pose(&pose);
        let back = pose_from_raw(p, a);
        assert!((back.position_m - pose.position_m).length() < 1e-6);
        assert!(back.orientation.dot(pose.orientation).abs() > 1.0 - 1e-6);
    }

    #[test]
    fn wrong_lengths_and_non_finite_values_are_rejected_loudly() {
        let mut dec = OpentrackDecoder::new();
        let good = datagram([1.0; 6]);
        for len in [0, 1, 47, 49, 96] {
            let bytes: Vec<u8> = good.iter().copied().cycle().take(len).collect();
            let events = feed_all(&mut dec, &bytes);
            assert!(poses(&events).is_empty());
            assert_eq!(dropped(&events), len);
            assert!(
                matches!(&events[0], DeviceEvent::Status(StatusEvent::Report { text }) if text.contains(&format!("{len} bytes")))
            );
        }
        for (i, bad) in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY]
            .into_iter()
            .enumerate()
        {
            let mut v = [1.0; 6];
            v[i + 2] = bad;
            let events = feed_all(&mut dec, &datagram(v));
            assert!(poses(&events).is_empty());
            assert_eq!(dropped(&events), 48);
            let DeviceEvent::Status(StatusEvent::Report { text }) = &events[0] else {
                panic!("{events:?}")
            };
            assert!(text.contains(["z", "yaw", "pitch"][i]), "{text}");
        }
        // A good datagram after bad ones still decodes.
        assert_eq!(poses(&feed_all(&mut dec, &good)).len(), 1);
    }
}
