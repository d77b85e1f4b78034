//! End-to-end device tests: fake devices on pseudo-terminal pairs and a loopback UDP socket,
//! through the real transports, drivers and hub; recording, replay, and the `devices` and
//! `record` commands. Every wait is bounded.
#![cfg(unix)]

use glam::{Quat, Vec3};
use leman::clock::RealClock;
use leman::devices::decoder::Decoder;
use leman::devices::encode;
use leman::devices::fastrak::{FastrakFormat, FastrakSettings, LengthUnit};
use leman::devices::hub::{DeviceState, Hub, HubOptions, HubSnapshot, TimedEvent};
use leman::devices::profile::{Profile, Role};
use leman::devices::replay::Replayer;
use leman::devices::sample::DeviceEvent;
use leman::devices::session::{Record, Session};
use leman::devices::spaceball::SpaceballDecoder;
use leman::devices::transport::udp::UdpTransport;
use leman::devices::transport::{FnOpener, Opener, Transport};
use leman::pose::Pose;
use serialport::{SerialPort, TTYPort};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, mpsc};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

const WAIT: Duration = Duration::from_secs(8);

fn wait_until(hub: &Hub, what: &str, cond: impl Fn(&HubSnapshot) -> bool) -> HubSnapshot {
    let start = Instant::now();
    loop {
        let snap = hub.snapshot();
        if cond(&snap) {
            return snap;
        }
        if start.elapsed() > WAIT {
            panic!("timed out waiting for {what}; last snapshot: {snap:#?}");
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

#[derive(Clone, Copy, PartialEq)]
enum Kind {
    Spaceball([i16; 6]),
    Fastrak,
}

/// A fake serial device on the master side of a pseudo-terminal: it answers the
/// initialisation commands and then streams packets, each written in fragments.
struct Fake {
    stop: Arc<AtomicBool>,
    paused: Arc<AtomicBool>,
    handle: Option<JoinHandle<()>>,
    slave_path: String,
}

impl Fake {
    fn spawn(kind: Kind) -> Fake {
        let (mut master, slave) = TTYPort::pair().expect("pseudo-terminal pair");
        let slave_path = slave.name().expect("slave name");
        master
            .set_timeout(Duration::from_millis(2))
            .expect("timeout");
        let stop = Arc::new(AtomicBool::new(false));
        let paused = Arc::new(AtomicBool::new(false));
        let (s, p) = (Arc::clone(&stop), Arc::clone(&paused));
        let handle = std::thread::spawn(move || {
            // Keep our slave end open so the master never reads EIO before the hub opens it.
            let _slave = slave;
            run_fake(kind, &mut master, &s, &p);
        });
        Fake {
            stop,
            paused,
            handle: Some(handle),
            slave_path,
        }
    }

    /// Unplugs the device: closes both ends of the pseudo-terminal.
    fn unplug(mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(h) = self.handle.take() {
            h.join().expect("fake device thread");
        }
    }
}

impl Drop for Fake {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

fn head_pose() -> Pose {
    Pose::new(Vec3::new(0.1, 0.2, 0.3), Quat::from_rotation_y(0.5))
}

fn wand_pose() -> Pose {
    Pose::new(Vec3::new(-0.2, 0.05, 0.25), Quat::from_rotation_x(0.3))
}

fn write_fragmented(port: &mut TTYPort, bytes: &[u8], tick: u64) {
    // Split at a point that moves with the tick, so packets straddle reads.
    let cut = if bytes.len() > 1 {
        1 + (tick as usize * 7) % (bytes.len() - 1)
    } else {
        bytes.len()
    };
    for (i, part) in [&bytes[..cut], &bytes[cut..]].into_iter().enumerate() {
        if part.is_empty() {
            continue;
        }
        if port.write_all(part).is_err() {
            return;
        }
        let _ = port.flush();
        if i == 0 {
            std::thread::sleep(Duration::from_micros(700));
        }
    }
}

fn run_fake(kind: Kind, master: &mut TTYPort, stop: &AtomicBool, paused: &AtomicBool) {
    let mut pending = Vec::new();
    let mut buf = [0u8; 256];
    let mut streaming = false;
    let mut fastrak = FastrakSettings::default();
    let mut format = FastrakFormat::Ascii;
    let mut stations: Vec<u8> = Vec::new();
    let mut tick = 0u64;
    let mut last_sent = Instant::now();
    while !stop.load(Ordering::SeqCst) {
        match master.read(&mut buf) {
            Ok(n) => pending.extend_from_slice(&buf[..n]),
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {}
            Err(_) => std::thread::sleep(Duration::from_millis(2)),
        }
        while let Some(end) = pending.iter().position(|&b| b == b'\r') {
            let cmd: Vec<u8> = pending.drain(..=end).collect();
            let cmd = String::from_utf8_lossy(&cmd[..cmd.len() - 1]).to_string();
            let reply: Vec<u8> = match (kind, cmd.as_str()) {
                (Kind::Spaceball(_), "@RESET") => encode::spaceball::encode_banner("2.43"),
                (Kind::Spaceball(_), "M") => {
                    streaming = true;
                    Vec::new()
                }
                (Kind::Fastrak, "c") => {
                    streaming = false;
                    Vec::new()
                }
                (Kind::Fastrak, "C") => {
                    streaming = true;
                    Vec::new()
                }
                (Kind::Fastrak, "F") => {
                    format = FastrakFormat::Ascii;
                    Vec::new()
                }
                (Kind::Fastrak, "f") => {
                    format = FastrakFormat::Binary;
                    Vec::new()
                }
                (Kind::Fastrak, "U") => {
                    fastrak.units = LengthUnit::Inches;
                    Vec::new()
                }
                (Kind::Fastrak, "u") => {
                    fastrak.units = LengthUnit::Centimetres;
                    Vec::new()
                }
                (Kind::Fastrak, "S") => encode::fastrak::encode_status_record(1, "fake FASTRAK"),
                (Kind::Fastrak, c) if c.starts_with('O') => {
                    fastrak.items = c[3..]
                        .split(',')
                        .filter_map(|s| s.trim().parse().ok())
                        .collect();
                    Vec::new()
                }
                (Kind::Fastrak, c) if c.starts_with('l') => {
                    if let Ok(st) = c[1..2].parse() {
                        stations.push(st);
                    }
                    Vec::new()
                }
                _ => Vec::new(),
            };
            if !reply.is_empty() {
                write_fragmented(master, &reply, tick);
            }
        }
        if streaming
            && !paused.load(Ordering::SeqCst)
            && last_sent.elapsed() >= Duration::from_millis(4)
        {
            last_sent = Instant::now();
            tick += 1;
            let packet = match kind {
                Kind::Spaceball(axes) => encode::spaceball::encode_d(64, axes),
                Kind::Fastrak => {
                    let st = if stations.is_empty() {
                        1
                    } else {
                        stations[tick as usize % stations.len()]
                    };
                    let pose = if st == 1 { head_pose() } else { wand_pose() };
                    let rec =
                        encode::fastrak::FastrakRecord::from_pose(st, &pose, fastrak.units, false);
                    encode::fastrak::encode_record(format, &fastrak, &rec)
                }
            };
            write_fragmented(master, &packet, tick);
        }
    }
}

fn swap_symlink(link: &Path, target: &str) {
    let tmp = link.with_extension("new");
    let _ = std::fs::remove_file(&tmp);
    std::os::unix::fs::symlink(target, &tmp).expect("symlink");
    std::fs::rename(&tmp, link).expect("swap symlink");
}

fn expected_axes(raw: [i16; 6]) -> [f32; 6] {
    let mut d = SpaceballDecoder::new();
    let mut out = Vec::new();
    d.feed(&encode::spaceball::encode_d(64, raw), &mut out);
    match out.as_slice() {
        [DeviceEvent::Axes(a)] => a.value,
        other => panic!("decoder gave {other:?}"),
    }
}

fn serial_profile(dir: &Path) -> Profile {
    let text = format!(
        r#"
version = 1
name = "pty"

[[device]]
name = "fastrak"
protocol = "fastrak-ascii"
transport = {{ kind = "serial", path = "{fastrak}" }}
driver = {{ reconnect_min_s = 0.02, reconnect_max_s = 0.1, stale_after_s = 0.25, read_timeout_s = 0.01 }}

[[device]]
name = "spaceball"
protocol = "spaceball"
transport = {{ kind = "serial", path = "{ball}" }}
driver = {{ reconnect_min_s = 0.02, reconnect_max_s = 0.1, stale_after_s = 0.25, read_timeout_s = 0.01 }}

[[role]]
role = "head"
device = "fastrak"
station = 1

[[role]]
role = "wand"
device = "fastrak"
station = 2

[[role]]
role = "navigation"
device = "spaceball"
input = "axes"
"#,
        fastrak = dir.join("fastrak").display(),
        ball = dir.join("spaceball").display(),
    );
    Profile::parse(&text, Path::new("pty.toml")).expect("profile")
}

fn per_device(events: &[TimedEvent], device: usize) -> Vec<TimedEvent> {
    events
        .iter()
        .filter(|e| e.device == device)
        .cloned()
        .collect()
}

#[test]
fn fake_spaceball_and_fastrak_on_ptys_survive_unplug_and_stall() {
    let dir = tempfile::tempdir().expect("tempdir");
    let axes_a = [1000, -2000, 3000, -400, 500, -600];
    let axes_b = [-5000, 0, 0, 0, 0, 7000];
    let fastrak = Fake::spawn(Kind::Fastrak);
    let ball = Fake::spawn(Kind::Spaceball(axes_a));
    swap_symlink(&dir.path().join("fastrak"), &fastrak.slave_path);
    swap_symlink(&dir.path().join("spaceball"), &ball.slave_path);
    let session_path = dir.path().join("live.session");
    let hub = Hub::start(
        serial_profile(dir.path()),
        Arc::new(RealClock::new()),
        HubOptions {
            record_to: Some(session_path.clone()),
        },
    )
    .expect("hub");
    let mut live_events = Vec::new();
    let t0 = Instant::now();

    // Both devices initialise (banner, status record) and stream through the hub.
    let snap = wait_until(&hub, "both devices running with data", |s| {
        s.devices
            .iter()
            .all(|d| d.state == DeviceState::Running && d.samples > 5)
            && Role::ALL.iter().all(|r| s.role(*r).at.is_some())
    });
    live_events.extend(hub.drain_events());
    eprintln!(
        "both devices initialised and streaming after {:?}",
        t0.elapsed()
    );
    let head = snap.role(Role::Head).pose.expect("head pose");
    let wand = snap.role(Role::Wand).pose.expect("wand pose");
    assert!(
        head.position_m.distance(head_pose().position_m) < 0.001,
        "{head:?}"
    );
    assert!(head.orientation.angle_between(head_pose().orientation) < 0.01);
    assert!(
        wand.position_m.distance(wand_pose().position_m) < 0.001,
        "{wand:?}"
    );
    assert!(wand.orientation.angle_between(wand_pose().orientation) < 0.01);
    assert_eq!(snap.role(Role::Navigation).axes, expected_axes(axes_a));
    assert_eq!(
        snap.devices[1].model.as_deref().map(|m| m.contains("4000")),
        Some(true)
    );
    assert_eq!(
        snap.devices[0].dropped_bytes, 0,
        "clean stream, fragmented reads"
    );

    // Unplug the Spaceball: it is reported lost, its axes read zero, the FASTRAK carries on.
    let t1 = Instant::now();
    ball.unplug();
    let snap = wait_until(&hub, "spaceball lost", |s| {
        s.devices[1].state == DeviceState::Lost
    });
    eprintln!("unplug reported lost after {:?}", t1.elapsed());
    assert_eq!(snap.role(Role::Navigation).axes, [0.0; 6]);
    assert!(snap.devices[1].last_error.is_some());
    let head_samples = snap.devices[0].samples;
    wait_until(&hub, "fastrak still streaming", |s| {
        s.devices[0].state == DeviceState::Running && s.devices[0].samples > head_samples + 10
    });
    live_events.extend(hub.drain_events());

    // Plug a Spaceball in again (a new pty behind the same path): the hub reopens it, reruns
    // the initialisation and reads the new device, without restarting anything.
    let t2 = Instant::now();
    let ball2 = Fake::spawn(Kind::Spaceball(axes_b));
    swap_symlink(&dir.path().join("spaceball"), &ball2.slave_path);
    let snap = wait_until(&hub, "spaceball back", |s| {
        s.devices[1].state == DeviceState::Running
            && s.role(Role::Navigation).axes == expected_axes(axes_b)
    });
    assert!(snap.devices[1].reconnects >= 1);
    eprintln!(
        "replugged spaceball streaming again after {:?}; rates: fastrak {} /s, spaceball {} /s",
        t2.elapsed(),
        snap.devices[0].rate_hz,
        snap.devices[1].rate_hz
    );
    live_events.extend(hub.drain_events());

    // A stalled FASTRAK (open, silent) goes stale, the head keeps its last good pose, and
    // recovers when data flows again.
    fastrak.paused.store(true, Ordering::SeqCst);
    let snap = wait_until(&hub, "fastrak stale", |s| {
        s.devices[0].state == DeviceState::Stale
    });
    assert!(snap.role(Role::Head).pose.is_some());
    fastrak.paused.store(false, Ordering::SeqCst);
    wait_until(&hub, "fastrak running again", |s| {
        s.devices[0].state == DeviceState::Running
    });
    live_events.extend(hub.drain_events());

    let path = hub.stop().expect("stop").expect("recorded");
    drop((fastrak, ball2));
    let session = Session::load(&path).expect("load the recording");
    let opened_ball = session
        .records
        .iter()
        .filter(|r| matches!(r, Record::Opened { device: 1, .. }))
        .count();
    assert!(opened_ball >= 2, "opened, lost, reopened");
    assert!(
        session
            .records
            .iter()
            .any(|r| matches!(r, Record::Lost { device: 1, .. }))
    );
    assert!(session.records.iter().any(
        |r| matches!(r, Record::Sent { device: 1, bytes, .. } if bytes.as_slice() == b"\r@RESET\r")
    ));

    // The recording replays into exactly the same events at the same times, per device.
    let mut replayer = Replayer::new(session).expect("replayer");
    replayer.run_to_end();
    let replayed = replayer.drain_events();
    for device in 0..2 {
        let live = per_device(&live_events, device);
        let again = per_device(&replayed, device);
        assert!(live.len() > 10);
        // Events after the last drain reached the file but not `live`: compare the prefix.
        assert!(again.len() >= live.len());
        assert_eq!(
            live,
            again[..live.len()],
            "device {device}: replay differs from live"
        );
    }
}

/// An opener binding a real UDP socket on 127.0.0.1 (ephemeral port) and reporting its address.
fn loopback_opener(tx: mpsc::Sender<std::net::SocketAddr>) -> Box<dyn Opener> {
    Box::new(FnOpener::new("udp loopback", move || {
        let t = UdpTransport::bind("127.0.0.1:0", Duration::from_millis(10))?;
        if let Some(a) = t.local_addr() {
            let _ = tx.send(a);
        }
        Ok(Box::new(t) as Box<dyn Transport>)
    }))
}

fn opentrack_profile(bind: &str) -> Profile {
    Profile::parse(
        &format!(
            r#"
version = 1
name = "ot"
[[device]]
name = "opentrack"
protocol = "opentrack"
transport = {{ kind = "udp", bind = "{bind}" }}
[[role]]
role = "head"
device = "opentrack"
map.z = {{ offset = 0.6 }}
"#
        ),
        Path::new("ot.toml"),
    )
    .expect("profile")
}

#[test]
fn opentrack_over_loopback_udp() {
    let (tx, rx) = mpsc::channel();
    let hub = Hub::start_with(
        opentrack_profile("127.0.0.1:0"),
        vec![Some(loopback_opener(tx))],
        Arc::new(RealClock::new()),
        HubOptions::default(),
    )
    .expect("hub");
    let addr = rx.recv_timeout(WAIT).expect("socket bound");
    let client = std::net::UdpSocket::bind("127.0.0.1:0").expect("client");
    // x, y, z in cm; yaw, pitch, roll in degrees.
    let good = encode::opentrack::datagram([10.0, -5.0, 2.0, 30.0, 0.0, 0.0]);
    let snap = {
        let start = Instant::now();
        loop {
            client.send_to(&good, addr).expect("send");
            let s = hub.snapshot();
            if s.role(Role::Head).pose.is_some() {
                break s;
            }
            assert!(start.elapsed() < WAIT, "no pose from UDP");
            std::thread::sleep(Duration::from_millis(5));
        }
    };
    let pose = snap.role(Role::Head).pose.expect("pose");
    // The profile's offset puts OpenTrack's centre 0.6 m in front of the screen.
    assert!(
        pose.position_m.distance(Vec3::new(0.10, -0.05, 0.62)) < 1e-5,
        "{pose:?}"
    );
    assert!((pose.orientation.angle_between(Quat::IDENTITY) - 30f32.to_radians()).abs() < 1e-4);

    // A short datagram and a NaN datagram are dropped loudly; the head keeps its last good pose.
    let dropped_before = snap.devices[0].dropped_bytes;
    client.send_to(&good[..20], addr).expect("send short");
    let nan = encode::opentrack::datagram([f64::NAN, 0.0, 0.0, 0.0, 0.0, 0.0]);
    client.send_to(&nan, addr).expect("send nan");
    let snap = wait_until(&hub, "both bad datagrams dropped", |s| {
        s.devices[0].dropped_bytes >= dropped_before + 20 + 48
    });
    assert_eq!(snap.role(Role::Head).pose, Some(pose));
    assert!(hub.stop().expect("stop").is_none());
}

fn leman() -> std::process::Command {
    std::process::Command::new(env!("CARGO_BIN_EXE_leman"))
}

/// `leman record` of an OpenTrack device on a free loopback port, into `dir/rec.session`, with
/// `extra` arguments; returns the child, the port and the session's path.
fn spawn_udp_recording(dir: &Path, extra: &[&str]) -> (Recorder, u16, PathBuf) {
    // Find a free loopback port for the recorder to bind.
    let port = {
        let probe = std::net::UdpSocket::bind("127.0.0.1:0").expect("probe");
        probe.local_addr().expect("addr").port()
    };
    let profile_path = dir.join("ot.toml");
    std::fs::write(
        &profile_path,
        opentrack_profile(&format!("127.0.0.1:{port}"))
            .to_toml()
            .expect("toml"),
    )
    .expect("write profile");
    let out = dir.join("rec.session");
    let child = leman()
        .args(["record", "--profile"])
        .arg(&profile_path)
        .arg("--out")
        .arg(&out)
        .args(["--status-every", "0"])
        .args(extra)
        .spawn()
        .expect("spawn leman record");
    (Recorder(child), port, out)
}

/// A running `leman record`, killed if a failing test leaves it running (it would otherwise
/// run on, listening, after the test).
struct Recorder(std::process::Child);

impl Drop for Recorder {
    fn drop(&mut self) {
        if matches!(self.0.try_wait(), Ok(None)) {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
}

/// Sends OpenTrack datagrams whose x counts up from 0 to `port`, one every `every`, for `for_`;
/// returns how many were sent.
fn send_counting_datagrams(port: u16, for_: Duration, every: Duration) -> u32 {
    let client = std::net::UdpSocket::bind("127.0.0.1:0").expect("client");
    let start = Instant::now();
    let mut sent = 0;
    while start.elapsed() < for_ {
        let d = encode::opentrack::datagram([f64::from(sent), 0.0, 0.0, 0.0, 0.0, 0.0]);
        let _ = client.send_to(&d, ("127.0.0.1", port));
        sent += 1;
        std::thread::sleep(every);
    }
    sent
}

/// Checks that a recorded session's chunks are whole datagrams, in time order, and the ones
/// sent in order (x counts up); returns how many there are.
fn assert_datagrams_in_order(session: &Session) -> usize {
    let chunks: Vec<_> = session.chunks(0).collect();
    assert!(
        chunks.iter().all(|(_, b)| b.len() == 48),
        "one datagram per chunk"
    );
    assert!(
        chunks.windows(2).all(|w| w[0].0 <= w[1].0),
        "times never decrease"
    );
    let xs: Vec<f64> = chunks.iter().map(|(_, b)| datagram_x(b)).collect();
    assert!(xs.windows(2).all(|w| w[1] > w[0]), "{xs:?}");
    chunks.len()
}

/// The x of an OpenTrack datagram ([`send_counting_datagrams`] counts in it).
fn datagram_x(bytes: &[u8]) -> f64 {
    f64::from_le_bytes(bytes[..8].try_into().expect("8 bytes"))
}

/// What a command that must fail said on standard error (it fails the test if it succeeded).
fn refusal(output: std::process::Output) -> String {
    let err = String::from_utf8_lossy(&output.stderr).into_owned();
    assert!(!output.status.success(), "succeeded: {err}");
    err
}

/// Runs `leman record --recover FROM --out OUT`.
fn record_recover(from: &Path, out: &Path) -> std::process::Output {
    leman()
        .args(["record", "--recover"])
        .arg(from)
        .arg("--out")
        .arg(out)
        .output()
        .expect("run leman record --recover")
}

#[test]
fn record_command_writes_a_session_of_live_udp_datagrams() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (mut child, port, out) = spawn_udp_recording(dir.path(), &["--seconds", "1.5"]);
    let sent =
        send_counting_datagrams(port, Duration::from_millis(1200), Duration::from_millis(10));
    let status = child.0.wait().expect("wait");
    assert!(status.success(), "leman record failed");
    let session = Session::load(&out).expect("load recorded session");
    let recorded = assert_datagrams_in_order(&session);
    assert!(recorded > 20, "{recorded} datagrams recorded of {sent}");
    let leftovers: Vec<PathBuf> = std::fs::read_dir(dir.path())
        .expect("list")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.to_string_lossy().contains("partial"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
}

#[test]
fn a_killed_recording_is_recovered_up_to_its_last_flush_even_after_a_silence() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (mut child, port, out) = spawn_udp_recording(dir.path(), &[]);
    // The recording has started (its clock too) when the partial file with its header exists.
    let partial = dir.path().join(".rec.session.partial");
    let waited = Instant::now();
    while !std::fs::metadata(&partial).is_ok_and(|m| m.len() > 0) {
        assert!(
            waited.elapsed() < Duration::from_secs(20),
            "no partial file"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    // 20 a second: 50 datagrams are about 6 KiB of session lines, less than the writer's
    // buffer holds, so only its flushes put them on disk before the kill.
    let sent =
        send_counting_datagrams(port, Duration::from_millis(2500), Duration::from_millis(50));
    let on_disk = || {
        Session::recover_file(&partial)
            .expect("the partial file is recoverable while recording")
            .session
    };
    // The recorder flushes at each second of recording, so the datagrams of the first two
    // seconds (about 40 of the 50 sent) are on disk as the last ones arrive.
    let flushed = on_disk().chunks(0).count();
    assert!(flushed >= 10, "{flushed} of {sent} datagrams on disk");
    // Then the tracker falls silent: with no record to carry a flush, the recorder's timer
    // puts the last ones on disk within about a second.
    let last_x = |s: &Session| s.chunks(0).last().map(|(_, b)| datagram_x(b));
    let waited = Instant::now();
    while last_x(&on_disk()) != Some(f64::from(sent - 1)) {
        assert!(
            waited.elapsed() < Duration::from_secs(20),
            "the last datagram never reached the file"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    // SIGKILL: no Ctrl-C handler, no `end` line, no rename.
    child.0.kill().expect("kill leman record");
    child.0.wait().expect("wait");
    assert!(!out.exists(), "a killed recording never appears whole");
    let recovered = dir.path().join("recovered.session");
    let run = record_recover(&partial, &recovered);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let session = Session::load(&recovered).expect("the recovered session loads strictly");
    assert_datagrams_in_order(&session);
    assert_eq!(
        last_x(&session),
        Some(f64::from(sent - 1)),
        "up to the last one sent"
    );
}

#[test]
fn record_recover_keeps_the_whole_records_of_a_cut_short_recording() {
    let sample = Path::new(env!("CARGO_MANIFEST_DIR")).join("devices/sessions/spaceball.session");
    let whole = Session::load(&sample).expect("sample session");
    let text = std::fs::read(&sample).expect("read sample");
    // Cut inside a record line, as a killed recording's buffered writes leave it.
    let cut = text.len() * 3 / 4;
    assert_ne!(text[cut - 1], b'\n', "the cut falls inside a line");
    let whole_lines = text[..cut].iter().filter(|&&b| b == b'\n').count();
    let kept = whole_lines - 2;
    let last_line_start = text[..cut]
        .iter()
        .rposition(|&b| b == b'\n')
        .expect("a line end")
        + 1;
    let dir = tempfile::tempdir().expect("tempdir");
    let partial = dir.path().join(".rec.session.partial");
    std::fs::write(&partial, &text[..cut]).expect("write the cut file");
    let out_path = dir.path().join("rec.session");

    // The strict reader refuses it and points at the recovery.
    let refused = leman()
        .args(["decode"])
        .arg(&partial)
        .output()
        .expect("run decode");
    assert!(!refused.status.success());
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(
        err.contains("truncated") && err.contains("--recover"),
        "{err}"
    );

    let run = record_recover(&partial, &out_path);
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(stdout.contains(&format!("kept {kept} records")), "{stdout}");
    assert!(
        stdout.contains(&format!("dropped {} bytes", cut - last_line_start)),
        "{stdout}"
    );
    let recovered = Session::load(&out_path).expect("the recovered session loads strictly");
    assert_eq!(recovered.header, whole.header);
    assert_eq!(recovered.records, whole.records[..kept]);

    // The file recovered from is never overwritten.
    let same = record_recover(&partial, &partial);
    assert!(!same.status.success());
    let err = String::from_utf8_lossy(&same.stderr);
    assert!(err.contains("name a new file"), "{err}");
    assert_eq!(std::fs::read(&partial).expect("reread"), &text[..cut]);

    // A file that cannot be read is named.
    let missing = record_recover(
        &dir.path().join("gone.partial"),
        &dir.path().join("x.session"),
    );
    assert!(!missing.status.success());
    let err = String::from_utf8_lossy(&missing.stderr);
    assert!(
        err.contains("session ") && err.contains("gone.partial"),
        "{err}"
    );
}

#[test]
fn record_command_names_the_profile_file_and_field_on_errors() {
    let dir = tempfile::tempdir().expect("tempdir");
    let bad = dir.path().join("bad.toml");
    std::fs::write(
        &bad,
        "version = 1\nname = \"x\"\n[[device]]\nname = \"d\"\nprotocol = \"desktop\"\n[[role]]\nrole = \"head\"\ndevice = \"nope\"\n",
    )
    .expect("write");
    let err = refusal(
        leman()
            .args(["record", "--profile"])
            .arg(&bad)
            .args(["--out"])
            .arg(dir.path().join("x.session"))
            .output()
            .expect("run"),
    );
    assert!(
        err.contains("bad.toml") && err.contains("role[0].device"),
        "{err}"
    );
}

#[test]
fn record_command_refuses_spans_that_are_not_seconds() {
    let dir = tempfile::tempdir().expect("tempdir");
    let profile = Path::new(env!("CARGO_MANIFEST_DIR")).join("devices/desktop.toml");
    // Each used to be taken as "no limit": the recording ran until Ctrl-C.
    let nan = "not a number of seconds";
    for (flag, value, why) in [
        ("--seconds", "-1", nan),
        ("--seconds", "nan", nan),
        ("--seconds", "inf", nan),
        ("--seconds", "ten", nan),
        ("--seconds", "1e300", "too long a span"),
        ("--status-every", "-2", nan),
    ] {
        let mut run = Recorder(
            leman()
                .args(["record", "--profile"])
                .arg(&profile)
                .arg("--out")
                .arg(dir.path().join("x.session"))
                .arg(format!("{flag}={value}"))
                .stderr(std::process::Stdio::piped())
                .spawn()
                .expect("run"),
        );
        let waited = Instant::now();
        let status = loop {
            if let Some(status) = run.0.try_wait().expect("wait") {
                break status;
            }
            // Dropping `run` kills a recorder that took the span as "no limit".
            assert!(
                waited.elapsed() < Duration::from_secs(20),
                "{flag} {value}: still recording"
            );
            std::thread::sleep(Duration::from_millis(10));
        };
        assert_eq!(status.code(), Some(2), "{flag} {value}");
        let mut err = String::new();
        std::io::Read::read_to_string(run.0.stderr.as_mut().expect("piped stderr"), &mut err)
            .expect("read stderr");
        assert!(
            err.contains(flag) && err.contains(why),
            "{flag} {value}: {err}"
        );
    }
    assert_eq!(
        std::fs::read_dir(dir.path()).expect("list").count(),
        0,
        "nothing recorded"
    );
}

/// Runs `leman record` of an OpenTrack device on a free loopback port into `out` for a moment,
/// with `extra` arguments (nothing is sent: the session holds the device's opening).
fn record_briefly(out: &Path, extra: &[&str]) -> std::process::Output {
    let profile = out.with_extension("toml");
    std::fs::write(
        &profile,
        opentrack_profile("127.0.0.1:0").to_toml().expect("toml"),
    )
    .expect("write profile");
    leman()
        .args(["record", "--profile"])
        .arg(&profile)
        .arg("--out")
        .arg(out)
        .args(["--seconds", "0.2", "--status-every", "0"])
        .args(extra)
        .output()
        .expect("run leman record")
}

#[test]
fn record_never_writes_over_a_session_or_a_partial_file_unasked() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("take.session");
    let stderr = |o: &std::process::Output| String::from_utf8_lossy(&o.stderr).into_owned();
    let first = record_briefly(&out, &[]);
    assert!(first.status.success(), "{}", stderr(&first));
    let take_one = std::fs::read(&out).expect("first take");
    let first_take = Session::load(&out).expect("the first take loads");

    // The same command again is refused before anything opens; the first take stays.
    let err = refusal(record_briefly(&out, &[]));
    assert!(
        err.contains("take.session")
            && err.contains("already exists")
            && err.contains("--overwrite"),
        "{err}"
    );
    assert_eq!(std::fs::read(&out).expect("reread"), take_one);
    // With --overwrite it is replaced by a new whole session.
    let replaced = record_briefly(&out, &["--overwrite"]);
    assert!(replaced.status.success(), "{}", stderr(&replaced));
    Session::load(&out).expect("the new take loads");

    // A cut-short recording's partial file is never started over, even with --overwrite: it
    // may be all there is of a take.
    std::fs::remove_file(&out).expect("remove the take");
    let partial = dir.path().join(".take.session.partial");
    // The take without its `end` line, as a killed recording leaves it.
    let end_line = take_one[..take_one.len() - 1]
        .iter()
        .rposition(|&b| b == b'\n')
        .expect("an end line")
        + 1;
    let cut = &take_one[..end_line];
    std::fs::write(&partial, cut).expect("write partial");
    for extra in [&[][..], &["--overwrite"][..]] {
        let err = refusal(record_briefly(&out, extra));
        assert!(
            err.contains(".take.session.partial") && err.contains("--recover"),
            "{extra:?}: {err}"
        );
        assert_eq!(std::fs::read(&partial).expect("reread"), cut);
        assert!(!out.exists());
    }
    std::fs::write(&out, &take_one).expect("put the take back");

    // Recovering into an existing file is refused too, and done with --overwrite.
    let err = refusal(record_recover(&partial, &out));
    assert!(err.contains("already exists"), "{err}");
    let recovered = leman()
        .args(["record", "--overwrite", "--recover"])
        .arg(&partial)
        .arg("--out")
        .arg(&out)
        .output()
        .expect("run leman record --recover");
    assert!(recovered.status.success(), "{}", stderr(&recovered));
    let kept = Session::load(&out).expect("the recovered take loads");
    assert_eq!(kept.header, first_take.header);
    assert_eq!(kept.records, first_take.records);
}

#[test]
fn record_refuses_a_profile_of_only_the_desktop_stand_ins() {
    let dir = tempfile::tempdir().expect("tempdir");
    let profile = Path::new(env!("CARGO_MANIFEST_DIR")).join("devices/desktop.toml");
    let record = |profile: &Path, out: &str| {
        leman()
            .args(["record", "--profile"])
            .arg(profile)
            .arg("--out")
            .arg(dir.path().join(out))
            .args(["--seconds", "0.2"])
            .output()
            .expect("run leman record")
    };
    let err = refusal(record(&profile, "d.session"));
    assert!(
        err.contains("desktop.toml") && err.contains("opens no window"),
        "{err}"
    );
    assert_eq!(
        std::fs::read_dir(dir.path()).expect("list").count(),
        0,
        "nothing written"
    );
    // A profile without devices is refused as such.
    let empty = dir.path().join("empty.toml");
    std::fs::write(&empty, "version = 1\nname = \"empty\"\n").expect("write");
    let err = refusal(record(&empty, "e.session"));
    assert!(
        err.contains("empty.toml") && err.contains("no devices"),
        "{err}"
    );
    assert!(!dir.path().join("e.session").exists());
}

#[test]
fn devices_command_lists_as_json() {
    let out = leman().args(["devices", "--json"]).output().expect("run");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json");
    assert!(
        v["serial"].is_array() && v["hid"].is_array() && v["notes"].is_array(),
        "{v}"
    );
    let text = leman().arg("devices").output().expect("run");
    assert!(String::from_utf8_lossy(&text.stdout).contains("Serial ports:"));
}
