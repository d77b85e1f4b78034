//! The generator of the sample sessions in `devices/sessions/` (we have no hardware here). Each
//! session is one device moved through a known motion ([`head_pose`], [`wand_pose`],
//! [`controller_axes`] at time t), encoded with the protocol encoders in
//! [`crate::devices::encode`], including the initialisation exchange (commands sent, replies
//! received). Serial byte streams are timed at the line's baud rate (10 bits per byte) and cut
//! into fragments of 1 to 24 bytes by a fixed pseudo-random sequence, as serial reads return them;
//! HID reports and UDP datagrams arrive one per chunk. Everything is deterministic, so the
//! committed files equal what this module generates (a test checks it).
//!
//! Regenerate after changing anything here or in the encoders:
//! `LEMAN_WRITE_SAMPLE_SESSIONS=1 cargo test --lib devices::sample_sessions`.

use crate::devices::encode;
use crate::devices::fastrak::{FastrakFormat, FastrakSettings, LengthUnit};
use crate::devices::profile::{
    AxisMaps, DeviceKind, DeviceSpec, DriverSettings, HidSpec, Input, PROFILE_VERSION, Profile,
    Role, RoleBinding, SerialLine, SerialSpec, TransportSpec, UdpSpec,
};
use crate::devices::protocol::{DecoderSettings, Protocol};
use crate::devices::session::{Record, Session, SessionError};
use crate::pose::Pose;
use glam::{EulerRot, Quat, Vec3};
use std::path::Path;
use std::time::Duration;

/// Length of each sample session's motion (seconds).
pub const MOTION_SECONDS: f64 = 1.0;

/// The known head motion: a 5 cm circle in x-y at 1 Hz around (0, 0.05, 0.5) m, nodding ±10°
/// about X and turning ±20° about Y.
pub fn head_pose(t: f64) -> Pose {
    let w = std::f64::consts::TAU * t;
    Pose::new(
        Vec3::new((0.05 * w.cos()) as f32, (0.05 + 0.05 * w.sin()) as f32, 0.5),
        Quat::from_euler(
            EulerRot::YXZ,
            (20f64.to_radians() * w.sin()) as f32,
            (10f64.to_radians() * (2.0 * w).sin()) as f32,
            0.0,
        ),
    )
}

/// The known wand motion: a straight push from (0.1, -0.1, 0.3) m by 0.2 m along -Z over the
/// second, turning up to 90° about Y.
pub fn wand_pose(t: f64) -> Pose {
    let s = (t / MOTION_SECONDS).clamp(0.0, 1.0) as f32;
    Pose::new(
        Vec3::new(0.1, -0.1, 0.3 - 0.2 * s),
        Quat::from_rotation_y(std::f32::consts::FRAC_PI_2 * s),
    )
}

/// Whether the wand's (or a controller's first) button is held at `t`: from 0.4 s to 0.6 s.
pub fn button_held(t: f64) -> bool {
    (0.4..0.6).contains(&t)
}

/// The known controller motion as fractions of full scale: push forward (half a sine) and twist
/// the other way (a full sine), other axes at rest.
pub fn controller_axes(t: f64) -> [f64; 6] {
    let w = std::f64::consts::PI * (t / MOTION_SECONDS).clamp(0.0, 1.0);
    [0.0, 0.0, 0.8 * w.sin(), 0.0, 0.0, -0.5 * (2.0 * w).sin()]
}

/// A fixed pseudo-random sequence (64-bit LCG) for fragment sizes and jitter.
struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> u64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        self.0 >> 33
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n.max(1)
    }
}

/// Builds a session's records: writes, and reads either as a byte stream or as messages.
struct Builder {
    records: Vec<Record>,
    rng: Lcg,
    byte_time: Duration,
    line_free_at: Duration,
    pending: Vec<u8>,
    pending_end: Duration,
    chunk_target: usize,
}

impl Builder {
    fn new(baud: u32, seed: u64) -> Self {
        let mut b = Self {
            records: vec![Record::Opened {
                at: Duration::ZERO,
                device: 0,
            }],
            rng: Lcg(seed),
            byte_time: Duration::from_nanos(10_000_000_000 / u64::from(baud.max(1))),
            line_free_at: Duration::ZERO,
            pending: Vec::new(),
            pending_end: Duration::ZERO,
            chunk_target: 0,
        };
        b.chunk_target = b.next_target();
        b
    }

