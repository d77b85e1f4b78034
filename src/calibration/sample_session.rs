//! The generator of `calibration/sessions/touch-corners.session`: a FASTRAK (ASCII, centimetres,
//! position + Euler + stylus) with the head on station 1 and the wand on station 2, recorded
//! while someone touches the four corners of a known screen with the wand tip, then accepts.
//! The tracker frames come from `calibration/fastrak-desk.toml` (transmitter under the desk,
//! turned; wand tip 10 cm in front of its sensor), so a replay exercises the decoder, the hub's
//! role maps, both tracker transforms, the stillness rule, outlier rejection and the fit.
//!
//! The wand: starts at rest, travels 0.7 s (smooth step) to each corner in turn (lower left,
//! lower right, upper right, upper left), holds 0.9 s with ±0.3 mm jitter and presses the stylus
//! 0.5 s into the hold for 0.2 s; one extra press during the first travel must be ignored
//! (moving); after the last corner it goes back to rest and presses once more (accept).
//! 80 records per second shared by the two stations; bytes arrive at 115200 baud in fragments
//! of 1 to 24 bytes (fixed pseudo-random sequence). Deterministic: a test checks the committed
//! file equals this output. Regenerate with
//! `LEMAN_WRITE_CALIBRATION_SESSION=1 cargo test --lib calibration::sample_session`.

use super::profile::CalibrationProfile;
use super::screen::{Corner, ScreenRect};
use crate::devices::encode::fastrak::{FastrakRecord, encode_record};
use crate::devices::fastrak::{FastrakFormat, FastrakSettings, LengthUnit};
use crate::devices::profile::{
    AxisMaps, DeviceKind, DeviceSpec, DriverSettings, Input, PROFILE_VERSION, Profile, Role,
    RoleBinding, SerialSpec, TransportSpec,
};
use crate::devices::protocol::{DecoderSettings, Protocol};
use crate::devices::session::{Record, Session};
use crate::pose::Pose;
use glam::{Quat, Vec3};
use std::time::Duration;

/// Path of the session, relative to the crate root.
pub const SESSION_PATH: &str = "calibration/sessions/touch-corners.session";
/// Path of the calibration profile with the tracker frames it was made for.
pub const PROFILE_PATH: &str = "calibration/fastrak-desk.toml";

/// The screen the session touches, in the world frame: 0.53 m × 0.30 m, centre
/// (0.05, 0.22, −0.30) m, tilted back 12° and turned 8° to the left.
pub fn known_screen() -> Option<ScreenRect> {
    let rot = Quat::from_rotation_y(8f32.to_radians()) * Quat::from_rotation_x(-12f32.to_radians());
    ScreenRect::from_center(
        Vec3::new(0.05, 0.22, -0.30),
        rot * Vec3::X,
        rot * Vec3::Y,
        0.53,
        0.30,
    )
    .ok()
}

/// The tracker frames of `calibration/fastrak-desk.toml`: the transmitter 0.4 m below and 0.2 m
/// in front of the world origin, turned 90° about +Y; the wand tip 0.1 m along the sensor's −Z.
pub fn desk_profile() -> Option<CalibrationProfile> {
    let mut p = CalibrationProfile {
        name: "FASTRAK on the desk (the sample calibration session's setup)".into(),
        screen: known_screen()?,
        ..CalibrationProfile::default()
    };
    p.tracker.world_from_tracker = Pose::new(
        Vec3::new(0.0, -0.4, 0.2),
        Quat::from_rotation_y(std::f32::consts::FRAC_PI_2),
    );
    p.tracker.wand_tip_in_sensor_m = Vec3::new(0.0, 0.0, -0.1);
    p.default_head = Pose::from_translation(Vec3::new(0.05, 0.25, 0.35));
    Some(p)
}

struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> u64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        self.0 >> 33
    }
    /// Uniform in [−1, 1].
    fn unit(&mut self) -> f32 {
        (self.next() % 20001) as f32 / 10000.0 - 1.0
    }
}

