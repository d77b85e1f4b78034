//! The device hub: one reader thread per device, off the render thread. Each reader opens its
//! device, runs the driver's initialisation, then reads chunks, stamps each at arrival on the
//! hub's [`Clock`], decodes it and publishes the newest sample of each role (head, wand,
//! navigation) with the device's state. The frame loop only ever takes a [`HubSnapshot`] (a
//! short lock and a copy; it never waits for a device).
//!
//! When a device errors or is unplugged the reader reports it [`DeviceState::Lost`], drops the
//! connection and reopens it with a doubling backoff (profile `driver.reconnect_min_s` ..
//! `reconnect_max_s`), rerunning the initialisation; the other devices and the last good values
//! carry on. A running device that sends nothing for `driver.stale_after_s` is reported
//! [`DeviceState::Stale`].
//!
//! The same [`HubState`] is driven by [`crate::devices::replay::Replayer`] from a recorded
//! session, so live and replayed samples go through exactly the same code.

use crate::clock::Clock;
use crate::devices::decoder::Decoder;
use crate::devices::desktop::{DesktopDevice, DesktopEvent};
use crate::devices::driver::{self, DriverError, InitSettings, Link};
use crate::devices::profile::{DeviceKind, Input, Profile, Role, RoleBinding, TransportSpec};
use crate::devices::protocol::decoder_with_settings;
use crate::devices::sample::{DeviceEvent, StatusEvent};
use crate::devices::session::{Record, SessionError, SessionHeader, SessionWriter};
use crate::devices::transport::hid::HidOpener;
use crate::devices::transport::serial::SerialOpener;
use crate::devices::transport::udp::UdpOpener;
use crate::devices::transport::{Opener, Transport};
use crate::pose::Pose;
use serde::Serialize;
use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::Duration;

/// How a device is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum DeviceState {
    /// Being opened or initialised.
    Opening,
    /// Delivering data.
    Running,
    /// Open, but nothing arrived for longer than its `stale_after_s`.
    Stale,
    /// Failed or unplugged; being reopened.
    Lost,
    /// The hub stopped.
    Stopped,
}

/// One device's state and counters.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DeviceStatus {
    /// Name from the profile.
    pub name: String,
    /// `desktop` or the protocol name.
    pub protocol: String,
    /// What it is connected through.
    pub transport: String,
    /// Current state.
    pub state: DeviceState,
    /// Arrival time of the newest chunk (hub clock).
    pub last_data_at: Option<Duration>,
    /// Samples (poses and axes) per second over the last second.
    pub rate_hz: f64,
    /// Chunks read.
    pub chunks: u64,
    /// Bytes read.
    pub bytes: u64,
    /// Samples decoded.
    pub samples: u64,
    /// Bytes the decoder dropped while resynchronising.
    pub dropped_bytes: u64,
    /// How many times it was opened after the first time.
    pub reconnects: u64,
    /// The last error (cleared when it runs again).
    pub last_error: Option<String>,
    /// Model the device identified itself as.
    pub model: Option<String>,
    #[serde(skip)]
    opened_at: Option<Duration>,
    #[serde(skip)]
    opened_count: u64,
    #[serde(skip)]
    sample_times: VecDeque<Duration>,
    #[serde(skip)]
    stale_after: Duration,
}

/// The newest state of one role.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RoleSample {
    /// The role.
    pub role: Role,
    /// Index of the device bound to it (into the profile's devices), if any.
    pub device: Option<usize>,
    /// Newest pose, after the profile's axis maps (pose roles).
    pub pose: Option<Pose>,
    /// Newest six axes after the maps (axes roles); zero until data arrives, and zero while
    /// the device is lost (so a lost controller does not keep flying the vehicle). With a
    /// desktop device in the profile, the navigation keys' axes are added to a working
    /// controller's (see `stand_in` for one that is not working).
    pub axes: [f32; 6],
    /// Buttons held (0-based); empty while the device is lost.
    pub pressed: Vec<u8>,
    /// Arrival time of the newest sample (hub clock).
    pub at: Option<Duration>,
    /// State of the bound device ([`DeviceState::Lost`] when nothing is bound).
    pub state: DeviceState,
    /// Whether this is the desktop stand-in's sample (then `device` is the desktop device and
    /// `state` its state): the wand and navigation roles fall back to the mouse and keyboard
    /// while the device bound to them is lost or still opening, or when none is bound, if the
    /// profile has a desktop device. The head does not: a lost head tracker's last pose is
    /// kept, and with none the view is from the calibrated position.
    pub stand_in: bool,
}

impl RoleSample {
    fn empty(role: Role) -> Self {
        Self {
            role,
            device: None,
            pose: None,
            axes: [0.0; 6],
            pressed: Vec::new(),
            at: None,
            state: DeviceState::Lost,
            stand_in: false,
        }
    }

    /// Takes `event` from a device bound to this role by `binding`, arrived at `at`.
    fn offer(&mut self, binding: &RoleBinding, event: &DeviceEvent, at: Duration) {
        match (event, binding.input) {
            (DeviceEvent::Pose(p), Input::Pose) if p.station == binding.station => {
                if let Some(pose) = binding.map.apply_pose(&p.pose) {
                    self.pose = Some(pose);
                    self.pressed.clone_from(&p.pressed);
                    self.at = Some(at);
                }
            }
            (DeviceEvent::Axes(a), Input::Axes) => {
                self.axes = binding.map.apply_axes(a.value);
                self.at = Some(at);
            }
            (DeviceEvent::Buttons { pressed }, Input::Axes) => {
                self.pressed.clone_from(pressed);
                self.at = Some(at);
            }
            _ => {}
        }
    }

    /// Adds the desktop stand-in's axes (the navigation keys) to this axes role's own, so the
    /// keys fly beside a working controller (a SpaceMouse that is found is taken up by default,
    /// and its user should not lose the keys for it). Nothing changes while no key is held; the
    /// sum goes on to the vehicle, which clamps each axis to [-1, 1].
    fn add_desktop_axes(&mut self, desktop: &RoleSample) {
        if desktop.axes.iter().all(|a| *a == 0.0) {
            return;
        }
        for (own, key) in self.axes.iter_mut().zip(desktop.axes) {
            *own += key;
        }
        self.at = self.at.max(desktop.at);
    }
}

/// The desktop device's samples for every role as the default desktop profile binds them
/// (whatever the profile binds), for [`RoleSample::stand_in`]; kept only when the profile has a
/// desktop device and some role that takes a stand-in is bound elsewhere or not at all.
struct StandIns {
    /// Index of the profile's desktop device.
    device: usize,
    /// The stand-in for each role, in [`Role::ALL`] order.
    roles: [RoleSample; 3],
    /// [`Profile::desktop_default`]'s bindings.
    bindings: Vec<RoleBinding>,
}

/// Whether a role falls back to the desktop stand-in while its own device cannot serve it.
fn takes_stand_in(role: Role) -> bool {
    role != Role::Head
}