    fn next_target(&mut self) -> usize {
        1 + self.rng.below(24) as usize
    }

    fn sent(&mut self, at: f64, bytes: &[u8]) {
        self.flush();
        self.records.push(Record::Sent {
            at: secs(at),
            device: 0,
            bytes: bytes.to_vec(),
        });
    }

    /// A message the device starts sending at `at` s, arriving byte by byte.
    fn stream(&mut self, at: f64, bytes: &[u8]) {
        let mut t = secs(at).max(self.line_free_at);
        for &b in bytes {
            t += self.byte_time;
            self.pending.push(b);
            self.pending_end = t;
            if self.pending.len() >= self.chunk_target {
                self.flush();
            }
        }
        self.line_free_at = t;
    }

    /// Ends the current fragment: it arrives a little after its last byte.
    fn flush(&mut self) {
        if self.pending.is_empty() {
            return;
        }
        let jitter = Duration::from_micros(100 + self.rng.below(900));
        let at = (self.pending_end + jitter).max(self.last_at());
        self.records.push(Record::Chunk {
            at,
            device: 0,
            bytes: std::mem::take(&mut self.pending),
        });
        self.chunk_target = self.next_target();
    }

    /// A whole message (HID report, datagram) arriving at `at` s.
    fn message(&mut self, at: f64, bytes: Vec<u8>) {
        let at = secs(at).max(self.last_at());
        self.records.push(Record::Chunk {
            at,
            device: 0,
            bytes,
        });
    }

    fn last_at(&self) -> Duration {
        self.records.last().map_or(Duration::ZERO, Record::at)
    }

    fn finish(mut self, profile: Profile) -> Session {
        self.flush();
        let mut s = Session::new(profile);
        s.header.recorded_by = "leman sample-session generator".into();
        s.records = self.records;
        s
    }
}

fn secs(s: f64) -> Duration {
    Duration::from_secs_f64(s.max(0.0))
}

fn serial_device(
    name: &str,
    protocol: Protocol,
    path: &str,
    decoder: DecoderSettings,
) -> DeviceSpec {
    DeviceSpec {
        name: name.into(),
        protocol: DeviceKind::Wire(protocol),
        transport: TransportSpec::Serial(SerialSpec {
            path: path.into(),
            ..SerialSpec::default()
        }),
        decoder,
        desktop: Default::default(),
        driver: DriverSettings::default(),
    }
}

fn bind(role: Role, device: &str, input: Input, station: u8) -> RoleBinding {
    RoleBinding {
        role,
        device: device.into(),
        input,
        station,
        map: AxisMaps::default(),
    }
}

fn profile(name: &str, description: &str, device: DeviceSpec, roles: Vec<RoleBinding>) -> Profile {
    Profile {
        version: PROFILE_VERSION,
        name: name.into(),
        description: description.into(),
        devices: vec![device],
        roles,
    }
}

fn ticks(rate_hz: f64) -> impl Iterator<Item = f64> {
    let n = (MOTION_SECONDS * rate_hz).round() as usize;
    (0..n).map(move |i| i as f64 / rate_hz)
}

fn fastrak(format: FastrakFormat) -> (String, Session) {
    let (protocol, settings, name) = match format {
        FastrakFormat::Ascii => (
            Protocol::FastrakAscii,
            FastrakSettings::default(),
            "fastrak-ascii",
        ),
        FastrakFormat::Binary => (
            Protocol::FastrakBinary,
            FastrakSettings {
                items: vec![2, 11, 16, 1],
                units: LengthUnit::Centimetres,
                stylus_bytes: 2,
            },
            "fastrak-binary",
        ),
    };
    let decoder = DecoderSettings {
        fastrak: settings.clone(),
    };
    let line = SerialLine::for_protocol(protocol);
    let mut b = Builder::new(line.baud, 0xFA57_0001 + format as u64);
    let init = crate::devices::driver::InitSettings {
        decoder: decoder.clone(),
        stations: vec![1, 2],
        timeout: Duration::from_secs(2),
    };
    b.sent(0.000_1, b"c\r");
    let mut t = 0.201;
    for cmd in crate::devices::driver::fastrak::setup_commands(protocol, &init) {
        b.sent(t, &cmd);
        t += 0.000_1;
    }
    b.sent(t, b"S\r");
    b.stream(
        t + 0.005,
        &encode::fastrak::encode_status_record(1, "sample FASTRAK 4.0"),
    );
    let start = t + 0.05;
    b.sent(start, b"C\r");
    // 120 records per second shared by stations 1 and 2.
    for (i, tick) in ticks(120.0).enumerate() {
        let station = 1 + (i % 2) as u8;
        let (pose, stylus) = if station == 1 {
            (head_pose(tick), false)
        } else {
            (wand_pose(tick), button_held(tick))
        };
        let rec = encode::fastrak::FastrakRecord::from_pose(station, &pose, settings.units, stylus);
        b.stream(
            start + 0.002 + tick,
            &encode::fastrak::encode_record(format, &settings, &rec),
        );
    }
    let device = serial_device("fastrak", protocol, "/dev/ttyUSB0", decoder);
    let p = profile(
        name,
        "Sample: FASTRAK, station 1 on the head, station 2 on the wand (stylus).",
        device,
        vec![
            bind(Role::Head, "fastrak", Input::Pose, 1),
            bind(Role::Wand, "fastrak", Input::Pose, 2),
        ],
    );
    (name.into(), b.finish(p))
}

