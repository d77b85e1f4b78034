//! Device profiles: which devices to open, how, and which device plays which role (head, wand,
//! navigation), with per-axis sign, scale, offset and dead zone. Profiles are TOML files in
//! `devices/`; the format is documented in `docs/sessions.md`.

use crate::devices::desktop::DesktopSettings;
use crate::devices::protocol::{DecoderSettings, Protocol};
use crate::pose::Pose;
use glam::{EulerRot, Quat, Vec3};
use serde::{Deserialize, Serialize};
use std::fmt;
use std::path::{Path, PathBuf};

/// The current profile format version.
pub const PROFILE_VERSION: u32 = 1;

/// The logical roles the frame loop reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Role {
    /// The head tracker (eyes follow it).
    Head,
    /// The tracked 3D mouse in the dominant hand that drives tools.
    Wand,
    /// The Spaceball-class controller that flies the vehicle.
    Navigation,
}

impl Role {
    /// All roles, in a fixed order (the index used by role arrays).
    pub const ALL: [Role; 3] = [Role::Head, Role::Wand, Role::Navigation];

    /// Index into [`Role::ALL`].
    pub fn index(self) -> usize {
        match self {
            Role::Head => 0,
            Role::Wand => 1,
            Role::Navigation => 2,
        }
    }

    /// Lower-case name as in profiles.
    pub fn name(self) -> &'static str {
        match self {
            Role::Head => "head",
            Role::Wand => "wand",
            Role::Navigation => "navigation",
        }
    }
}

impl fmt::Display for Role {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// What kind of device a profile entry is: the desktop stand-ins or a wire protocol.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub enum DeviceKind {
    /// Mouse and keyboard stand-ins, fed by the window ([`crate::devices::desktop`]).
    Desktop,
    /// A real device speaking a protocol.
    Wire(Protocol),
}

impl TryFrom<String> for DeviceKind {
    type Error = String;
    fn try_from(s: String) -> Result<Self, String> {
        if s.eq_ignore_ascii_case("desktop") {
            return Ok(DeviceKind::Desktop);
        }
        s.parse::<Protocol>()
            .map(DeviceKind::Wire)
            .map_err(|e| format!("{e} or desktop"))
    }
}

impl From<DeviceKind> for String {
    fn from(k: DeviceKind) -> String {
        match k {
            DeviceKind::Desktop => "desktop".into(),
            DeviceKind::Wire(p) => p.name().into(),
        }
    }
}

/// Parity of a serial line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Parity {
    /// No parity bit.
    None,
    /// Odd parity.
    Odd,
    /// Even parity.
    Even,
}

/// Flow control of a serial line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FlowControl {
    /// None.
    None,
    /// XON/XOFF.
    Software,
    /// RTS/CTS.
    Hardware,
}

/// Serial line settings; unset fields take the protocol's defaults ([`SerialLine::for_protocol`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct SerialSpec {
    /// Device path (`/dev/ttyUSB0`, `COM3`).
    pub path: String,
    /// Baud rate.
    pub baud: Option<u32>,
    /// Data bits (5 to 8).
    pub data_bits: Option<u8>,
    /// Parity.
    pub parity: Option<Parity>,
    /// Stop bits (1 or 2).
    pub stop_bits: Option<u8>,
    /// Flow control.
    pub flow_control: Option<FlowControl>,
}

/// Fully resolved serial line settings.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct SerialLine {
    /// Baud rate.
    pub baud: u32,
    /// Data bits.
    pub data_bits: u8,
    /// Parity.
    pub parity: Parity,
    /// Stop bits.
    pub stop_bits: u8,
    /// Flow control.
    pub flow_control: FlowControl,
}

impl SerialLine {
    /// The line settings each serial protocol needs (PROTOCOLS.md): FASTRAK 115200 8N1, Spaceball
    /// 9600 8N1 XON/XOFF, Magellan 9600 8N2 RTS/CTS, Logitech 19200 8N1. Others: 9600 8N1.
    pub fn for_protocol(protocol: Protocol) -> Self {
        let line = |baud, stop_bits, flow_control| SerialLine {
            baud,
            data_bits: 8,
            parity: Parity::None,
            stop_bits,
            flow_control,
        };
        match protocol {
            Protocol::FastrakAscii | Protocol::FastrakBinary => line(115_200, 1, FlowControl::None),
            Protocol::Spaceball => line(9600, 1, FlowControl::Software),
            Protocol::Magellan => line(9600, 2, FlowControl::Hardware),
            Protocol::Logitech => line(19_200, 1, FlowControl::None),
            Protocol::SpacemouseHid | Protocol::Opentrack => line(9600, 1, FlowControl::None),
        }
    }