/// What the frame loop reads: every role's newest sample and every device's status.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct HubSnapshot {
    /// The hub clock's time when the snapshot was taken.
    pub now: Duration,
    /// Head, wand, navigation, in [`Role::ALL`] order.
    pub roles: [RoleSample; 3],
    /// One entry per profile device.
    pub devices: Vec<DeviceStatus>,
}

impl HubSnapshot {
    /// The newest sample of `role`.
    pub fn role(&self, role: Role) -> &RoleSample {
        &self.roles[role.index()]
    }

    /// Whether `role`'s sample comes from the desktop stand-ins (bound to the desktop device, or
    /// standing in for a missing one): poses already in the physical (screen) frame, exact, and
    /// with no 3D position of a hand behind them.
    pub fn from_desktop(&self, role: Role) -> bool {
        let sample = self.role(role);
        sample.stand_in
            || sample
                .device
                .and_then(|d| self.devices.get(d))
                .is_some_and(|d| d.protocol == "desktop")
    }
}

/// A device event with its arrival time and device, as delivered (before the role maps).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TimedEvent {
    /// Arrival time of the chunk (or desktop event) that completed it.
    pub at: Duration,
    /// Index into the profile's devices.
    pub device: usize,
    /// The event.
    pub event: DeviceEvent,
}

/// Events kept for [`HubState::drain_events`] at most; older ones are dropped.
pub const EVENT_QUEUE_LEN: usize = 8192;

/// The hub's data: role samples, device statuses, the desktop stand-in and the event queue.
/// Pure (no clock, threads or I/O): live readers and replays feed it timed chunks.
pub struct HubState {
    profile: Profile,
    roles: [RoleSample; 3],
    devices: Vec<DeviceStatus>,
    bindings: Vec<Vec<RoleBinding>>,
    desktop: Option<(usize, DesktopDevice)>,
    stand_ins: Option<StandIns>,
    events: VecDeque<TimedEvent>,
}

impl HubState {
    /// Fresh state for `profile` (every device [`DeviceState::Opening`]).
    pub fn new(profile: Profile) -> Self {
        let devices = profile
            .devices
            .iter()
            .map(|d| DeviceStatus {
                name: d.name.clone(),
                protocol: String::from(d.protocol),
                transport: describe_transport(&d.transport),
                state: DeviceState::Opening,
                last_data_at: None,
                rate_hz: 0.0,
                chunks: 0,
                bytes: 0,
                samples: 0,
                dropped_bytes: 0,
                reconnects: 0,
                last_error: None,
                model: None,
                opened_at: None,
                opened_count: 0,
                sample_times: VecDeque::new(),
                stale_after: Duration::from_secs_f64(d.driver.stale_after_s),
            })
            .collect();
        let bindings = (0..profile.devices.len())
            .map(|i| {
                profile
                    .roles
                    .iter()
                    .filter(|b| profile.device_index(&b.device) == Some(i))
                    .cloned()
                    .collect()
            })
            .collect();
        let mut roles = Role::ALL.map(RoleSample::empty);
        for b in &profile.roles {
            roles[b.role.index()].device = profile.device_index(&b.device);
        }
        let desktop = profile
            .devices
            .iter()
            .position(|d| d.protocol == DeviceKind::Desktop)
            .map(|i| (i, DesktopDevice::new(profile.devices[i].desktop.clone())));
        // Only when some role that takes a stand-in is not the desktop's own (with every such
        // role bound to the desktop, as in the desktop default, its events would be mapped
        // twice for samples nobody reads).
        let stand_ins = desktop
            .as_ref()
            .filter(|(device, _)| {
                Role::ALL
                    .iter()
                    .any(|&r| takes_stand_in(r) && roles[r.index()].device != Some(*device))
            })
            .map(|(device, _)| StandIns {
                device: *device,
                roles: Role::ALL.map(|role| RoleSample {
                    device: Some(*device),
                    stand_in: true,
                    ..RoleSample::empty(role)
                }),
                bindings: Profile::desktop_default().roles,
            });
        Self {
            profile,
            roles,
            devices,
            bindings,
            desktop,
            stand_ins,
            events: VecDeque::new(),
        }
    }

    /// The profile.
    pub fn profile(&self) -> &Profile {
        &self.profile
    }

    /// The device was (re)opened at `at`. For the desktop device this also publishes its
    /// initial samples.
    pub fn opened(&mut self, device: usize, at: Duration) {
        let mut initial = Vec::new();
        if let Some((d, desk)) = &self.desktop
            && *d == device
        {
            desk.current(&mut initial);
        }
        if let Some(s) = self.devices.get_mut(device) {
            if s.opened_count > 0 {
                s.reconnects += 1;
            }
            s.opened_count += 1;
            s.opened_at = Some(at);
            s.state = if initial.is_empty() {
                DeviceState::Opening
            } else {
                DeviceState::Running
            };
        }
        if !initial.is_empty() {
            self.apply(device, at, &initial);
        }
    }

    /// Initialisation finished: the device is running.
    pub fn running(&mut self, device: usize, at: Duration) {
        if let Some(s) = self.devices.get_mut(device) {
            s.state = DeviceState::Running;
            s.last_error = None;
            s.opened_at = Some(at);
        }
    }

    /// The device failed at `at`.
    pub fn lost(&mut self, device: usize, _at: Duration, error: &str) {
        if let Some(s) = self.devices.get_mut(device) {
            s.state = DeviceState::Lost;
            s.last_error = Some(error.to_string());
        }
    }

    /// The hub stopped.
    pub fn stopped(&mut self) {
        for s in &mut self.devices {
            s.state = DeviceState::Stopped;
        }
    }

    /// A chunk of `bytes` from `device` arrived at `at` and decoded to `events`.
    pub fn chunk(&mut self, device: usize, at: Duration, bytes: usize, events: &[DeviceEvent]) {
        if let Some(s) = self.devices.get_mut(device) {
            s.chunks += 1;
            s.bytes += bytes as u64;
            s.last_data_at = Some(at);
            if s.state == DeviceState::Stale {
                s.state = DeviceState::Running;
            }
        }
        self.apply(device, at, events);
    }

    /// A desktop event arrived at `at`; returns false when the profile has no desktop device.
    pub fn desktop_event(&mut self, at: Duration, event: &DesktopEvent) -> bool {
        let Some((device, desk)) = &mut self.desktop else {
            return false;
        };
        let device = *device;
        let mut out = Vec::new();
        desk.feed(event, &mut out);
        if let Some(s) = self.devices.get_mut(device) {
            s.last_data_at = Some(at);
        }
        self.apply(device, at, &out);
        true
    }

