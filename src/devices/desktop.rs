//! The desktop mouse and keyboard as stand-ins for the head tracker, the wand and the navigation
//! controller, so the workstation is usable without any hardware.
//!
//! The window layer turns its own events into [`DesktopEvent`]s and hands them to the hub
//! (`Hub::feed_desktop`). They are stamped and recorded in sessions like device bytes, and a
//! [`DesktopDevice`] (a pure state machine) turns them into the same [`DeviceEvent`]s a real
//! device produces:
//!
//! - station 1 pose ("head"): fixed at [`DesktopSettings::head_position_m`], looking down -Z;
//! - station 2 pose ("wand"): the cursor mapped onto a rectangle of
//!   [`DesktopSettings::wand_area_m`] centred on the screen, at depth `wand_depth_m` (moved by the
//!   wheel), identity orientation; mouse buttons left, right, middle are wand buttons 0, 1, 2;
//! - axes ("navigation"): keys W/S move forward/back (-Z/+Z), A/D left/right (-X/+X), R/F up/down
//!   (+Y/-Y); arrow Up/Down pitch (about X), Left/Right yaw (about Y), Q/E roll (about Z). Each
//!   held key gives ±1 on its axis (raw ±1, value ±1);
//! - buttons: digit keys 1..9 are navigation buttons 0..8.
//!
//! The desktop frame is the screen frame: origin at the screen centre, +X right, +Y up, +Z toward
//! the viewer, metres.

use crate::devices::sample::{AxesSample, DeviceEvent, PoseSample, RawOrientation};
use crate::pose::Pose;
use glam::{Quat, Vec3};
use serde::{Deserialize, Serialize};

/// One window event of the desktop stand-ins, as recorded in sessions.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum DesktopEvent {
    /// The cursor moved; position normalised to the window: x from 0 (left) to 1 (right),
    /// y from 0 (top) to 1 (bottom).
    MouseMove {
        /// Horizontal position, 0 = left edge, 1 = right edge.
        x: f32,
        /// Vertical position, 0 = top edge, 1 = bottom edge.
        y: f32,
    },
    /// A mouse button changed: 0 left, 1 right, 2 middle, others as the window numbers them.
    MouseButton {
        /// Button number.
        button: u8,
        /// True when pressed, false when released.
        pressed: bool,
    },
    /// The wheel turned, in lines (positive = away from the user).
    Wheel {
        /// Lines scrolled.
        delta_lines: f32,
    },
    /// A key changed. Names as egui's `Key::name()` gives them ("W", "Up", "1"); case-insensitive,
    /// "ArrowUp" etc. are accepted too.
    Key {
        /// Key name.
        name: String,
        /// True when pressed, false when released.
        pressed: bool,
    },
    /// The window lost focus: every key and button counts as released.
    FocusLost,
}

/// Settings of the desktop stand-ins (in a profile's `[devices.desktop]` table).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DesktopSettings {
    /// Where the stand-in head sits, in the screen frame (metres).
    pub head_position_m: [f32; 3],
    /// Width and height of the area the cursor spans for the wand (metres).
    pub wand_area_m: [f32; 2],
    /// Initial distance of the wand in front of the screen (metres).
    pub wand_depth_m: f32,
    /// How far one wheel line moves the wand in depth (metres).
    pub wheel_step_m: f32,
    /// Nearest and farthest wand depth (metres).
    pub wand_depth_range_m: [f32; 2],
}

impl Default for DesktopSettings {
    fn default() -> Self {
        Self {
            head_position_m: [0.0, 0.0, 0.6],
            wand_area_m: [0.4, 0.3],
            wand_depth_m: 0.1,
            wheel_step_m: 0.01,
            wand_depth_range_m: [-0.3, 0.5],
        }
    }
}

impl DesktopSettings {
    /// The first setting out of range, as its field name and what is wrong: every value must
    /// be finite, the wand area positive and the wheel step not negative (a NaN here would
    /// reach the wand pose, and a NaN depth range the wheel's clamp).
    pub fn check(&self) -> Result<(), (&'static str, String)> {
        let finite = |name: &'static str, values: &[f32]| {
            if values.iter().all(|v| v.is_finite()) {
                Ok(())
            } else {
                Err((name, format!("{values:?} is not finite")))
            }
        };
        finite("head_position_m", &self.head_position_m)?;
        finite("wand_area_m", &self.wand_area_m)?;
        finite("wand_depth_m", &[self.wand_depth_m])?;
        finite("wheel_step_m", &[self.wheel_step_m])?;
        finite("wand_depth_range_m", &self.wand_depth_range_m)?;
        if self.wand_area_m.iter().any(|v| *v <= 0.0) {
            return Err((
                "wand_area_m",
                format!("{:?} must be positive", self.wand_area_m),
            ));
        }
        if self.wheel_step_m < 0.0 {
            return Err((
                "wheel_step_m",
                format!("{} must not be negative", self.wheel_step_m),
            ));
        }
        Ok(())
    }
}