    /// `spec`'s explicit settings over the protocol's defaults.
    pub fn resolve(protocol: Protocol, spec: &SerialSpec) -> Self {
        let d = Self::for_protocol(protocol);
        SerialLine {
            baud: spec.baud.unwrap_or(d.baud),
            data_bits: spec.data_bits.unwrap_or(d.data_bits),
            parity: spec.parity.unwrap_or(d.parity),
            stop_bits: spec.stop_bits.unwrap_or(d.stop_bits),
            flow_control: spec.flow_control.unwrap_or(d.flow_control),
        }
    }
}

/// Which HID device to open; unset fields match any supported SpaceMouse.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct HidSpec {
    /// USB vendor id.
    pub vendor_id: Option<u16>,
    /// USB product id.
    pub product_id: Option<u16>,
    /// Serial number string.
    pub serial: Option<String>,
}

/// Where a UDP device listens.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UdpSpec {
    /// Local address to bind (`0.0.0.0:4242` by default, OpenTrack's default port).
    #[serde(default = "default_udp_bind")]
    pub bind: String,
}

fn default_udp_bind() -> String {
    "0.0.0.0:4242".into()
}

impl Default for UdpSpec {
    fn default() -> Self {
        Self {
            bind: default_udp_bind(),
        }
    }
}

/// How to reach a device.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum TransportSpec {
    /// No transport (desktop stand-ins, fed by the window).
    #[default]
    None,
    /// A serial port.
    Serial(SerialSpec),
    /// A USB HID device.
    Hid(HidSpec),
    /// A UDP socket.
    Udp(UdpSpec),
}

/// Driver timing (initialisation and reconnection).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DriverSettings {
    /// How long to wait for the device's answer during initialisation (seconds).
    pub init_timeout_s: f64,
    /// First wait before reopening a lost device (seconds); doubles on each failure.
    pub reconnect_min_s: f64,
    /// Longest wait between reopen attempts (seconds).
    pub reconnect_max_s: f64,
    /// A running device with no data for this long is reported stale (seconds). SpaceMice go
    /// silent when not touched: give them a large value.
    pub stale_after_s: f64,
    /// Longest a single read blocks before the reader checks for stop requests (seconds).
    pub read_timeout_s: f64,
}

impl Default for DriverSettings {
    fn default() -> Self {
        Self {
            init_timeout_s: 2.0,
            reconnect_min_s: 0.1,
            reconnect_max_s: 2.0,
            stale_after_s: 0.5,
            read_timeout_s: 0.05,
        }
    }
}

/// One device in a profile.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DeviceSpec {
    /// A name unique in the profile; roles refer to it.
    pub name: String,
    /// `desktop` or a protocol name (`fastrak-ascii`, `spaceball`, ...).
    pub protocol: DeviceKind,
    /// How to reach it (absent for `desktop`).
    #[serde(default)]
    pub transport: TransportSpec,
    /// What the device is configured to send (FASTRAK output list, units, stylus).
    #[serde(default)]
    pub decoder: DecoderSettings,
    /// Desktop stand-in settings (only for `desktop`).
    #[serde(default)]
    pub desktop: DesktopSettings,
    /// Timing of initialisation, reconnection and staleness.
    #[serde(default)]
    pub driver: DriverSettings,
}

/// Which kind of sample a role takes from its device.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Input {
    /// Poses of one station (trackers).
    #[default]
    Pose,
    /// Six axes and buttons (3D controllers).
    Axes,
}

/// One axis' mapping: `out = sign * scale * dead_zone(in) + offset`, where the dead zone sets
/// `|in| <= dead_zone` to 0 and shrinks larger values toward 0 by `dead_zone`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AxisMap {
    /// +1 or -1.
    pub sign: f32,
    /// Multiplier (finite).
    pub scale: f32,
    /// Added after scaling (metres for positions, radians for angles, unitless for axes).
    pub offset: f32,
    /// Half-width of the zone around 0 that reads as 0 (same unit as the input).
    pub dead_zone: f32,
}