fn to_i16(v: f64, full_scale: f64) -> i16 {
    (v * full_scale).round().clamp(-32768.0, 32767.0) as i16
}

fn spaceball() -> (String, Session) {
    let mut b = Builder::new(9600, 0x5BA1_1001);
    b.sent(0.0, crate::devices::driver::spaceball::RESET);
    b.stream(0.3, &encode::spaceball::encode_banner("2.43"));
    b.sent(0.45, crate::devices::driver::spaceball::SETUP);
    b.sent(0.45, crate::devices::driver::spaceball::START);
    let start = 0.5;
    b.stream(start, &encode::spaceball::encode_dot(&[], true));
    let mut held = false;
    for tick in ticks(50.0) {
        let axes = controller_axes(tick).map(|v| to_i16(v, 20000.0));
        let period = 20 * 16; // 20 ms in 1/16 ms
        b.stream(start + tick, &encode::spaceball::encode_d(period, axes));
        if button_held(tick) != held {
            held = !held;
            let pressed: &[u8] = if held { &[0] } else { &[] };
            b.stream(start + tick, &encode::spaceball::encode_dot(pressed, true));
        }
    }
    let device = serial_device(
        "spaceball",
        Protocol::Spaceball,
        "/dev/ttyS0",
        DecoderSettings::default(),
    );
    let p = profile(
        "spaceball",
        "Sample: a Spaceball 4000FLX as the navigation controller.",
        device,
        vec![bind(Role::Navigation, "spaceball", Input::Axes, 1)],
    );
    ("spaceball".into(), b.finish(p))
}

fn magellan() -> (String, Session) {
    let mut b = Builder::new(9600, 0x3A6E_0001);
    b.sent(0.0, b"vQ\r");
    b.stream(0.05, &encode::magellan::encode_version());
    b.sent(0.15, b"z\r");
    b.sent(0.15, b"m3\r");
    let start = 0.2;
    let mut held = false;
    for tick in ticks(50.0) {
        let axes = controller_axes(tick).map(|v| i32::from(to_i16(v, 500.0)));
        b.stream(start + tick, &encode::magellan::encode_d(axes));
        if button_held(tick) != held {
            held = !held;
            let pressed: &[u8] = if held { &[0] } else { &[] };
            b.stream(start + tick, &encode::magellan::encode_k(pressed, 3));
        }
    }
    let device = serial_device(
        "magellan",
        Protocol::Magellan,
        "/dev/ttyS0",
        DecoderSettings::default(),
    );
    let p = profile(
        "magellan",
        "Sample: a Magellan / SpaceMouse (serial) as the navigation controller.",
        device,
        vec![bind(Role::Navigation, "magellan", Input::Axes, 1)],
    );
    ("magellan".into(), b.finish(p))
}