    fn apply(&mut self, device: usize, at: Duration, events: &[DeviceEvent]) {
        let Some(status) = self.devices.get_mut(device) else {
            return;
        };
        for event in events {
            match event {
                DeviceEvent::Pose(_) | DeviceEvent::Axes(_) => {
                    status.samples += 1;
                    status.sample_times.push_back(at);
                }
                DeviceEvent::Dropped { bytes } => status.dropped_bytes += *bytes as u64,
                DeviceEvent::Status(StatusEvent::Identified { model, .. }) => {
                    status.model = Some(model.clone());
                }
                DeviceEvent::Status(StatusEvent::Report { .. }) | DeviceEvent::Buttons { .. } => {}
            }
            for b in self.bindings.get(device).into_iter().flatten() {
                self.roles[b.role.index()].offer(b, event, at);
            }
            if let Some(stand_ins) = self.stand_ins.as_mut().filter(|s| s.device == device) {
                for b in &stand_ins.bindings {
                    stand_ins.roles[b.role.index()].offer(b, event, at);
                }
            }
            if self.events.len() >= EVENT_QUEUE_LEN {
                self.events.pop_front();
            }
            self.events.push_back(TimedEvent {
                at,
                device,
                event: event.clone(),
            });
        }
        trim_rate_window(status, at);
    }

    /// Takes every event delivered since the last call (at most [`EVENT_QUEUE_LEN`]).
    pub fn drain_events(&mut self) -> Vec<TimedEvent> {
        self.events.drain(..).collect()
    }

    /// The roles and device statuses as of `now` (stale detection and rates use `now`).
    pub fn snapshot(&mut self, now: Duration) -> HubSnapshot {
        for s in &mut self.devices {
            trim_rate_window(s, now);
            s.rate_hz = s.sample_times.len() as f64;
            if s.state == DeviceState::Running {
                let since = s.last_data_at.max(s.opened_at).unwrap_or(Duration::ZERO);
                if now.saturating_sub(since) > s.stale_after {
                    s.state = DeviceState::Stale;
                }
            }
        }
        let mut roles = self.roles.clone();
        for r in &mut roles {
            r.state = r
                .device
                .and_then(|d| self.devices.get(d))
                .map_or(DeviceState::Lost, |s| s.state);
            let axes_role = self
                .profile
                .binding(r.role)
                .is_some_and(|b| b.input == Input::Axes);
            if matches!(r.state, DeviceState::Lost | DeviceState::Stopped) {
                r.pressed.clear();
                if axes_role {
                    r.axes = [0.0; 6];
                }
            }
            if let Some(stand_ins) = &self.stand_ins
                && takes_stand_in(r.role)
                && r.device != Some(stand_ins.device)
            {
                let desktop = &stand_ins.roles[r.role.index()];
                if matches!(r.state, DeviceState::Lost | DeviceState::Opening) {
                    let desktop_state = self
                        .devices
                        .get(stand_ins.device)
                        .map_or(DeviceState::Lost, |s| s.state);
                    *r = RoleSample {
                        state: desktop_state,
                        ..desktop.clone()
                    };
                } else if axes_role {
                    r.add_desktop_axes(desktop);
                }
            }
        }
        HubSnapshot {
            now,
            roles,
            devices: self.devices.clone(),
        }
    }
}

fn trim_rate_window(s: &mut DeviceStatus, now: Duration) {
    while s
        .sample_times
        .front()
        .is_some_and(|t| now.saturating_sub(*t) >= Duration::from_secs(1))
    {
        s.sample_times.pop_front();
    }
}

/// A short description of a transport spec.
pub fn describe_transport(t: &TransportSpec) -> String {
    match t {
        TransportSpec::None => "window".into(),
        TransportSpec::Serial(s) => format!("serial {}", s.path),
        TransportSpec::Hid(h) => crate::devices::transport::hid::describe_spec(h),
        TransportSpec::Udp(u) => format!("udp {}", u.bind),
    }
}

/// Why a hub could not start or stop cleanly.
#[derive(Debug, thiserror::Error)]
pub enum HubError {
    /// A device's decoder settings are unusable.
    #[error("device {device}: {message}")]
    Device {
        /// The device's name.
        device: String,
        /// What is wrong.
        message: String,
    },
    /// The session file could not be written.
    #[error(transparent)]
    Session(#[from] SessionError),
    /// A reader thread could not be started.
    #[error("cannot start a reader thread: {0}")]
    Thread(std::io::Error),
}

/// Where a device's bytes come from: an opener per wire device (the desktop device has none).
pub type Openers = Vec<Option<Box<dyn Opener>>>;

/// The openers a profile describes (serial, HID, UDP), one per device; `None` for desktop.
pub fn openers_for(profile: &Profile) -> Openers {
    profile
        .devices
        .iter()
        .map(|d| -> Option<Box<dyn Opener>> {
            let read_timeout = Duration::from_secs_f64(d.driver.read_timeout_s);
            match (&d.protocol, &d.transport) {
                (DeviceKind::Wire(p), TransportSpec::Serial(s)) => Some(Box::new(SerialOpener {
                    path: s.path.clone(),
                    line: crate::devices::profile::SerialLine::resolve(*p, s),
                    read_timeout,
                })),
                (DeviceKind::Wire(_), TransportSpec::Hid(h)) => Some(Box::new(HidOpener {
                    spec: h.clone(),
                    read_timeout,
                })),
                (DeviceKind::Wire(_), TransportSpec::Udp(u)) => Some(Box::new(UdpOpener {
                    bind: u.bind.clone(),
                    read_timeout,
                })),
                _ => None,
            }
        })
        .collect()
}

struct Shared {
    clock: Arc<dyn Clock>,
    state: Mutex<HubState>,
    recorder: Mutex<Option<SessionWriter>>,
    record_error: Mutex<Option<String>>,
    stop: AtomicBool,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

impl Shared {
    /// Stamps a record's time on the clock (or uses a replay's recorded time) and writes it to
    /// the session being recorded, under one lock so the file's times never decrease.
    fn stamp(&self, recorded: Option<Duration>, make: impl FnOnce(Duration) -> Record) -> Duration {
        let mut rec = lock(&self.recorder);
        let at = recorded.unwrap_or_else(|| self.clock.now());
        if let Some(w) = rec.as_mut()
            && let Err(e) = w.write(&make(at))
        {
            self.recording_failed(&e);
        }
        at
    }

    /// Puts the recording's buffered records on disk if they are
    /// [`FLUSH_EVERY`](crate::devices::session::FLUSH_EVERY) old on the clock (see
    /// [`SessionWriter::flush_if_due`]).
    fn flush_recording(&self) {
        let mut rec = lock(&self.recorder);
        if let Some(w) = rec.as_mut()
            && let Err(e) = w.flush_if_due(self.clock.now())
        {
            self.recording_failed(&e);
        }
    }