impl Default for AxisMap {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl AxisMap {
    /// Passes the value through unchanged.
    pub const IDENTITY: Self = Self {
        sign: 1.0,
        scale: 1.0,
        offset: 0.0,
        dead_zone: 0.0,
    };

    /// Maps one value.
    pub fn apply(&self, v: f32) -> f32 {
        let dz = self.dead_zone.max(0.0);
        let shrunk = if v.abs() <= dz {
            0.0
        } else {
            v - dz * v.signum()
        };
        self.sign * self.scale * shrunk + self.offset
    }

    fn is_identity(&self) -> bool {
        *self == Self::IDENTITY
    }
}

/// Per-axis maps: for poses x, y, z are the position (metres) and rx, ry, rz are pitch, yaw,
/// roll (radians, the orientation taken apart as yaw about Y, then pitch about X, then roll about
/// Z); for axes devices they are the six axes in order.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
#[serde(default, deny_unknown_fields)]
pub struct AxisMaps {
    /// X (position x or axis 0).
    pub x: AxisMap,
    /// Y.
    pub y: AxisMap,
    /// Z.
    pub z: AxisMap,
    /// Rotation about X (pitch) or axis 3.
    pub rx: AxisMap,
    /// Rotation about Y (yaw) or axis 4.
    pub ry: AxisMap,
    /// Rotation about Z (roll) or axis 5.
    pub rz: AxisMap,
}

impl AxisMaps {
    fn all(&self) -> [(&'static str, &AxisMap); 6] {
        [
            ("x", &self.x),
            ("y", &self.y),
            ("z", &self.z),
            ("rx", &self.rx),
            ("ry", &self.ry),
            ("rz", &self.rz),
        ]
    }

    /// Maps six axis values.
    pub fn apply_axes(&self, v: [f32; 6]) -> [f32; 6] {
        let m = self.all();
        std::array::from_fn(|i| {
            let out = m[i].1.apply(v[i]);
            if out.is_finite() { out } else { 0.0 }
        })
    }

    /// Maps a pose; returns `None` when the result would not be finite.
    pub fn apply_pose(&self, pose: &Pose) -> Option<Pose> {
        let p = pose.position_m;
        let position_m = Vec3::new(self.x.apply(p.x), self.y.apply(p.y), self.z.apply(p.z));
        let orientation = if self.rx.is_identity() && self.ry.is_identity() && self.rz.is_identity()
        {
            pose.orientation
        } else {
            let (yaw, pitch, roll) = pose.orientation.to_euler(EulerRot::YXZ);
            Quat::from_euler(
                EulerRot::YXZ,
                self.ry.apply(yaw),
                self.rx.apply(pitch),
                self.rz.apply(roll),
            )
        };
        let out = Pose::new(position_m, orientation.normalize());
        out.is_valid().then_some(out)
    }
}

/// Binds a role to a device (and station).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RoleBinding {
    /// The role.
    pub role: Role,
    /// Name of a device in this profile.
    pub device: String,
    /// Pose of a station, or axes and buttons.
    #[serde(default)]
    pub input: Input,
    /// Station number for poses (1 for single-sensor devices; FASTRAK 1..=4).
    #[serde(default = "default_station")]
    pub station: u8,
    /// Per-axis sign, scale, offset and dead zone.
    #[serde(default)]
    pub map: AxisMaps,
}

fn default_station() -> u8 {
    1
}

/// A device profile.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Profile {
    /// Format version ([`PROFILE_VERSION`]).
    pub version: u32,
    /// A short name.
    pub name: String,
    /// What the setup is.
    #[serde(default)]
    pub description: String,
    /// The devices to open.
    #[serde(default, rename = "device")]
    pub devices: Vec<DeviceSpec>,
    /// Which device plays which role.
    #[serde(default, rename = "role")]
    pub roles: Vec<RoleBinding>,
}

/// A profile that cannot be loaded; names the file and, where it can, the field.
#[derive(Debug, thiserror::Error)]
pub enum ProfileError {
    /// The file could not be read.
    #[error("cannot read device profile {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// The TOML is malformed or a field has the wrong type (the message gives line, column and
    /// field).
    #[error("device profile {path}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// The parser's message.
        message: String,
    },
    /// A field has a value that cannot work.
    #[error("device profile {path}: field `{field}`: {message}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// Path of the field (`role[1].device`).
        field: String,
        /// What is wrong.
        message: String,
    },
}