fn spacemouse_hid() -> (String, Session) {
    let mut b = Builder::new(9600, 0x5E1D_0001);
    b.sent(0.0, &[4, 1]);
    let mut held = false;
    for tick in ticks(100.0) {
        let axes = controller_axes(tick).map(|v| i32::from(to_i16(v, 350.0)));
        let [t, r] = encode::spacemouse_hid::split_reports(axes);
        let at = 0.01 + tick;
        b.message(at, t);
        b.message(at + 0.000_5, r);
        if button_held(tick) != held {
            held = !held;
            let pressed: &[u8] = if held { &[0] } else { &[] };
            b.message(
                at + 0.001,
                encode::spacemouse_hid::buttons_report(pressed, 2),
            );
        }
    }
    // Released: a few zero reports, then silence.
    for k in 0..3 {
        let at = 0.01 + MOTION_SECONDS + 0.01 * f64::from(k);
        let [t, r] = encode::spacemouse_hid::split_reports([0; 6]);
        b.message(at, t);
        b.message(at + 0.000_5, r);
    }
    let device = DeviceSpec {
        name: "spacemouse".into(),
        protocol: DeviceKind::Wire(Protocol::SpacemouseHid),
        transport: TransportSpec::Hid(HidSpec {
            vendor_id: Some(0x046D),
            product_id: Some(0xC626),
            serial: None,
        }),
        decoder: DecoderSettings::default(),
        desktop: Default::default(),
        driver: DriverSettings {
            stale_after_s: 1.0e5,
            ..DriverSettings::default()
        },
    };
    let p = profile(
        "spacemouse-hid",
        "Sample: a SpaceNavigator (USB HID, split reports) as the navigation controller.",
        device,
        vec![bind(Role::Navigation, "spacemouse", Input::Axes, 1)],
    );
    ("spacemouse-hid".into(), b.finish(p))
}

fn opentrack() -> (String, Session) {
    let mut b = Builder::new(9600, 0x0DE2_0001);
    let mut rng = Lcg(0x0DE2_0002);
    for tick in ticks(60.0) {
        let (cm, ypr) = crate::devices::opentrack::raw_from_pose(&head_pose(tick));
        let jitter = rng.below(2000) as f64 * 1e-6;
        b.message(
            0.005 + tick + jitter,
            encode::opentrack::datagram([cm[0], cm[1], cm[2], ypr[0], ypr[1], ypr[2]]).to_vec(),
        );
    }
    let device = DeviceSpec {
        name: "opentrack".into(),
        protocol: DeviceKind::Wire(Protocol::Opentrack),
        transport: TransportSpec::Udp(UdpSpec::default()),
        decoder: DecoderSettings::default(),
        desktop: Default::default(),
        driver: DriverSettings::default(),
    };
    let p = profile(
        "opentrack",
        "Sample: OpenTrack (webcam head tracker) over UDP as the head tracker.",
        device,
        vec![bind(Role::Head, "opentrack", Input::Pose, 1)],
    );
    ("opentrack".into(), b.finish(p))
}

fn logitech() -> (String, Session) {
    let mut b = Builder::new(19_200, 0x1061_0001);
    b.sent(0.0, b"*R");
    b.sent(0.2, b"*\x05");
    b.stream(0.21, &[0xBF, 0x3F]);
    b.sent(0.25, b"*S");
    let start = 0.26;
    for tick in ticks(50.0) {
        let pose = wand_pose(tick);
        let (counts, pyr) = logitech_raw(&pose);
        let flags = if button_held(tick) {
            crate::devices::logitech::flags::LEFT
        } else {
            0
        };
        b.stream(start + tick, &encode::logitech::report(flags, counts, pyr));
    }
    let device = serial_device(
        "logitech",
        Protocol::Logitech,
        "/dev/ttyS1",
        DecoderSettings::default(),
    );
    let p = profile(
        "logitech",
        "Sample: the Logitech 3D mouse as the wand.",
        device,
        vec![bind(Role::Wand, "logitech", Input::Pose, 1)],
    );
    ("logitech".into(), b.finish(p))
}

/// A pose as the Logitech device reports it: positions in 1/1000 inch, and pitch, yaw, roll in
/// counts (40 per degree, angles taken into 0..360°), the inverse of
/// [`crate::devices::logitech::pose_from_raw`] (`Ry(yaw)·Rx(pitch)·Rz(roll)`).
fn logitech_raw(pose: &Pose) -> ([i32; 3], [u16; 3]) {
    let counts = (pose.position_m.as_dvec3() / crate::devices::logitech::METRES_PER_COUNT)
        .round()
        .as_ivec3()
        .to_array();
    let (yaw, pitch, roll) = pose.orientation.as_dquat().to_euler(EulerRot::YXZ);
    let raw = [pitch, yaw, roll].map(|a| {
        (a.to_degrees().rem_euclid(360.0) * crate::devices::logitech::COUNTS_PER_DEGREE).round()
            as u16
    });
    (counts, raw)
}