/// One segment of the wand's script.
struct Segment {
    from_m: Vec3,
    to_m: Vec3,
    travel_s: f64,
    hold_s: f64,
    /// Presses (start, length) relative to the segment's start.
    presses: Vec<(f64, f64)>,
}

fn smoothstep(x: f64) -> f32 {
    let x = x.clamp(0.0, 1.0);
    (x * x * (3.0 - 2.0 * x)) as f32
}

/// The session (deterministic).
pub fn generate() -> Option<Session> {
    let screen = known_screen()?;
    let profile = desk_profile()?;
    let frames = profile.tracker;
    let tracker_from_world = frames.world_from_tracker.inverse();
    // The wand tilted toward the screen (tip forward and down), constant.
    let wand_orientation = Quat::from_rotation_x(-0.4) * Quat::from_rotation_y(0.2);
    let rest = Vec3::new(0.25, -0.15, 0.15);
    let mut script = Vec::new();
    let mut from = rest;
    for (i, corner) in Corner::ALL.into_iter().enumerate() {
        let to = screen.corner_m(corner);
        let mut presses = vec![(0.7 + 0.5, 0.2)];
        if i == 0 {
            presses.insert(0, (0.3, 0.15)); // while moving: ignored
        }
        script.push(Segment {
            from_m: from,
            to_m: to,
            travel_s: 0.7,
            hold_s: 0.9,
            presses,
        });
        from = to;
    }
    script.push(Segment {
        from_m: from,
        to_m: rest,
        travel_s: 0.7,
        hold_s: 0.9,
        presses: vec![(0.7 + 0.5, 0.2)],
    });
    let settings = FastrakSettings {
        items: vec![2, 4, 16, 1],
        units: LengthUnit::Centimetres,
        stylus_bytes: 2,
    };
    let head =
        Pose::from_translation(tracker_from_world.transform_point(Vec3::new(0.05, 0.25, 0.35)));
    let byte_time = Duration::from_nanos(10_000_000_000 / 115_200);
    let mut rng = Lcg(0xCA11_B8A7);
    let mut records = vec![Record::Opened {
        at: Duration::ZERO,
        device: 0,
    }];
    let mut pending: Vec<u8> = Vec::new();
    let mut target = 1 + (rng.next() % 24) as usize;
    let mut line_free = Duration::ZERO;
    let mut last_at = Duration::ZERO;
    let rate_hz = 80.0;
    let start_s = 0.3;
    let mut seg_start = start_s;
    let mut tick = 0u64;
    for seg in &script {
        let seg_len = seg.travel_s + seg.hold_s;
        loop {
            let t = tick as f64 / rate_hz;
            if t >= seg_start + seg_len {
                break;
            }
            tick += 1;
            let local = (t - seg_start).max(0.0);
            let station = 1 + (tick % 2) as u8;
            let (pose, stylus) = if station == 1 {
                (head, false)
            } else {
                let s = smoothstep(local / seg.travel_s);
                let mut tip = seg.from_m + (seg.to_m - seg.from_m) * s;
                if local >= seg.travel_s {
                    tip += Vec3::new(rng.unit(), rng.unit(), rng.unit()) * 0.0003;
                }
                let world_from_sensor = Pose::new(
                    tip - wand_orientation * frames.wand_tip_in_sensor_m,
                    wand_orientation,
                );
                let pressed = seg
                    .presses
                    .iter()
                    .any(|(at, len)| local >= *at && local < at + len);
                (tracker_from_world * world_from_sensor, pressed)
            };
            let rec = FastrakRecord::from_pose(station, &pose, settings.units, stylus);
            let bytes = encode_record(FastrakFormat::Ascii, &settings, &rec);
            let mut at = Duration::from_secs_f64(t).max(line_free);
            for b in bytes {
                at += byte_time;
                pending.push(b);
                if pending.len() >= target {
                    let arrive = (at + Duration::from_micros(100 + rng.next() % 900)).max(last_at);
                    last_at = arrive;
                    records.push(Record::Chunk {
                        at: arrive,
                        device: 0,
                        bytes: std::mem::take(&mut pending),
                    });
                    target = 1 + (rng.next() % 24) as usize;
                }
            }
            line_free = at;
        }
        seg_start += seg_len;
    }
    if !pending.is_empty() {
        records.push(Record::Chunk {
            at: line_free.max(last_at) + Duration::from_micros(500),
            device: 0,
            bytes: pending,
        });
    }
    let binding = |role, station| RoleBinding {
        role,
        device: "fastrak".into(),
        input: Input::Pose,
        station,
        map: AxisMaps::default(),
    };
    let device_profile = Profile {
        version: PROFILE_VERSION,
        name: "calibration-sample".into(),
        description: "Sample: FASTRAK, head on station 1, wand (stylus) on station 2, touching \
                      the four screen corners."
            .into(),
        devices: vec![DeviceSpec {
            name: "fastrak".into(),
            protocol: DeviceKind::Wire(Protocol::FastrakAscii),
            transport: TransportSpec::Serial(SerialSpec {
                path: "/dev/ttyUSB0".into(),
                baud: Some(115_200),
                ..SerialSpec::default()
            }),
            decoder: DecoderSettings { fastrak: settings },
            desktop: Default::default(),
            driver: DriverSettings::default(),
        }],
        roles: vec![binding(Role::Head, 1), binding(Role::Wand, 2)],
    };
    let mut session = Session::new(device_profile);
    session.header.recorded_by = "leman calibration sample-session generator".into();
    session.records = records;
    Some(session)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calibration::drive::run_on_session;
    use crate::calibration::procedure::{ProcedureConfig, ProcedureEvent, Step};
    use std::path::Path;

    fn root() -> &'static Path {
        Path::new(env!("CARGO_MANIFEST_DIR"))
    }

    #[test]
    fn committed_files_equal_the_generator() {
        let session = generate().expect("generate");
        let profile = desk_profile().expect("profile");
        if std::env::var_os("LEMAN_WRITE_CALIBRATION_SESSION").is_some() {
            let dir = root().join("calibration/sessions");
            std::fs::create_dir_all(&dir).expect("mkdir");
            session
                .save(&root().join(SESSION_PATH))
                .expect("write session");
            profile
                .save(&root().join(PROFILE_PATH))
                .expect("write profile");
        }
        let text = std::fs::read_to_string(root().join(SESSION_PATH)).expect("read session");
        assert!(
            text == session.to_text(),
            "{SESSION_PATH} differs: regenerate (module docs)"
        );
        let loaded = CalibrationProfile::load(&root().join(PROFILE_PATH)).expect("load profile");
        assert_eq!(
            loaded, profile,
            "{PROFILE_PATH} differs: regenerate (module docs)"
        );
    }

    #[test]
    fn replayed_session_gives_the_known_screen() {
        let session = Session::load(&root().join(SESSION_PATH)).expect("load session");
        let profile = CalibrationProfile::load(&root().join(PROFILE_PATH)).expect("profile");
        let out =
            run_on_session(session, ProcedureConfig::default(), &profile.tracker).expect("replay");
        let kinds: Vec<&ProcedureEvent> = out.events.iter().map(|(_, e)| e).collect();
        assert!(
            matches!(kinds[0], ProcedureEvent::PressIgnoredMoving { .. }),
            "{kinds:?}"
        );
        let recorded: Vec<Corner> = kinds
            .iter()
            .filter_map(|e| match e {
                ProcedureEvent::Recorded { corner, .. } => Some(*corner),
                _ => None,
            })
            .collect();
        assert_eq!(recorded, Corner::ALL.to_vec());
        assert_eq!(kinds.last(), Some(&&ProcedureEvent::Accepted));
        let Step::Done(fit) = out.procedure.step() else {
            panic!("not accepted: {:?}", out.procedure.step());
        };
        let truth = known_screen().expect("screen");
        for c in Corner::ALL {
            let e = (fit.screen.corner_m(c) - truth.corner_m(c)).length();
            assert!(e < 0.0015, "corner {c} off by {e} m");
        }
        assert!(fit.residual_m < 0.001, "{}", fit.residual_m);
    }
}