impl Profile {
    /// Reads and checks a profile file.
    pub fn load(path: &Path) -> Result<Self, ProfileError> {
        let text = std::fs::read_to_string(path).map_err(|source| ProfileError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        Self::parse(&text, path)
    }

    /// Parses and checks profile text; `path` is only used in error messages.
    pub fn parse(text: &str, path: &Path) -> Result<Self, ProfileError> {
        let profile: Profile = toml::from_str(text).map_err(|e| ProfileError::Parse {
            path: path.to_path_buf(),
            message: e.to_string().trim_end().to_string(),
        })?;
        profile.validate(path)?;
        Ok(profile)
    }

    /// The profile as TOML text.
    pub fn to_toml(&self) -> Result<String, toml::ser::Error> {
        toml::to_string(self)
    }

    /// Index of the device called `name`.
    pub fn device_index(&self, name: &str) -> Option<usize> {
        self.devices.iter().position(|d| d.name == name)
    }

    /// The binding of `role`, if any.
    pub fn binding(&self, role: Role) -> Option<&RoleBinding> {
        self.roles.iter().find(|b| b.role == role)
    }

    /// Checks what the types cannot: versions, unique names, references, finite numbers.
    pub fn validate(&self, path: &Path) -> Result<(), ProfileError> {
        let bad = |field: String, message: String| ProfileError::Invalid {
            path: path.to_path_buf(),
            field,
            message,
        };
        if self.version != PROFILE_VERSION {
            return Err(bad(
                "version".into(),
                format!(
                    "version {} is not supported (this build reads {PROFILE_VERSION})",
                    self.version
                ),
            ));
        }
        for (i, d) in self.devices.iter().enumerate() {
            let f = |name: &str| format!("device[{i}].{name}");
            if d.name.trim().is_empty() {
                return Err(bad(f("name"), "must not be empty".into()));
            }
            if self.devices[..i].iter().any(|o| o.name == d.name) {
                return Err(bad(f("name"), format!("{:?} is used twice", d.name)));
            }
            if d.protocol == DeviceKind::Desktop
                && self.devices[..i]
                    .iter()
                    .any(|o| o.protocol == DeviceKind::Desktop)
            {
                return Err(bad(
                    f("protocol"),
                    "only one desktop device per profile".into(),
                ));
            }
            match (d.protocol, &d.transport) {
                (DeviceKind::Desktop, TransportSpec::None) => {}
                (DeviceKind::Desktop, _) => {
                    return Err(bad(
                        f("transport"),
                        "the desktop device takes no transport".into(),
                    ));
                }
                (DeviceKind::Wire(_), TransportSpec::None) => {
                    return Err(bad(f("transport"), "missing (serial, hid or udp)".into()));
                }
                (DeviceKind::Wire(p), TransportSpec::Serial(s)) => {
                    if s.path.trim().is_empty() {
                        return Err(bad(f("transport.path"), "must not be empty".into()));
                    }
                    let line = SerialLine::resolve(p, s);
                    if !(5..=8).contains(&line.data_bits) {
                        return Err(bad(f("transport.data_bits"), "must be 5 to 8".into()));
                    }
                    if !(1..=2).contains(&line.stop_bits) {
                        return Err(bad(f("transport.stop_bits"), "must be 1 or 2".into()));
                    }
                    if line.baud == 0 {
                        return Err(bad(f("transport.baud"), "must be positive".into()));
                    }
                }
                (DeviceKind::Wire(p), TransportSpec::Hid(_)) if p != Protocol::SpacemouseHid => {
                    return Err(bad(
                        f("transport"),
                        format!("{p} is not a HID protocol (use serial)"),
                    ));
                }
                (DeviceKind::Wire(p), TransportSpec::Udp(u)) => {
                    if p != Protocol::Opentrack {
                        return Err(bad(f("transport"), format!("{p} does not come over UDP")));
                    }
                    if u.bind.parse::<std::net::SocketAddr>().is_err() {
                        return Err(bad(
                            f("transport.bind"),
                            format!("{:?} is not an address like 0.0.0.0:4242", u.bind),
                        ));
                    }
                }
                (DeviceKind::Wire(_), _) => {}
            }
            if let DeviceKind::Wire(p) = d.protocol
                && let Err(e) = crate::devices::protocol::decoder_with_settings(p, &d.decoder)
            {
                return Err(bad(f("decoder"), e.to_string()));
            }
            if let Err((name, message)) = d.desktop.check() {
                return Err(bad(f(&format!("desktop.{name}")), message));
            }
            let s = &d.driver;
            for (name, v) in [
                ("init_timeout_s", s.init_timeout_s),
                ("reconnect_min_s", s.reconnect_min_s),
                ("reconnect_max_s", s.reconnect_max_s),
                ("stale_after_s", s.stale_after_s),
                ("read_timeout_s", s.read_timeout_s),
            ] {
                if !(v.is_finite() && v > 0.0 && v < 1.0e6) {
                    return Err(bad(
                        f(&format!("driver.{name}")),
                        format!("{v} is not a positive number of seconds"),
                    ));
                }
            }
        }
        for (i, b) in self.roles.iter().enumerate() {
            let f = |name: &str| format!("role[{i}].{name}");
            if self.roles[..i].iter().any(|o| o.role == b.role) {
                return Err(bad(f("role"), format!("{} is bound twice", b.role)));
            }
            if self.device_index(&b.device).is_none() {
                return Err(bad(
                    f("device"),
                    format!("no device named {:?} in this profile", b.device),
                ));
            }
            if b.input == Input::Pose && !(1..=4).contains(&b.station) {
                return Err(bad(f("station"), "must be 1 to 4".into()));
            }
            for (axis, m) in b.map.all() {
                let g = |k: &str| f(&format!("map.{axis}.{k}"));
                if m.sign != 1.0 && m.sign != -1.0 {
                    return Err(bad(g("sign"), format!("{} is not 1 or -1", m.sign)));
                }
                if !m.scale.is_finite() {
                    return Err(bad(g("scale"), "must be finite".into()));
                }
                if !m.offset.is_finite() {
                    return Err(bad(g("offset"), "must be finite".into()));
                }
                if !(m.dead_zone.is_finite() && m.dead_zone >= 0.0) {
                    return Err(bad(g("dead_zone"), "must be finite and >= 0".into()));
                }
            }
        }
        Ok(())
    }

    /// The built-in default: the desktop mouse and keyboard stand in for every role (the same
    /// profile as `devices/desktop.toml`).
    pub fn desktop_default() -> Self {
        Profile {
            version: PROFILE_VERSION,
            name: "desktop".into(),
            description: "No hardware: the mouse is the wand, the keyboard flies, the head sits \
                          0.6 m in front of the screen centre."
                .into(),
            devices: vec![DeviceSpec {
                name: "desktop".into(),
                protocol: DeviceKind::Desktop,
                transport: TransportSpec::None,
                decoder: DecoderSettings::default(),
                desktop: DesktopSettings::default(),
                driver: DriverSettings {
                    stale_after_s: 1.0e5,
                    ..DriverSettings::default()
                },
            }],
            roles: vec![
                RoleBinding {
                    role: Role::Head,
                    device: "desktop".into(),
                    input: Input::Pose,
                    station: crate::devices::desktop::HEAD_STATION,
                    map: AxisMaps::default(),
                },
                RoleBinding {
                    role: Role::Wand,
                    device: "desktop".into(),
                    input: Input::Pose,
                    station: crate::devices::desktop::WAND_STATION,
                    map: AxisMaps::default(),
                },
                RoleBinding {
                    role: Role::Navigation,
                    device: "desktop".into(),
                    input: Input::Axes,
                    station: 1,
                    map: AxisMaps::default(),
                },
            ],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Profile, ProfileError> {
        Profile::parse(text, Path::new("devices/test.toml"))
    }

    const GOOD: &str = r#"
version = 1
name = "t"

[[device]]
name = "fastrak"
protocol = "fastrak-ascii"
transport = { kind = "serial", path = "/dev/ttyS0" }

[[device]]
name = "ball"
protocol = "spaceball"
transport = { kind = "serial", path = "/dev/ttyS1", baud = 9600 }

[[role]]
role = "head"
device = "fastrak"
station = 1
map.x = { sign = -1, scale = 2.0 }

[[role]]
role = "navigation"
device = "ball"
input = "axes"
map.rz = { dead_zone = 0.1 }
"#;

    #[test]
    fn parses_a_profile_and_applies_maps() {
        let p = parse(GOOD).expect("good profile");
        assert_eq!(p.devices.len(), 2);
        assert_eq!(
            p.devices[0].protocol,
            DeviceKind::Wire(Protocol::FastrakAscii)
        );
        let head = p.binding(Role::Head).expect("head");
        let pose = Pose::from_translation(Vec3::new(0.1, 0.2, 0.3));
        let mapped = head.map.apply_pose(&pose).expect("finite");
        assert!((mapped.position_m - Vec3::new(-0.2, 0.2, 0.3)).length() < 1e-6);
        let nav = p.binding(Role::Navigation).expect("nav");
        let a = nav.map.apply_axes([0.0, 0.0, 0.0, 0.0, 0.0, 0.05]);
        assert_eq!(a[5], 0.0);
        let a = nav.map.apply_axes([0.0, 0.0, 0.0, 0.0, 0.0, -0.5]);
        assert!((a[5] + 0.4).abs() < 1e-6);
        let SerialLine {
            baud, stop_bits, ..
        } = match &p.devices[0].transport {
            TransportSpec::Serial(s) => SerialLine::resolve(Protocol::FastrakAscii, s),
            other => panic!("{other:?}"),
        };
        assert_eq!((baud, stop_bits), (115_200, 1));
    }

    #[test]
    fn rotation_maps_flip_yaw() {
        let mut maps = AxisMaps::default();
        maps.ry.sign = -1.0;
        let pose = Pose::new(Vec3::ZERO, Quat::from_rotation_y(0.3));
        let out = maps.apply_pose(&pose).expect("finite");
        assert!(out.orientation.angle_between(Quat::from_rotation_y(-0.3)) < 1e-5);
    }

    #[test]
    fn errors_name_the_file_and_field() {
        let unknown_protocol = GOOD.replace("\"spaceball\"", "\"spaceballz\"");
        let e = parse(&unknown_protocol)
            .expect_err("bad protocol")
            .to_string();
        assert!(
            e.contains("devices/test.toml") && e.contains("spaceballz"),
            "{e}"
        );
        assert!(e.contains("protocol"), "{e}");

        let bad_sign = GOOD.replace("sign = -1", "sign = 3");
        let e = parse(&bad_sign).expect_err("bad sign").to_string();
        assert!(e.contains("role[0].map.x.sign"), "{e}");

        let bad_ref = GOOD.replace("device = \"ball\"", "device = \"nope\"");
        let e = parse(&bad_ref).expect_err("bad device").to_string();
        assert!(e.contains("role[1].device") && e.contains("nope"), "{e}");

        let missing = GOOD.replace("role = \"head\"\n", "");
        let e = parse(&missing).expect_err("missing role").to_string();
        assert!(e.contains("devices/test.toml") && e.contains("role"), "{e}");

        let typo = GOOD.replace("station = 1", "statoin = 1");
        let e = parse(&typo).expect_err("unknown field").to_string();
        assert!(e.contains("statoin"), "{e}");

        // A NaN in the desktop stand-ins' settings would reach the wand pose (found by
        // tests/profile_fuzz.rs); the field is named.
        let mut desktop = Profile::desktop_default();
        desktop.devices[0].desktop.wand_area_m[0] = f32::NAN;
        let text = desktop.to_toml().expect("serialises");
        let e = parse(&text).expect_err("NaN wand area").to_string();
        assert!(e.contains("device[0].desktop.wand_area_m"), "{e}");

        let e = Profile::load(Path::new("/no/such/profile.toml"))
            .expect_err("missing file")
            .to_string();
        assert!(e.contains("/no/such/profile.toml"), "{e}");
    }

    #[test]
    fn committed_profiles_load_and_desktop_matches_the_builtin() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("devices");
        let mut names = Vec::new();
        for entry in std::fs::read_dir(&dir).expect("devices/") {
            let path = entry.expect("entry").path();
            if path.extension().is_some_and(|e| e == "toml") {
                let p = Profile::load(&path).unwrap_or_else(|e| panic!("{e}"));
                names.push(p.name.clone());
                if p.name == "desktop" {
                    assert_eq!(p, Profile::desktop_default());
                }
            }
        }
        names.sort();
        assert_eq!(
            names,
            ["desktop", "fastrak-spaceball", "opentrack-spacemouse"]
        );
    }

    #[test]
    fn desktop_default_round_trips_through_toml() {
        let p = Profile::desktop_default();
        p.validate(Path::new("builtin")).expect("valid");
        let text = p.to_toml().expect("toml");
        assert_eq!(parse(&text).expect("parse back"), p);
    }
}