    /// Keeps the first recording error for [`Hub::record_error`].
    fn recording_failed(&self, e: &SessionError) {
        let mut err = lock(&self.record_error);
        if err.is_none() {
            tracing::error!("recording failed: {e}");
            *err = Some(e.to_string());
        }
    }
}

/// How often a recording hub's flusher looks at the recording's buffer (real time).
const FLUSH_TICK: Duration = Duration::from_millis(50);

/// The recording hub's flusher: without it, records that came just before every device fell
/// silent would wait in the writer's buffer for the next record, and a recording killed then
/// would lose them however old they were.
fn run_flusher(shared: &Shared) {
    while !shared.stop.load(Ordering::SeqCst) {
        std::thread::park_timeout(FLUSH_TICK);
        shared.flush_recording();
    }
}

/// Options of a live hub.
#[derive(Debug, Clone, Default)]
pub struct HubOptions {
    /// Record every chunk, write and desktop event into this session file (streamed to a
    /// temporary file, renamed into place by [`Hub::stop`]).
    pub record_to: Option<PathBuf>,
}

/// The live device hub. Dropping it stops the readers (without finishing a recording: call
/// [`Hub::stop`] for that).
pub struct Hub {
    shared: Arc<Shared>,
    threads: Vec<JoinHandle<()>>,
    /// The recording's flusher (see [`FLUSH_EVERY`](crate::devices::session::FLUSH_EVERY)),
    /// when recording.
    flusher: Option<JoinHandle<()>>,
}

impl std::fmt::Debug for Hub {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Hub")
            .field("threads", &self.threads.len())
            .finish()
    }
}

impl Hub {
    /// Starts a hub for `profile`, opening its devices through their transports.
    pub fn start(
        profile: Profile,
        clock: Arc<dyn Clock>,
        options: HubOptions,
    ) -> Result<Self, HubError> {
        let openers = openers_for(&profile);
        Self::start_with(profile, openers, clock, options)
    }

    /// The default hub: the desktop stand-ins only, on the real clock.
    pub fn desktop() -> Result<Self, HubError> {
        Self::start(
            Profile::desktop_default(),
            Arc::new(crate::clock::RealClock::new()),
            HubOptions::default(),
        )
    }

    /// Starts a hub with explicit openers (one per profile device; tests and replays use their
    /// own). A wire device without an opener stays [`DeviceState::Lost`].
    pub fn start_with(
        profile: Profile,
        mut openers: Openers,
        clock: Arc<dyn Clock>,
        options: HubOptions,
    ) -> Result<Self, HubError> {
        let mut decoders = Vec::new();
        for d in &profile.devices {
            decoders.push(match d.protocol {
                DeviceKind::Wire(p) => {
                    Some(
                        decoder_with_settings(p, &d.decoder).map_err(|e| HubError::Device {
                            device: d.name.clone(),
                            message: e.to_string(),
                        })?,
                    )
                }
                DeviceKind::Desktop => None,
            });
        }
        let recorder = match &options.record_to {
            Some(path) => Some(SessionWriter::create(
                path,
                &SessionHeader::new(profile.clone()),
            )?),
            None => None,
        };
        let shared = Arc::new(Shared {
            clock,
            state: Mutex::new(HubState::new(profile.clone())),
            recorder: Mutex::new(recorder),
            record_error: Mutex::new(None),
            stop: AtomicBool::new(false),
        });
        // Built before any thread starts: if one cannot be started, dropping the hub stops
        // those that did.
        let mut hub = Self {
            shared: Arc::clone(&shared),
            threads: Vec::new(),
            flusher: None,
        };
        openers.resize_with(profile.devices.len(), || None);
        for (index, (decoder, opener)) in decoders.into_iter().zip(openers).enumerate() {
            let spec = &profile.devices[index];
            match (spec.protocol, decoder, opener) {
                (DeviceKind::Desktop, _, _) => {
                    let at = shared.stamp(None, |at| Record::Opened { at, device: index });
                    lock(&shared.state).opened(index, at);
                }
                (DeviceKind::Wire(protocol), Some(decoder), Some(opener)) => {
                    let stations = profile
                        .roles
                        .iter()
                        .filter(|b| b.device == spec.name && b.input == Input::Pose)
                        .map(|b| b.station)
                        .collect();
                    let reader = Reader {
                        shared: Arc::clone(&shared),
                        index,
                        name: spec.name.clone(),
                        protocol,
                        init: InitSettings {
                            decoder: spec.decoder.clone(),
                            stations,
                            timeout: Duration::from_secs_f64(spec.driver.init_timeout_s),
                        },
                        reconnect_min: Duration::from_secs_f64(spec.driver.reconnect_min_s),
                        reconnect_max: Duration::from_secs_f64(spec.driver.reconnect_max_s),
                        decoder,
                        opener,
                    };
                    let handle = std::thread::Builder::new()
                        .name(format!("leman-device-{}", spec.name))
                        .spawn(move || reader.run())
                        .map_err(HubError::Thread)?;
                    hub.threads.push(handle);
                }
                (DeviceKind::Wire(_), _, _) => {
                    let at = shared.clock.now();
                    lock(&shared.state).lost(index, at, "no transport to open it with");
                }
            }
        }
        if options.record_to.is_some() {
            let handle = std::thread::Builder::new()
                .name("leman-recording-flush".into())
                .spawn(move || run_flusher(&shared))
                .map_err(HubError::Thread)?;
            hub.flusher = Some(handle);
        }
        Ok(hub)
    }

    /// Every role's newest sample and every device's status, now. Never blocks on a device.
    pub fn snapshot(&self) -> HubSnapshot {
        let now = self.shared.clock.now();
        lock(&self.shared.state).snapshot(now)
    }

    /// The newest sample of one role.
    pub fn newest(&self, role: Role) -> RoleSample {
        let snap = self.snapshot();
        snap.roles[role.index()].clone()
    }

    /// Every device event since the last call, in arrival order (button edges a frame loop
    /// would otherwise miss between two snapshots).
    pub fn drain_events(&self) -> Vec<TimedEvent> {
        lock(&self.shared.state).drain_events()
    }

    /// Hands a window event to the desktop stand-ins: stamped now, recorded, applied at once.
    /// Ignored (returns false) when the profile has no desktop device.
    pub fn feed_desktop(&self, event: DesktopEvent) -> bool {
        let has_desktop = lock(&self.shared.state).desktop.is_some();
        if !has_desktop {
            return false;
        }
        let at = self.shared.stamp(None, |at| Record::Desktop {
            at,
            event: event.clone(),
        });
        lock(&self.shared.state).desktop_event(at, &event)
    }

    /// The first recording error, if writing the session failed.
    pub fn record_error(&self) -> Option<String> {
        lock(&self.shared.record_error).clone()
    }

    /// Stops the readers, waits for them, and finishes the recording (renaming it into place);
    /// returns the session path if one was recorded.
    pub fn stop(mut self) -> Result<Option<PathBuf>, HubError> {
        self.halt();
        let writer = lock(&self.shared.recorder).take();
        match writer {
            Some(w) => Ok(Some(w.finish()?)),
            None => Ok(None),
        }
    }