/// Every sample session: `(file stem, session)`, in a fixed order.
pub fn sample_sessions() -> Vec<(String, Session)> {
    vec![
        fastrak(FastrakFormat::Ascii),
        fastrak(FastrakFormat::Binary),
        spaceball(),
        magellan(),
        spacemouse_hid(),
        opentrack(),
        logitech(),
    ]
}

/// Writes every sample session as `<dir>/<stem>.session`.
pub fn write_sample_sessions(dir: &Path) -> Result<(), SessionError> {
    for (stem, s) in sample_sessions() {
        s.save(&dir.join(format!("{stem}.session")))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::devices::profile::Role;
    use crate::devices::replay::Replayer;
    use crate::devices::sample::DeviceEvent;

    fn committed_dir() -> std::path::PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("devices/sessions")
    }

    #[test]
    fn committed_sample_sessions_equal_the_generator() {
        let dir = committed_dir();
        if std::env::var_os("LEMAN_WRITE_SAMPLE_SESSIONS").is_some() {
            std::fs::create_dir_all(&dir).expect("mkdir");
            write_sample_sessions(&dir).expect("write");
        }
        for (stem, s) in sample_sessions() {
            let path = dir.join(format!("{stem}.session"));
            let committed = std::fs::read_to_string(&path).unwrap_or_else(|e| {
                panic!("{}: {e} (regenerate, see module docs)", path.display())
            });
            assert!(
                committed == s.to_text(),
                "{} differs from the generator: regenerate (see module docs)",
                path.display()
            );
        }
    }

    #[test]
    fn every_sample_replays_into_the_known_motion_without_drops() {
        for (stem, s) in sample_sessions() {
            let fragments = s
                .records
                .iter()
                .filter(|r| matches!(r, Record::Chunk { .. }))
                .count();
            let mut r = Replayer::new(s.clone()).expect("replayer");
            r.run_to_end();
            let events = r.drain_events();
            let dropped: usize = events
                .iter()
                .map(|e| match &e.event {
                    DeviceEvent::Dropped { bytes } => *bytes,
                    _ => 0,
                })
                .sum();
            let samples = events
                .iter()
                .filter(|e| matches!(e.event, DeviceEvent::Pose(_) | DeviceEvent::Axes(_)))
                .count();
            assert!(
                samples >= 45,
                "{stem}: only {samples} samples from {fragments} chunks"
            );
            // Logitech's diagnostics reply is two stray bytes the decoder drops, by design.
            let allowed = if stem == "logitech" { 2 } else { 0 };
            assert!(dropped <= allowed, "{stem}: {dropped} bytes dropped");
            let snap = r.snapshot(s.duration());
            for role in Role::ALL {
                let Some(b) = s.header.profile.binding(role) else {
                    continue;
                };
                let got = snap.role(role);
                assert!(got.at.is_some(), "{stem}: no {role} sample");
                match b.input {
                    Input::Pose => {
                        // The last sample of the motion (t close to 1 s) is what the role holds.
                        let pose = got.pose.expect("pose");
                        let expect = if role == Role::Head {
                            head_pose(MOTION_SECONDS)
                        } else {
                            wand_pose(MOTION_SECONDS)
                        };
                        let dist = pose.position_m.distance(expect.position_m);
                        assert!(dist < 0.01, "{stem} {role}: {dist} m from the known motion");
                        let angle = pose.orientation.angle_between(expect.orientation);
                        assert!(
                            angle < 0.15,
                            "{stem} {role}: {angle} rad from the known motion"
                        );
                    }
                    Input::Axes => {
                        // Held at the last value; the motion ends near rest.
                        assert!(
                            got.axes.iter().all(|v| v.abs() < 0.2),
                            "{stem}: {:?}",
                            got.axes
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn serial_samples_are_fragmented_across_packets() {
        for (stem, s) in sample_sessions() {
            if matches!(stem.as_str(), "spacemouse-hid" | "opentrack") {
                continue;
            }
            let sizes: Vec<usize> = s.chunks(0).map(|(_, b)| b.len()).collect();
            assert!(sizes.contains(&1), "{stem}: some 1-byte reads");
            assert!(sizes.iter().any(|&n| n > 16), "{stem}: some long reads");
        }
    }
}
