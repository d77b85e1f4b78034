//! What decoders produce: device events in our units and frame (metres, radians, +Y up,
//! right-handed), each also carrying the device's own numbers for debugging and `leman decode`.

use crate::pose::Pose;
use serde::{Deserialize, Serialize};

/// The device's own orientation numbers, as sent.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum RawOrientation {
    /// Euler angles in degrees (azimuth, elevation, roll for FASTRAK; pitch, yaw, roll for
    /// Logitech; yaw, pitch, roll for OpenTrack), in the device's order.
    EulerDeg([f64; 3]),
    /// A quaternion as sent, scalar first (q0, q1, q2, q3).
    Quaternion([f64; 4]),
}

/// A 6-DOF pose from a tracker station.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PoseSample {
    /// Station (receiver) number as the device counts it (FASTRAK 1..=4; 1 for single-sensor
    /// devices).
    pub station: u8,
    /// Sensor pose in the tracker's base frame, converted to metres and +Y up.
    pub pose: Pose,
    /// Position as sent, in the device's units and axes.
    pub raw_position: [f64; 3],
    /// Orientation as sent.
    pub raw_orientation: RawOrientation,
    /// Buttons held on this station (stylus switch, mouse buttons), 0-based.
    pub pressed: Vec<u8>,
    /// A device status letter or flag that came with the record, if any.
    pub status: Option<char>,
}

/// Six axes from a 3D controller (Spaceball, Magellan, SpaceMouse).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AxesSample {
    /// Tx, Ty, Tz, Rx, Ry, Rz exactly as on the wire (after unescaping), no sign flips or scale.
    pub raw: [i32; 6],
    /// Normalised to about [-1, 1] and signed into our frame: translation x (right), y (up),
    /// z (toward the user), then rotation about those same axes (right-hand rule).
    pub value: [f32; 6],
}

/// Something a decoder reports that is not a measurement.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum StatusEvent {
    /// The device identified itself (banner, version string).
    Identified {
        /// Model name as detected.
        model: String,
        /// The raw identification text.
        text: String,
    },
    /// A device status record or error letter.
    Report {
        /// Human-readable description.
        text: String,
    },
}

/// One decoded event.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum DeviceEvent {
    /// A tracker pose.
    Pose(PoseSample),
    /// Six axes of a 3D controller.
    Axes(AxesSample),
    /// The full set of buttons now held (0-based numbers).
    Buttons {
        /// Buttons held now.
        pressed: Vec<u8>,
    },
    /// Identification or status.
    Status(StatusEvent),
    /// Bytes discarded while resynchronising.
    Dropped {
        /// How many bytes were dropped.
        bytes: usize,
    },
}