    fn halt(&mut self) {
        self.shared.stop.store(true, Ordering::SeqCst);
        if let Some(f) = self.flusher.take() {
            f.thread().unpark();
            let _ = f.join();
        }
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
        lock(&self.shared.state).stopped();
    }
}

impl Drop for Hub {
    fn drop(&mut self) {
        self.halt();
    }
}

struct Reader {
    shared: Arc<Shared>,
    index: usize,
    /// The device's name in the profile, for the log.
    name: String,
    protocol: crate::devices::protocol::Protocol,
    init: InitSettings,
    reconnect_min: Duration,
    reconnect_max: Duration,
    decoder: Box<dyn Decoder>,
    opener: Box<dyn Opener>,
}

impl Reader {
    fn stopping(&self) -> bool {
        self.shared.stop.load(Ordering::SeqCst)
    }

    /// Sleeps up to `d` in real time, waking early when the hub stops.
    fn pause(&self, d: Duration) {
        let step = Duration::from_millis(10);
        let mut left = d;
        while !left.is_zero() && !self.stopping() {
            let s = left.min(step);
            std::thread::sleep(s);
            left = left.saturating_sub(s);
        }
    }

    /// Reports a failure. A failure to open that repeats the previous one is neither logged
    /// nor recorded again; after the device was opened, a failure is always recorded (so a
    /// replay sees the state change), but logged only when its message is new.
    fn lose(&self, error: &str, last_error: &mut Option<String>, was_opened: bool) {
        let index = self.index;
        let repeated = last_error.as_deref() == Some(error);
        if !repeated {
            tracing::warn!("device {index} ({}): {error}", self.name);
            *last_error = Some(error.to_string());
        }
        if !repeated || was_opened {
            let at = self.shared.stamp(None, |at| Record::Lost {
                at,
                device: index,
                error: error.to_string(),
            });
            lock(&self.shared.state).lost(index, at, error);
        }
    }

    fn handle_chunk(
        shared: &Shared,
        decoder: &mut dyn Decoder,
        index: usize,
        bytes: &[u8],
        recorded: Option<Duration>,
        events: &mut Vec<DeviceEvent>,
    ) {
        let at = shared.stamp(recorded, |at| Record::Chunk {
            at,
            device: index,
            bytes: bytes.to_vec(),
        });
        events.clear();
        decoder.feed(bytes, events);
        lock(&shared.state).chunk(index, at, bytes.len(), events);
    }

    fn run(mut self) {
        let mut backoff = self.reconnect_min;
        let mut last_error: Option<String> = None;
        let mut events = Vec::new();
        let mut buf = vec![0u8; 4096];
        while !self.stopping() {
            let mut transport = match self.opener.open() {
                Ok(t) => t,
                Err(e) => {
                    self.lose(&e.to_string(), &mut last_error, false);
                    self.pause(backoff);
                    backoff = (backoff * 2).min(self.reconnect_max);
                    continue;
                }
            };
            let index = self.index;
            let at = self
                .shared
                .stamp(None, |at| Record::Opened { at, device: index });
            lock(&self.shared.state).opened(index, at);
            self.decoder.reset();
            match self.initialise(transport.as_mut(), &mut events) {
                Ok(()) => {}
                Err(DriverError::Stopped) => break,
                Err(e) => {
                    self.lose(&e.to_string(), &mut last_error, true);
                    drop(transport);
                    self.pause(backoff);
                    backoff = (backoff * 2).min(self.reconnect_max);
                    continue;
                }
            }
            let at = self.shared.clock.now();
            lock(&self.shared.state).running(index, at);
            last_error = None;
            backoff = self.reconnect_min;
            while !self.stopping() {
                match transport.read(&mut buf) {
                    Ok(0) => {}
                    Ok(n) => Self::handle_chunk(
                        &self.shared,
                        self.decoder.as_mut(),
                        index,
                        &buf[..n],
                        transport.recorded_arrival(),
                        &mut events,
                    ),
                    Err(e) => {
                        self.lose(&e.to_string(), &mut last_error, true);
                        break;
                    }
                }
            }
            drop(transport);
            if !self.stopping() {
                self.pause(backoff);
            }
        }
    }