/// Station number of the stand-in head pose.
pub const HEAD_STATION: u8 = 1;
/// Station number of the stand-in wand pose.
pub const WAND_STATION: u8 = 2;

/// Which navigation axis a key drives, and in which direction.
fn key_axis(name: &str) -> Option<(usize, i32)> {
    let lower = name.to_ascii_lowercase();
    let key = lower.strip_prefix("arrow").unwrap_or(&lower);
    Some(match key {
        "d" => (0, 1),
        "a" => (0, -1),
        "r" => (1, 1),
        "f" => (1, -1),
        "s" => (2, 1),
        "w" => (2, -1),
        "up" => (3, 1),
        "down" => (3, -1),
        "left" => (4, 1),
        "right" => (4, -1),
        "q" => (5, 1),
        "e" => (5, -1),
        _ => return None,
    })
}

fn key_button(name: &str) -> Option<u8> {
    let digit = name.strip_prefix("Num").unwrap_or(name);
    match digit.parse::<u8>() {
        Ok(n @ 1..=9) => Some(n - 1),
        _ => None,
    }
}

/// The desktop stand-in device: a pure state machine from [`DesktopEvent`]s to device events.
#[derive(Debug, Clone)]
pub struct DesktopDevice {
    settings: DesktopSettings,
    cursor: [f32; 2],
    depth_m: f32,
    mouse_pressed: Vec<u8>,
    keys_held: Vec<String>,
    buttons_held: Vec<u8>,
}

impl DesktopDevice {
    /// A stand-in device with the cursor in the window centre and nothing held.
    pub fn new(settings: DesktopSettings) -> Self {
        let depth_m = settings.wand_depth_m;
        Self {
            settings,
            cursor: [0.5, 0.5],
            depth_m,
            mouse_pressed: Vec::new(),
            keys_held: Vec::new(),
            buttons_held: Vec::new(),
        }
    }

    /// The events describing the current state (head, wand, axes, buttons), as emitted at start.
    pub fn current(&self, out: &mut Vec<DeviceEvent>) {
        out.push(self.head_event());
        out.push(self.wand_event());
        out.push(self.axes_event());
        out.push(DeviceEvent::Buttons {
            pressed: self.buttons_held.clone(),
        });
    }

    /// Applies one window event and appends the samples it changes.
    pub fn feed(&mut self, event: &DesktopEvent, out: &mut Vec<DeviceEvent>) {
        match event {
            DesktopEvent::MouseMove { x, y } => {
                if x.is_finite() && y.is_finite() {
                    self.cursor = [x.clamp(0.0, 1.0), y.clamp(0.0, 1.0)];
                    out.push(self.wand_event());
                }
            }
            DesktopEvent::MouseButton { button, pressed } => {
                let changed = set_member(&mut self.mouse_pressed, *button, *pressed);
                if changed {
                    out.push(self.wand_event());
                }
            }
            DesktopEvent::Wheel { delta_lines } => {
                if delta_lines.is_finite() && *delta_lines != 0.0 {
                    let [near, far] = self.settings.wand_depth_range_m;
                    let (lo, hi) = (near.min(far), near.max(far));
                    self.depth_m =
                        (self.depth_m - delta_lines * self.settings.wheel_step_m).clamp(lo, hi);
                    out.push(self.wand_event());
                }
            }
            DesktopEvent::Key { name, pressed } => {
                if key_axis(name).is_some() {
                    let lower = name.to_ascii_lowercase();
                    let held = self.keys_held.contains(&lower);
                    if *pressed && !held {
                        self.keys_held.push(lower);
                        out.push(self.axes_event());
                    } else if !*pressed && held {
                        self.keys_held.retain(|k| *k != lower);
                        out.push(self.axes_event());
                    }
                } else if let Some(button) = key_button(name)
                    && set_member(&mut self.buttons_held, button, *pressed)
                {
                    out.push(DeviceEvent::Buttons {
                        pressed: self.buttons_held.clone(),
                    });
                }
            }
            DesktopEvent::FocusLost => {
                if !self.mouse_pressed.is_empty() {
                    self.mouse_pressed.clear();
                    out.push(self.wand_event());
                }
                if !self.keys_held.is_empty() {
                    self.keys_held.clear();
                    out.push(self.axes_event());
                }
                if !self.buttons_held.is_empty() {
                    self.buttons_held.clear();
                    out.push(DeviceEvent::Buttons {
                        pressed: Vec::new(),
                    });
                }
            }
        }
    }

    fn head_event(&self) -> DeviceEvent {
        let p = Vec3::from_array(self.settings.head_position_m);
        let p = if p.is_finite() { p } else { Vec3::ZERO };
        pose_event(HEAD_STATION, p, Vec::new())
    }

    fn wand_event(&self) -> DeviceEvent {
        let [w, h] = self.settings.wand_area_m;
        let p = Vec3::new(
            (self.cursor[0] - 0.5) * w,
            (0.5 - self.cursor[1]) * h,
            self.depth_m,
        );
        let p = if p.is_finite() { p } else { Vec3::ZERO };
        pose_event(WAND_STATION, p, self.mouse_pressed.clone())
    }

