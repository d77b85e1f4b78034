//! Replaying a recorded session through the same decoders and [`HubState`] as live devices,
//! deterministically: [`Replayer::advance_to`] applies every record up to a time, with the
//! recorded arrival times and the original chunk boundaries, so the samples and their times are
//! exactly those seen while recording. [`ClockedReplay`] drives a replayer from a [`Clock`]
//! (usually a [`crate::clock::VirtualClock`]) behind the same [`DeviceSource`] interface the
//! live [`crate::devices::hub::Hub`] offers. For a threaded replay through real readers, use
//! [`crate::devices::transport::replay::ReplayTransport`] with `Hub::start_with`.

use crate::clock::Clock;
use crate::devices::decoder::Decoder;
use crate::devices::desktop::DesktopEvent;
use crate::devices::hub::{Hub, HubSnapshot, HubState, TimedEvent};
use crate::devices::profile::DeviceKind;
use crate::devices::protocol::decoder_with_settings;
use crate::devices::sample::DeviceEvent;
use crate::devices::session::{Record, Session};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// What the frame loop needs from a device source, live or replayed.
pub trait DeviceSource: Send + Sync {
    /// Every role's newest sample and every device's status, now.
    fn snapshot(&self) -> HubSnapshot;
    /// Every device event since the last call, in arrival order.
    fn drain_events(&self) -> Vec<TimedEvent>;
    /// A window event for the desktop stand-ins (ignored by replays, which play the recorded
    /// ones). Returns whether it was used.
    fn feed_desktop(&self, event: DesktopEvent) -> bool;
}

impl DeviceSource for Hub {
    fn snapshot(&self) -> HubSnapshot {
        Hub::snapshot(self)
    }
    fn drain_events(&self) -> Vec<TimedEvent> {
        Hub::drain_events(self)
    }
    fn feed_desktop(&self, event: DesktopEvent) -> bool {
        Hub::feed_desktop(self, event)
    }
}

/// A session's decoder settings are unusable.
#[derive(Debug, thiserror::Error)]
#[error("session device {device}: {message}")]
pub struct ReplayError {
    /// The device's name.
    pub device: String,
    /// What is wrong.
    pub message: String,
}

/// Plays a session's records into a [`HubState`].
pub struct Replayer {
    session: Session,
    next: usize,
    state: HubState,
    decoders: Vec<Option<Box<dyn Decoder>>>,
    scratch: Vec<DeviceEvent>,
}

impl std::fmt::Debug for Replayer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Replayer")
            .field("next", &self.next)
            .field("records", &self.session.records.len())
            .finish()
    }
}

impl Replayer {
    /// A replayer at the start of `session`.
    pub fn new(session: Session) -> Result<Self, ReplayError> {
        let profile = session.header.profile.clone();
        let mut decoders = Vec::new();
        for d in &profile.devices {
            decoders.push(match d.protocol {
                DeviceKind::Wire(p) => {
                    Some(
                        decoder_with_settings(p, &d.decoder).map_err(|e| ReplayError {
                            device: d.name.clone(),
                            message: e.to_string(),
                        })?,
                    )
                }
                DeviceKind::Desktop => None,
            });
        }
        Ok(Self {
            state: HubState::new(profile),
            session,
            next: 0,
            decoders,
            scratch: Vec::new(),
        })
    }

    /// The session being played.
    pub fn session(&self) -> &Session {
        &self.session
    }

    /// True when every record has been applied.
    pub fn finished(&self) -> bool {
        self.next >= self.session.records.len()
    }

    /// Time of the next record to apply, if any.
    pub fn next_time(&self) -> Option<Duration> {
        self.session.records.get(self.next).map(Record::at)
    }

    /// Applies the next record; returns it, or `None` at the end.
    pub fn step(&mut self) -> Option<&Record> {
        let record = self.session.records.get(self.next)?;
        self.next += 1;
        match record {
            Record::Chunk { at, device, bytes } => {
                self.scratch.clear();
                if let Some(Some(decoder)) = self.decoders.get_mut(*device) {
                    decoder.feed(bytes, &mut self.scratch);
                }
                self.state.chunk(*device, *at, bytes.len(), &self.scratch);
            }
            Record::Opened { at, device } => {
                if let Some(Some(decoder)) = self.decoders.get_mut(*device) {
                    decoder.reset();
                }
                self.state.opened(*device, *at);
                if matches!(
                    self.state
                        .profile()
                        .devices
                        .get(*device)
                        .map(|d| d.protocol),
                    Some(DeviceKind::Wire(_))
                ) {
                    // Live, a device runs once its initialisation is done; a replay has no
                    // such moment, so it counts as running from its opening.
                    self.state.running(*device, *at);
                }
            }
            Record::Lost { at, device, error } => self.state.lost(*device, *at, error),
            Record::Desktop { at, event } => {
                self.state.desktop_event(*at, event);
            }
            Record::Sent { .. } => {}
        }
        Some(record)
    }

    /// Applies every record up to and including time `t`.
    pub fn advance_to(&mut self, t: Duration) {
        while self.next_time().is_some_and(|at| at <= t) {
            self.step();
        }
    }

    /// Applies every remaining record.
    pub fn run_to_end(&mut self) {
        while self.step().is_some() {}
    }

    /// Roles and device statuses as of `now`.
    pub fn snapshot(&mut self, now: Duration) -> HubSnapshot {
        self.state.snapshot(now)
    }

    /// Events delivered since the last call.
    pub fn drain_events(&mut self) -> Vec<TimedEvent> {
        self.state.drain_events()
    }
}

/// A replay that follows a clock: each snapshot first applies every record up to the clock's
/// now. With a [`crate::clock::VirtualClock`] advanced by the frame loop, a replay is
/// bit-for-bit repeatable.
pub struct ClockedReplay {
    replayer: Mutex<Replayer>,
    clock: Arc<dyn Clock>,
}

impl ClockedReplay {
    /// Plays `session` on `clock` (time zero of the clock = time zero of the recording).
    pub fn new(session: Session, clock: Arc<dyn Clock>) -> Result<Self, ReplayError> {
        Ok(Self {
            replayer: Mutex::new(Replayer::new(session)?),
            clock,
        })
    }

    /// True when the whole session has been played.
    pub fn finished(&self) -> bool {
        self.lock().finished()
    }

    /// The recording's length (time of its last record).
    pub fn duration(&self) -> Duration {
        self.lock().session().duration()
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Replayer> {
        self.replayer
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }
}

impl DeviceSource for ClockedReplay {
    fn snapshot(&self) -> HubSnapshot {
        let now = self.clock.now();
        let mut r = self.lock();
        r.advance_to(now);
        r.snapshot(now)
    }

    fn drain_events(&self) -> Vec<TimedEvent> {
        let now = self.clock.now();
        let mut r = self.lock();
        r.advance_to(now);
        r.drain_events()
    }

    fn feed_desktop(&self, _event: DesktopEvent) -> bool {
        false
    }
}