    fn initialise(
        &mut self,
        transport: &mut dyn Transport,
        events: &mut Vec<DeviceEvent>,
    ) -> Result<(), DriverError> {
        let shared = Arc::clone(&self.shared);
        let index = self.index;
        let decoder = self.decoder.as_mut();
        // Replays hold no replies to commands: skip initialisation for them.
        if !transport.needs_init() {
            return Ok(());
        }
        let mut on_read = |bytes: &[u8]| {
            Self::handle_chunk(&shared, decoder, index, bytes, None, events);
        };
        let shared2 = Arc::clone(&self.shared);
        let mut on_sent = |bytes: &[u8]| {
            shared2.stamp(None, |at| Record::Sent {
                at,
                device: index,
                bytes: bytes.to_vec(),
            });
        };
        let clock = Arc::clone(&self.shared.clock);
        let mut link = Link::new(
            transport,
            clock.as_ref(),
            &self.shared.stop,
            &mut on_read,
            &mut on_sent,
        );
        driver::initialise(self.protocol, &self.init, &mut link)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::clock::VirtualClock;
    use crate::devices::desktop::DesktopEvent;
    use crate::devices::replay::{ClockedReplay, DeviceSource, Replayer};
    use crate::devices::sample_sessions::sample_sessions;
    use crate::devices::session::Session;
    use crate::devices::transport::FnOpener;
    use crate::devices::transport::replay::{Pacing, ReplayTransport};

    fn sample(stem: &str) -> Session {
        sample_sessions()
            .into_iter()
            .find(|(s, _)| s == stem)
            .map(|(_, s)| s)
            .expect("sample session")
    }

    fn wait_for(hub: &Hub, cond: impl Fn(&HubSnapshot) -> bool) -> HubSnapshot {
        let start = std::time::Instant::now();
        loop {
            let s = hub.snapshot();
            if cond(&s) {
                return s;
            }
            assert!(
                start.elapsed() < Duration::from_secs(10),
                "timed out: {s:#?}"
            );
            std::thread::sleep(Duration::from_millis(2));
        }
    }

    #[test]
    fn threaded_replay_rerecords_the_same_chunks_times_and_samples() {
        for stem in ["spaceball", "fastrak-binary", "spacemouse-hid"] {
            let original = sample(stem);
            let dir = tempfile::tempdir().expect("tempdir");
            let out = dir.path().join("again.session");
            let replay = original.clone();
            let opener: Box<dyn Opener> = Box::new(FnOpener::new("replay", move || {
                Ok(Box::new(ReplayTransport::new(
                    &replay,
                    0,
                    Pacing::AsFastAsPossible,
                    Duration::from_millis(5),
                )) as Box<dyn Transport>)
            }));
            let mut profile = original.header.profile.clone();
            // One pass only: after the session ends, do not reopen for a long time.
            profile.devices[0].driver.reconnect_min_s = 1000.0;
            profile.devices[0].driver.reconnect_max_s = 1000.0;
            let hub = Hub::start_with(
                profile,
                vec![Some(opener)],
                Arc::new(VirtualClock::new()),
                HubOptions {
                    record_to: Some(out.clone()),
                },
            )
            .expect("hub");
            wait_for(&hub, |s| s.devices[0].state == DeviceState::Lost);
            let live = hub.drain_events();
            hub.stop().expect("stop");
            let again = Session::load(&out).expect("load");
            let chunks = |s: &Session| -> Vec<(Duration, Vec<u8>)> {
                s.chunks(0).map(|(t, b)| (t, b.to_vec())).collect()
            };
            assert_eq!(chunks(&again), chunks(&original), "{stem}: chunks differ");
            let mut r = Replayer::new(original).expect("replayer");
            r.run_to_end();
            assert_eq!(live, r.drain_events(), "{stem}: samples differ");
        }
    }

    /// A hub of the desktop default on `clock`, recording to `out`.
    fn recording_desktop_hub(out: &std::path::Path, clock: &VirtualClock) -> Hub {
        Hub::start(
            Profile::desktop_default(),
            Arc::new(clock.clone()),
            HubOptions {
                record_to: Some(out.to_path_buf()),
            },
        )
        .expect("hub")
    }

    #[test]
    fn desktop_events_are_recorded_on_the_clock_and_replay_identically() {
        let dir = tempfile::tempdir().expect("tempdir");
        let out = dir.path().join("desk.session");
        let clock = VirtualClock::new();
        let hub = recording_desktop_hub(&out, &clock);
        let start = hub.snapshot();
        assert_eq!(start.devices[0].state, DeviceState::Running);
        assert!(
            start.role(Role::Head).pose.is_some(),
            "head stand-in from the start"
        );
        let script = [
            (10, DesktopEvent::MouseMove { x: 0.75, y: 0.25 }),
            (
                20,
                DesktopEvent::MouseButton {
                    button: 0,
                    pressed: true,
                },
            ),
            (
                35,
                DesktopEvent::Key {
                    name: "W".into(),
                    pressed: true,
                },
            ),
            (50, DesktopEvent::Wheel { delta_lines: 1.0 }),
        ];
        for (ms, e) in &script {
            clock.set(Duration::from_millis(*ms));
            assert!(hub.feed_desktop(e.clone()));
        }
        clock.set(Duration::from_millis(60));
        let live = hub.snapshot();
        let wand = live.role(Role::Wand);
        assert_eq!(wand.pressed, vec![0]);
        assert_eq!(wand.at, Some(Duration::from_millis(50)));
        assert_eq!(live.role(Role::Navigation).axes[2], -1.0);
        hub.stop().expect("stop");

        let session = Session::load(&out).expect("load");
        let desktop_times: Vec<Duration> = session
            .records
            .iter()
            .filter_map(|r| match r {
                Record::Desktop { at, .. } => Some(*at),
                _ => None,
            })
            .collect();
        assert_eq!(
            desktop_times,
            [10, 20, 35, 50].map(Duration::from_millis).to_vec()
        );
        // Replayed on a virtual clock: the same roles at the same times.
        let replay_clock = VirtualClock::new();
        let replay = ClockedReplay::new(session, Arc::new(replay_clock.clone())).expect("replay");
        replay_clock.set(Duration::from_millis(30));
        let mid = replay.snapshot();
        assert_eq!(mid.role(Role::Wand).pressed, vec![0]);
        assert_eq!(
            mid.role(Role::Navigation).axes,
            [0.0; 6],
            "W not pressed yet"
        );
        replay_clock.set(Duration::from_millis(60));
        let end = replay.snapshot();
        assert_eq!(
            end.roles,
            live.roles.clone().map(|mut r| {
                r.state = DeviceState::Running;
                r
            })
        );
        assert!(
            !replay.feed_desktop(DesktopEvent::FocusLost),
            "replays ignore live input"
        );
    }

    #[test]
    fn a_recording_puts_its_records_on_disk_when_the_devices_fall_silent() {
        let dir = tempfile::tempdir().expect("tempdir");
        let out = dir.path().join("quiet.session");
        let partial = dir.path().join(".quiet.session.partial");
        let clock = VirtualClock::new();
        let hub = recording_desktop_hub(&out, &clock);
        let desktop_records = || {
            crate::devices::session::records_on_disk(&partial)
                .iter()
                .filter(|r| matches!(r, Record::Desktop { .. }))
                .count()
        };
        clock.set(Duration::from_millis(100));
        assert!(hub.feed_desktop(DesktopEvent::MouseMove { x: 0.5, y: 0.5 }));
        clock.set(Duration::from_millis(200));
        assert!(hub.feed_desktop(DesktopEvent::Wheel { delta_lines: 1.0 }));
        // Then nothing more comes. Under a second of recording, the events wait in the buffer
        // (the flusher looks every FLUSH_TICK of real time).
        std::thread::sleep(FLUSH_TICK * 4);
        assert_eq!(desktop_records(), 0, "not due yet");
        // A second after the start on the recording's clock, with no record to carry it, the
        // flusher puts them on disk.
        clock.set(Duration::from_millis(1100));
        let waited = std::time::Instant::now();
        while desktop_records() < 2 {
            assert!(
                waited.elapsed() < Duration::from_secs(10),
                "the silent recording's events never reached the file"
            );
            std::thread::sleep(Duration::from_millis(5));
        }
        hub.stop().expect("stop");
        assert!(!partial.exists());
        assert_eq!(Session::load(&out).expect("load").records.len(), 3);
    }

    /// The desktop default with a tracker (device 1) on the head (station 2) and the wand
    /// (station 1), and a SpaceMouse (device 2) flying.
    fn tracked_profile() -> Profile {
        let mut p = Profile::desktop_default();
        let mut tracker = p.devices[0].clone();
        tracker.name = "tracker".into();
        tracker.protocol = DeviceKind::Wire(crate::devices::protocol::Protocol::Opentrack);
        tracker.transport = TransportSpec::Udp(Default::default());
        let mut mouse = tracker.clone();
        mouse.name = "mouse3d".into();
        mouse.protocol = DeviceKind::Wire(crate::devices::protocol::Protocol::SpacemouseHid);
        mouse.transport = TransportSpec::Hid(Default::default());
        p.devices.extend([tracker, mouse]);
        for b in &mut p.roles {
            (b.device, b.station) = match b.role {
                Role::Head => ("tracker".into(), 2),
                Role::Wand => ("tracker".into(), 1),
                Role::Navigation => ("mouse3d".into(), 1),
            };
        }
        p.validate(std::path::Path::new("tracked")).expect("valid");
        p
    }

    fn pose_at(station: u8, x: f32) -> DeviceEvent {
        DeviceEvent::Pose(crate::devices::sample::PoseSample {
            station,
            pose: Pose::new(glam::Vec3::new(x, 0.0, 0.0), glam::Quat::IDENTITY),
            raw_position: [f64::from(x), 0.0, 0.0],
            raw_orientation: crate::devices::sample::RawOrientation::EulerDeg([0.0; 3]),
            pressed: Vec::new(),
            status: None,
        })
    }

    #[test]
    fn the_mouse_and_keyboard_stand_in_for_a_missing_wand_and_navigation() {
        let ms = Duration::from_millis;
        let mut state = HubState::new(tracked_profile());
        state.opened(0, ms(0));
        // Nothing of the tracker or the SpaceMouse yet: both still opening.
        state.desktop_event(ms(10), &DesktopEvent::MouseMove { x: 0.75, y: 0.5 });
        state.desktop_event(
            ms(20),
            &DesktopEvent::Key {
                name: "W".into(),
                pressed: true,
            },
        );
        let snap = state.snapshot(ms(30));
        let (wand, nav, head) = (
            snap.role(Role::Wand),
            snap.role(Role::Navigation),
            snap.role(Role::Head),
        );
        assert!(wand.stand_in && nav.stand_in, "{snap:#?}");
        assert_eq!((wand.device, nav.device), (Some(0), Some(0)));
        assert_eq!(wand.state, DeviceState::Running, "the desktop's state");
        let mouse_wand = wand.pose.expect("the mouse's wand pose");
        assert!(mouse_wand.position_m.x > 0.0, "cursor right of centre");
        assert_eq!(nav.axes[2], -1.0, "W flies forward");
        assert!(
            !head.stand_in && head.pose.is_none(),
            "the head does not fall back"
        );
        // The devices come up: their own samples take over.
        for d in [1, 2] {
            state.opened(d, ms(40));
            state.running(d, ms(40));
        }
        let axes = DeviceEvent::Axes(crate::devices::sample::AxesSample {
            raw: [0; 6],
            value: [0.0, 0.0, 0.0, 0.0, 0.5, 0.0],
        });
        state.chunk(1, ms(50), 48, &[pose_at(1, -0.2), pose_at(2, 0.1)]);
        state.chunk(2, ms(50), 13, &[axes]);
        let snap = state.snapshot(ms(60));
        let (wand, nav, head) = (
            snap.role(Role::Wand),
            snap.role(Role::Navigation),
            snap.role(Role::Head),
        );
        assert!(!wand.stand_in && !nav.stand_in && !head.stand_in);
        assert_eq!((wand.device, nav.device), (Some(1), Some(2)));
        assert_eq!(wand.pose.expect("tracked wand").position_m.x, -0.2);
        assert_eq!(
            nav.axes,
            [0.0, 0.0, -1.0, 0.0, 0.5, 0.0],
            "the SpaceMouse's turn, and W still held flies beside it"
        );
        assert_eq!(nav.at, Some(ms(50)));
        // W let go: the SpaceMouse's alone.
        state.desktop_event(
            ms(70),
            &DesktopEvent::Key {
                name: "W".into(),
                pressed: false,
            },
        );
        let nav = state.snapshot(ms(75)).roles[Role::Navigation.index()].clone();
        assert!(!nav.stand_in);
        assert_eq!(nav.axes, [0.0, 0.0, 0.0, 0.0, 0.5, 0.0]);
        // A key alone while the SpaceMouse rests (it sends nothing then) still flies, from the
        // key's time.
        let rest = DeviceEvent::Axes(crate::devices::sample::AxesSample {
            raw: [0; 6],
            value: [0.0; 6],
        });
        state.chunk(2, ms(74), 13, &[rest]);
        state.desktop_event(
            ms(76),
            &DesktopEvent::Key {
                name: "S".into(),
                pressed: true,
            },
        );
        let nav = state.snapshot(ms(77)).roles[Role::Navigation.index()].clone();
        assert_eq!(nav.axes, [0.0, 0.0, 1.0, 0.0, 0.0, 0.0], "S backs off");
        assert_eq!(nav.at, Some(ms(76)));
        state.desktop_event(
            ms(78),
            &DesktopEvent::Key {
                name: "S".into(),
                pressed: false,
            },
        );
        // Both unplugged: the stand-ins again, with what the mouse and keyboard did meanwhile.
        state.lost(1, ms(80), "unplugged");
        state.lost(2, ms(80), "unplugged");
        let snap = state.snapshot(ms(90));
        let (wand, nav, head) = (
            snap.role(Role::Wand),
            snap.role(Role::Navigation),
            snap.role(Role::Head),
        );
        assert!(wand.stand_in && nav.stand_in);
        assert_eq!(wand.pose, Some(mouse_wand));
        assert_eq!(nav.axes, [0.0; 6], "W was let go");
        assert!(!head.stand_in);
        assert_eq!(head.state, DeviceState::Lost);
        assert_eq!(
            head.pose.expect("the head's last pose").position_m.x,
            0.1,
            "a lost head tracker's last pose is kept"
        );
    }

    #[test]
    fn stand_ins_are_kept_only_for_roles_the_desktop_does_not_serve() {
        assert!(
            HubState::new(Profile::desktop_default())
                .stand_ins
                .is_none()
        );
        assert!(HubState::new(tracked_profile()).stand_ins.is_some());
        assert!(
            HubState::new(crate::devices::found::default_profile())
                .stand_ins
                .is_some()
        );
    }

    #[test]
    fn without_a_desktop_device_nothing_stands_in() {
        let mut p = tracked_profile();
        p.devices.remove(0);
        let mut state = HubState::new(p);
        let snap = state.snapshot(Duration::ZERO);
        for r in &snap.roles {
            assert!(!r.stand_in, "{r:?}");
            assert!(r.device.is_some(), "{r:?}");
            assert_eq!(r.state, DeviceState::Opening, "its own device's state");
        }
    }

    #[test]
    fn stale_and_rate_follow_the_clock() {
        let session = sample("opentrack");
        let mut state = HubState::new(session.header.profile.clone());
        state.opened(0, Duration::ZERO);
        state.running(0, Duration::ZERO);
        let mut decoder =
            crate::devices::protocol::decoder_for(crate::devices::protocol::Protocol::Opentrack);
        let mut events = Vec::new();
        for (i, (_, bytes)) in session.chunks(0).take(30).enumerate() {
            events.clear();
            decoder.feed(bytes, &mut events);
            // 30 datagrams 10 ms apart.
            state.chunk(
                0,
                Duration::from_millis(10 * i as u64),
                bytes.len(),
                &events,
            );
        }
        let snap = state.snapshot(Duration::from_millis(300));
        assert_eq!(snap.devices[0].state, DeviceState::Running);
        assert_eq!(snap.devices[0].rate_hz, 30.0);
        let snap = state.snapshot(Duration::from_millis(800));
        assert_eq!(
            snap.devices[0].state,
            DeviceState::Stale,
            "0.5 s without data"
        );
        assert!(snap.role(Role::Head).pose.is_some(), "last good pose kept");
        let snap = state.snapshot(Duration::from_millis(1200));
        // Only the samples of the last second count: those after 0.2 s (210..=290 ms).
        assert_eq!(snap.devices[0].rate_hz, 9.0);
        state.chunk(0, Duration::from_millis(1250), 48, &events);
        assert_eq!(
            state.snapshot(Duration::from_millis(1250)).devices[0].state,
            DeviceState::Running
        );
        state.lost(0, Duration::from_secs(2), "unplugged");
        let snap = state.snapshot(Duration::from_secs(2));
        assert_eq!(snap.role(Role::Head).state, DeviceState::Lost);
        assert!(
            snap.role(Role::Head).pose.is_some(),
            "head pose survives a loss"
        );
    }

    /// A device that opens fine and sends the same bytes every millisecond: none (it never
    /// answers), or a report (a SpaceMouse held off its centre).
    struct Repeating(Vec<u8>);

    impl Transport for Repeating {
        fn read(
            &mut self,
            buf: &mut [u8],
        ) -> Result<usize, crate::devices::transport::TransportError> {
            std::thread::sleep(Duration::from_millis(1));
            buf[..self.0.len()].copy_from_slice(&self.0);
            Ok(self.0.len())
        }
        fn write(
            &mut self,
            _bytes: &[u8],
        ) -> Result<(), crate::devices::transport::TransportError> {
            Ok(())
        }
        fn describe(&self) -> String {
            "repeating".into()
        }
    }

    #[test]
    fn the_default_profile_takes_up_a_spacemouse_plugged_in_after_start() {
        let mut profile = crate::devices::found::default_profile();
        let spacemouse = profile
            .device_index(crate::devices::found::SPACEMOUSE_DEVICE)
            .expect("a SpaceMouse entry");
        let driver = &mut profile.devices[spacemouse].driver;
        (driver.reconnect_min_s, driver.reconnect_max_s) = (0.005, 0.02);
        let plugged = Arc::new(AtomicBool::new(false));
        let tries = Arc::new(std::sync::atomic::AtomicUsize::new(0));
        let opener: Box<dyn Opener> = Box::new(FnOpener::new("spacemouse", {
            let (plugged, tries) = (Arc::clone(&plugged), Arc::clone(&tries));
            move || {
                tries.fetch_add(1, Ordering::SeqCst);
                if !plugged.load(Ordering::SeqCst) {
                    return Err(crate::devices::transport::TransportError::Open {
                        what: "hid any:any".into(),
                        message: "no such HID device is plugged in".into(),
                    });
                }
                let report =
                    crate::devices::encode::spacemouse_hid::combined_report([0, 0, 0, 0, 300, 0]);
                Ok(Box::new(Repeating(report)) as Box<dyn Transport>)
            }
        }));
        let mut openers: Openers = profile.devices.iter().map(|_| None).collect();
        openers[spacemouse] = Some(opener);
        let hub = Hub::start_with(
            profile,
            openers,
            Arc::new(crate::clock::RealClock::new()),
            HubOptions::default(),
        )
        .expect("hub");
        let key = |pressed| DesktopEvent::Key {
            name: "W".into(),
            pressed,
        };
        hub.feed_desktop(key(true));
        let w = [0.0, 0.0, -1.0, 0.0, 0.0, 0.0];
        // Not plugged in: lost (and tried again and again), and the keys fly in its place.
        let snap = wait_for(&hub, |s| {
            s.devices[spacemouse].state == DeviceState::Lost
                && tries.load(Ordering::SeqCst) >= 3
                && s.role(Role::Navigation).axes == w
        });
        assert!(snap.role(Role::Navigation).stand_in);
        assert!(
            snap.devices[spacemouse]
                .last_error
                .as_deref()
                .is_some_and(|e| e.contains("no such HID device is plugged in")),
            "{snap:#?}"
        );
        // Plugged in: opened at the next try, its axes fly with W's added.
        plugged.store(true, Ordering::SeqCst);
        let snap = wait_for(&hub, |s| {
            s.devices[spacemouse].state == DeviceState::Running
                && s.role(Role::Navigation).axes != w
        });
        let with_w = snap.role(Role::Navigation).axes;
        assert!(!snap.role(Role::Navigation).stand_in);
        hub.feed_desktop(key(false));
        let snap = wait_for(&hub, |s| s.role(Role::Navigation).axes[2] != -1.0);
        let own = snap.role(Role::Navigation).axes;
        assert_ne!(own, [0.0; 6], "the held cap turns the view");
        for k in 0..6 {
            assert_eq!(with_w[k], own[k] + w[k], "axis {k}: {with_w:?} {own:?}");
        }
        hub.stop().expect("stop");
    }

    #[test]
    fn a_device_that_never_answers_is_lost_on_every_attempt_and_recorded_so() {
        let dir = tempfile::tempdir().expect("tempdir");
        let out = dir.path().join("silent.session");
        let mut profile = sample("spaceball").header.profile;
        profile.devices[0].driver.init_timeout_s = 0.02;
        profile.devices[0].driver.reconnect_min_s = 0.005;
        profile.devices[0].driver.reconnect_max_s = 0.01;
        let opener: Box<dyn Opener> = Box::new(FnOpener::new("silent", || {
            Ok(Box::new(Repeating(Vec::new())) as Box<dyn Transport>)
        }));
        let hub = Hub::start_with(
            profile,
            vec![Some(opener)],
            Arc::new(crate::clock::RealClock::new()),
            HubOptions {
                record_to: Some(out.clone()),
            },
        )
        .expect("hub");
        let snap = wait_for(&hub, |s| {
            s.devices[0].reconnects >= 3 && s.devices[0].state == DeviceState::Lost
        });
        assert!(
            snap.devices[0]
                .last_error
                .as_deref()
                .is_some_and(|e| e.contains("@1")),
            "{snap:#?}"
        );
        hub.stop().expect("stop");
        let session = Session::load(&out).expect("load");
        let count = |f: fn(&Record) -> bool| session.records.iter().filter(|r| f(r)).count();
        let opened = count(|r| matches!(r, Record::Opened { .. }));
        let lost = count(|r| matches!(r, Record::Lost { .. }));
        assert!(opened >= 4, "{opened}");
        // Every opening that timed out is followed by a loss (the last may be cut by stop).
        assert!(lost + 1 >= opened, "{lost} losses for {opened} openings");
        let end = session.duration();
        let mut r = Replayer::new(session).expect("replay");
        r.run_to_end();
        assert_eq!(r.snapshot(end).devices[0].reconnects as usize, opened - 1);
    }

    #[test]
    fn a_wire_device_without_transport_is_lost_and_desktop_input_needs_a_desktop() {
        let session = sample("spaceball");
        let hub = Hub::start_with(
            session.header.profile.clone(),
            vec![None],
            Arc::new(VirtualClock::new()),
            HubOptions::default(),
        )
        .expect("hub");
        let snap = hub.snapshot();
        assert_eq!(snap.devices[0].state, DeviceState::Lost);
        assert!(!hub.feed_desktop(DesktopEvent::FocusLost));
        assert_eq!(
            hub.newest(Role::Head).state,
            DeviceState::Lost,
            "unbound role"
        );
    }
}