    fn axes_event(&self) -> DeviceEvent {
        let mut raw = [0i32; 6];
        for key in &self.keys_held {
            if let Some((axis, sign)) = key_axis(key)
                && let Some(slot) = raw.get_mut(axis)
            {
                *slot = (*slot + sign).clamp(-1, 1);
            }
        }
        DeviceEvent::Axes(AxesSample {
            raw,
            value: raw.map(|v| v as f32),
        })
    }
}

fn pose_event(station: u8, position_m: Vec3, pressed: Vec<u8>) -> DeviceEvent {
    DeviceEvent::Pose(PoseSample {
        station,
        pose: Pose::new(position_m, Quat::IDENTITY),
        raw_position: position_m.as_dvec3().to_array(),
        raw_orientation: RawOrientation::Quaternion([1.0, 0.0, 0.0, 0.0]),
        pressed,
        status: None,
    })
}

/// Adds or removes `item` (kept sorted); returns whether the set changed.
fn set_member(set: &mut Vec<u8>, item: u8, present: bool) -> bool {
    match (set.binary_search(&item), present) {
        (Err(at), true) => {
            set.insert(at, item);
            true
        }
        (Ok(at), false) => {
            set.remove(at);
            true
        }
        _ => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn wand(events: &[DeviceEvent]) -> &PoseSample {
        events
            .iter()
            .rev()
            .find_map(|e| match e {
                DeviceEvent::Pose(p) if p.station == WAND_STATION => Some(p),
                _ => None,
            })
            .expect("a wand pose")
    }

    #[test]
    fn cursor_maps_onto_the_wand_area_and_wheel_moves_depth() {
        let mut dev = DesktopDevice::new(DesktopSettings::default());
        let mut out = Vec::new();
        dev.feed(&DesktopEvent::MouseMove { x: 1.0, y: 0.0 }, &mut out);
        let p = wand(&out).pose.position_m;
        assert!((p - Vec3::new(0.2, 0.15, 0.1)).length() < 1e-6, "{p}");
        dev.feed(&DesktopEvent::Wheel { delta_lines: 2.0 }, &mut out);
        assert!((wand(&out).pose.position_m.z - 0.08).abs() < 1e-6);
        dev.feed(
            &DesktopEvent::MouseMove {
                x: f32::NAN,
                y: 0.3,
            },
            &mut out,
        );
        assert!(wand(&out).pose.is_valid());
    }

    #[test]
    fn keys_drive_axes_and_focus_loss_releases_everything() {
        let mut dev = DesktopDevice::new(DesktopSettings::default());
        let mut out = Vec::new();
        for name in ["W", "ArrowLeft", "q"] {
            dev.feed(
                &DesktopEvent::Key {
                    name: name.into(),
                    pressed: true,
                },
                &mut out,
            );
        }
        match out.last() {
            Some(DeviceEvent::Axes(a)) => assert_eq!(a.raw, [0, 0, -1, 0, 1, 1]),
            other => panic!("expected axes, got {other:?}"),
        }
        // A repeated press (key repeat) changes nothing.
        let before = out.len();
        dev.feed(
            &DesktopEvent::Key {
                name: "w".into(),
                pressed: true,
            },
            &mut out,
        );
        assert_eq!(out.len(), before);
        dev.feed(
            &DesktopEvent::Key {
                name: "3".into(),
                pressed: true,
            },
            &mut out,
        );
        assert_eq!(out.last(), Some(&DeviceEvent::Buttons { pressed: vec![2] }));
        dev.feed(
            &DesktopEvent::MouseButton {
                button: 0,
                pressed: true,
            },
            &mut out,
        );
        assert_eq!(wand(&out).pressed, vec![0]);
        out.clear();
        dev.feed(&DesktopEvent::FocusLost, &mut out);
        assert_eq!(wand(&out).pressed, Vec::<u8>::new());
        assert!(
            out.iter()
                .any(|e| matches!(e, DeviceEvent::Axes(a) if a.raw == [0; 6]))
        );
        assert!(out.contains(&DeviceEvent::Buttons { pressed: vec![] }));
    }

    #[test]
    fn desktop_events_round_trip_through_json() {
        let events = vec![
            DesktopEvent::MouseMove { x: 0.25, y: 0.75 },
            DesktopEvent::MouseButton {
                button: 1,
                pressed: true,
            },
            DesktopEvent::Wheel { delta_lines: -1.5 },
            DesktopEvent::Key {
                name: "Up".into(),
                pressed: false,
            },
            DesktopEvent::FocusLost,
        ];
        for e in events {
            let text = serde_json::to_string(&e).expect("serialise");
            let back: DesktopEvent = serde_json::from_str(&text).expect("parse");
            assert_eq!(back, e);
        }
    }
}
