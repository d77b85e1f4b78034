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

/// An f32 written as the shortest decimal that reads back to it (0.1, not 0.10000000149011612).
#[derive(Clone, Copy)]
struct Short(f32);

impl Serialize for Short {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_f64(crate::decimal::widen_as_written(self.0))
    }
}

/// The `leman decode --json` shape (field order as documented; `kind` first).
#[derive(Serialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
enum JsonEvent<'a> {
    Pose {
        station: u8,
        position_m: [Short; 3],
        orientation_xyzw: [Short; 4],
        raw_position: &'a [f64; 3],
        #[serde(skip_serializing_if = "Option::is_none")]
        raw_euler_deg: Option<&'a [f64; 3]>,
        #[serde(skip_serializing_if = "Option::is_none")]
        raw_quaternion: Option<&'a [f64; 4]>,
        pressed: &'a [u8],
        status: Option<String>,
    },
    Axes {
        raw: &'a [i32; 6],
        value: [Short; 6],
    },
    Buttons {
        pressed: &'a [u8],
    },
    Status {
        #[serde(skip_serializing_if = "Option::is_none")]
        model: Option<&'a str>,
        text: &'a str,
    },
    Dropped {
        bytes: usize,
    },
}

impl DeviceEvent {
    fn json_event(&self) -> JsonEvent<'_> {
        match self {
            DeviceEvent::Pose(p) => {
                let q = p.pose.orientation;
                let (raw_euler_deg, raw_quaternion) = match &p.raw_orientation {
                    RawOrientation::EulerDeg(e) => (Some(e), None),
                    RawOrientation::Quaternion(q) => (None, Some(q)),
                };
                JsonEvent::Pose {
                    station: p.station,
                    position_m: p.pose.position_m.to_array().map(Short),
                    orientation_xyzw: [q.x, q.y, q.z, q.w].map(Short),
                    raw_position: &p.raw_position,
                    raw_euler_deg,
                    raw_quaternion,
                    pressed: &p.pressed,
                    status: p.status.map(String::from),
                }
            }
            DeviceEvent::Axes(a) => JsonEvent::Axes {
                raw: &a.raw,
                value: a.value.map(Short),
            },
            DeviceEvent::Buttons { pressed } => JsonEvent::Buttons { pressed },
            DeviceEvent::Status(StatusEvent::Identified { model, text }) => JsonEvent::Status {
                model: Some(model),
                text,
            },
            DeviceEvent::Status(StatusEvent::Report { text }) => {
                JsonEvent::Status { model: None, text }
            }
            DeviceEvent::Dropped { bytes } => JsonEvent::Dropped { bytes: *bytes },
        }
    }

    /// The event as one line of JSON in the documented `leman decode --json` shape: `kind`
    /// (`pose`, `axes`, `buttons`, `status` or `dropped`) first; see `docs/devices.md`.
    pub fn to_json_line(&self) -> String {
        serde_json::to_string(&self.json_event()).unwrap_or_else(|e| {
            format!("{{\"kind\":\"status\",\"text\":\"unserialisable event: {e}\"}}")
        })
    }

    /// The same object as [`DeviceEvent::to_json_line`], as a JSON value.
    pub fn to_json(&self) -> serde_json::Value {
        serde_json::to_value(self.json_event()).unwrap_or(serde_json::Value::Null)
    }

    /// One readable line describing the event.
    pub fn describe(&self) -> String {
        let v3 = |v: [f32; 3]| format!("[{:8.4} {:8.4} {:8.4}]", v[0], v[1], v[2]);
        let f3 = |v: &[f64; 3]| format!("[{:.2} {:.2} {:.2}]", v[0], v[1], v[2]);
        match self {
            DeviceEvent::Pose(p) => {
                let q = p.pose.orientation;
                let raw = match &p.raw_orientation {
                    RawOrientation::EulerDeg(e) => format!("euler_deg {}", f3(e)),
                    RawOrientation::Quaternion(q) => {
                        format!("quat [{:.4} {:.4} {:.4} {:.4}]", q[0], q[1], q[2], q[3])
                    }
                };
                let mut line = format!(
                    "pose    station {} position_m {} xyzw [{:7.4} {:7.4} {:7.4} {:7.4}]  raw position {} {raw}",
                    p.station,
                    v3(p.pose.position_m.to_array()),
                    q.x,
                    q.y,
                    q.z,
                    q.w,
                    f3(&p.raw_position),
                );
                if !p.pressed.is_empty() {
                    line.push_str(&format!(" pressed {:?}", p.pressed));
                }
                if let Some(s) = p.status {
                    line.push_str(&format!(" status {s:?}"));
                }
                line
            }
            DeviceEvent::Axes(a) => format!(
                "axes    raw {:?} value [{}]",
                a.raw,
                a.value
                    .iter()
                    .map(|v| format!("{v:6.3}"))
                    .collect::<Vec<_>>()
                    .join(" ")
            ),
            DeviceEvent::Buttons { pressed } => format!("buttons pressed {pressed:?}"),
            DeviceEvent::Status(StatusEvent::Identified { model, text }) => {
                format!("status  identified {model}: {text}")
            }
            DeviceEvent::Status(StatusEvent::Report { text }) => format!("status  {text}"),
            DeviceEvent::Dropped { bytes } => format!("dropped {bytes} bytes"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Quat, Vec3};

    #[test]
    fn json_shapes_match_the_documentation() {
        let pose = DeviceEvent::Pose(PoseSample {
            station: 2,
            pose: Pose::new(Vec3::new(0.1, 0.0, -0.5), Quat::IDENTITY),
            raw_position: [1.5, 2.0, 3.0],
            raw_orientation: RawOrientation::EulerDeg([10.0, 0.0, 0.0]),
            pressed: vec![0],
            status: Some('E'),
        });
        assert_eq!(
            pose.to_json_line(),
            r#"{"kind":"pose","station":2,"position_m":[0.1,0.0,-0.5],"orientation_xyzw":[0.0,0.0,0.0,1.0],"raw_position":[1.5,2.0,3.0],"raw_euler_deg":[10.0,0.0,0.0],"pressed":[0],"status":"E"}"#
        );
        let axes = DeviceEvent::Axes(AxesSample {
            raw: [1, -2, 3, 4, 5, 6],
            value: [0.1, -0.2, 0.0, 1.0, -1.0, 0.5],
        });
        assert_eq!(
            axes.to_json_line(),
            r#"{"kind":"axes","raw":[1,-2,3,4,5,6],"value":[0.1,-0.2,0.0,1.0,-1.0,0.5]}"#
        );
        assert_eq!(
            DeviceEvent::Buttons {
                pressed: vec![1, 3]
            }
            .to_json()
            .to_string(),
            r#"{"kind":"buttons","pressed":[1,3]}"#
        );
        assert_eq!(
            DeviceEvent::Dropped { bytes: 7 }.to_json_line(),
            r#"{"kind":"dropped","bytes":7}"#
        );
        let status = DeviceEvent::Status(StatusEvent::Identified {
            model: "m".into(),
            text: "t".into(),
        });
        assert_eq!(status.to_json()["kind"], "status");
        assert_eq!(status.to_json()["model"], "m");
        assert_eq!(
            status.to_json_line(),
            r#"{"kind":"status","model":"m","text":"t"}"#
        );
        let q = DeviceEvent::Pose(PoseSample {
            raw_orientation: RawOrientation::Quaternion([1.0, 0.0, 0.0, 0.0]),
            status: None,
            pressed: vec![],
            ..match pose {
                DeviceEvent::Pose(ref p) => p.clone(),
                _ => unreachable!(),
            }
        });
        assert_eq!(
            q.to_json()["raw_quaternion"],
            serde_json::json!([1.0, 0.0, 0.0, 0.0])
        );
        assert!(q.to_json().get("raw_euler_deg").is_none());
        assert_eq!(q.to_json()["status"], serde_json::Value::Null);
        assert!(axes.describe().starts_with("axes"));
        assert!(pose.describe().contains("status 'E'"));
    }
}
