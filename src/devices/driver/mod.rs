//! Device drivers: what each device must be told after it is opened, and the replies awaited
//! (PROTOCOLS.md). A driver talks through a [`Link`], which hands every byte read during
//! initialisation to the hub (so it is recorded and decoded like any other chunk) and reports
//! every byte written. Waits are measured on the hub's [`Clock`].
//!
//! | protocol | initialisation |
//! | --- | --- |
//! | Spaceball | `\r@RESET\r`; wait for `@1` (init timeout, 2 s by default) and the `@2` firmware line (at most 0.5 s more); `\rCB\rMSSV\rk\r`, then `M\r` (automatic data) |
//! | FASTRAK | `c\r` (stop streaming), drain 0.2 s; `F\r`/`f\r` (format), `U\r`/`u\r` (inches/cm), per station `l<st>,1\r` and `O<st>,<items>\r`; `S\r` and wait for the status record; `C\r` (continuous) |
//! | Magellan | `vQ\r` and wait for the `v...MAGELLAN` reply; `z\r` (rezero), `m3\r` (3D mode) |
//! | Logitech | `*R` (reset), wait 0.2 s; `*` 0x05 (diagnostics) and wait for 2 bytes starting with bit 7 set; `*S` (stream) |
//! | SpaceMouse HID | output report 4 = 1 (LED on); failures are ignored (not every model has an LED) |
//! | OpenTrack | nothing (it only sends) |

pub mod fastrak;
pub mod logitech;
pub mod magellan;
pub mod spaceball;

use crate::clock::Clock;
use crate::devices::protocol::{DecoderSettings, Protocol};
use crate::devices::transport::{Transport, TransportError};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

/// Why initialisation failed.
#[derive(Debug, thiserror::Error)]
pub enum DriverError {
    /// The transport failed.
    #[error(transparent)]
    Transport(#[from] TransportError),
    /// The device did not answer in time.
    #[error("{device}: no {waited_for} within {timeout_s:.1} s")]
    Timeout {
        /// The device.
        device: String,
        /// What was awaited.
        waited_for: String,
        /// How long we waited (seconds).
        timeout_s: f64,
    },
    /// The hub is stopping.
    #[error("stopped")]
    Stopped,
}

/// What a driver needs to know beyond the protocol.
#[derive(Debug, Clone)]
pub struct InitSettings {
    /// What the device is to be configured to send.
    pub decoder: DecoderSettings,
    /// Tracker stations to switch on (FASTRAK); empty means station 1.
    pub stations: Vec<u8>,
    /// How long to wait for each awaited reply.
    pub timeout: Duration,
}

/// A freshly opened transport during initialisation.
pub struct Link<'a> {
    transport: &'a mut dyn Transport,
    clock: &'a dyn Clock,
    stop: &'a AtomicBool,
    on_read: &'a mut dyn FnMut(&[u8]),
    on_sent: &'a mut dyn FnMut(&[u8]),
    buf: Vec<u8>,
    /// Everything read since the link was made.
    pub received: Vec<u8>,
}

impl<'a> Link<'a> {
    /// Wraps `transport`; `on_read` sees every chunk read and `on_sent` every write.
    pub fn new(
        transport: &'a mut dyn Transport,
        clock: &'a dyn Clock,
        stop: &'a AtomicBool,
        on_read: &'a mut dyn FnMut(&[u8]),
        on_sent: &'a mut dyn FnMut(&[u8]),
    ) -> Self {
        Self {
            transport,
            clock,
            stop,
            on_read,
            on_sent,
            buf: vec![0; 4096],
            received: Vec::new(),
        }
    }

    /// Writes `bytes` to the device.
    pub fn send(&mut self, bytes: &[u8]) -> Result<(), DriverError> {
        (self.on_sent)(bytes);
        self.transport.write(bytes)?;
        Ok(())
    }

    /// Reads one chunk (waiting at most the transport's read timeout); returns its length.
    fn read_once(&mut self) -> Result<usize, DriverError> {
        if self.stop.load(Ordering::Relaxed) {
            return Err(DriverError::Stopped);
        }
        let n = self.transport.read(&mut self.buf)?;
        if n > 0 {
            let chunk = &self.buf[..n];
            (self.on_read)(chunk);
            self.received.extend_from_slice(chunk);
        }
        Ok(n)
    }

    /// Reads until `found(received)` holds, or fails after `timeout` on the clock.
    pub fn wait_for(
        &mut self,
        waited_for: &str,
        timeout: Duration,
        found: impl Fn(&[u8]) -> bool,
    ) -> Result<(), DriverError> {
        let start = self.clock.now();
        loop {
            if found(&self.received) {
                return Ok(());
            }
            if self.clock.now().saturating_sub(start) >= timeout {
                return Err(DriverError::Timeout {
                    device: self.transport.describe(),
                    waited_for: waited_for.to_string(),
                    timeout_s: timeout.as_secs_f64(),
                });
            }
            self.read_once()?;
        }
    }

    /// Reads (and passes on) whatever arrives for `duration` on the clock.
    pub fn drain(&mut self, duration: Duration) -> Result<(), DriverError> {
        let start = self.clock.now();
        while self.clock.now().saturating_sub(start) < duration {
            self.read_once()?;
        }
        Ok(())
    }

    /// Forgets what was received so far (before awaiting a new reply).
    pub fn clear_received(&mut self) {
        self.received.clear();
    }
}

/// True when `hay` contains `needle`.
pub(crate) fn contains(hay: &[u8], needle: &[u8]) -> bool {
    !needle.is_empty() && hay.windows(needle.len()).any(|w| w == needle)
}

/// Runs `protocol`'s initialisation over `link`.
pub fn initialise(
    protocol: Protocol,
    settings: &InitSettings,
    link: &mut Link<'_>,
) -> Result<(), DriverError> {
    match protocol {
        Protocol::Spaceball => spaceball::initialise(settings, link),
        Protocol::FastrakAscii | Protocol::FastrakBinary => {
            fastrak::initialise(protocol, settings, link)
        }
        Protocol::Magellan => magellan::initialise(settings, link),
        Protocol::Logitech => logitech::initialise(settings, link),
        Protocol::SpacemouseHid => {
            // LED on. Some models have no LED report: not an error.
            let _ = link.send(&[4, 1]);
            Ok(())
        }
        Protocol::Opentrack => Ok(()),
    }
}

#[cfg(test)]
pub(crate) mod test_support {
    use super::*;
    use crate::clock::VirtualClock;
    use std::collections::VecDeque;

    /// A scripted device: answers writes with canned replies; every read advances the virtual
    /// clock by `tick`.
    pub struct Scripted {
        pub clock: VirtualClock,
        pub tick: Duration,
        pub written: Vec<u8>,
        pub pending: VecDeque<Vec<u8>>,
        pub replies: Vec<(Vec<u8>, Vec<u8>)>,
    }

    impl Scripted {
        pub fn clock_now(&self) -> Duration {
            self.clock.now()
        }
    }

    impl Transport for Scripted {
        fn read(&mut self, buf: &mut [u8]) -> Result<usize, TransportError> {
            self.clock.advance(self.tick);
            match self.pending.pop_front() {
                Some(chunk) => {
                    let n = chunk.len().min(buf.len());
                    buf[..n].copy_from_slice(&chunk[..n]);
                    Ok(n)
                }
                None => Ok(0),
            }
        }

        fn write(&mut self, bytes: &[u8]) -> Result<(), TransportError> {
            self.written.extend_from_slice(bytes);
            for (trigger, reply) in &self.replies {
                if contains(bytes, trigger) {
                    // Deliver the reply in two fragments, as a serial line might.
                    let mid = reply.len() / 2;
                    self.pending.push_back(reply[..mid].to_vec());
                    self.pending.push_back(reply[mid..].to_vec());
                }
            }
            Ok(())
        }

        fn describe(&self) -> String {
            "scripted".into()
        }
    }

    pub fn scripted(replies: Vec<(Vec<u8>, Vec<u8>)>) -> Scripted {
        Scripted {
            clock: VirtualClock::new(),
            tick: Duration::from_millis(50),
            written: Vec::new(),
            pending: VecDeque::new(),
            replies,
        }
    }

    /// Runs `protocol`'s init against `dev`; returns (result, bytes seen by on_read).
    pub fn run(
        protocol: Protocol,
        settings: &InitSettings,
        dev: &mut Scripted,
    ) -> (Result<(), DriverError>, Vec<u8>) {
        let clock = dev.clock.clone();
        let stop = AtomicBool::new(false);
        let mut seen = Vec::new();
        let mut sent = Vec::new();
        let result = {
            let mut on_read = |b: &[u8]| seen.extend_from_slice(b);
            let mut on_sent = |b: &[u8]| sent.extend_from_slice(b);
            let mut link = Link::new(dev, &clock, &stop, &mut on_read, &mut on_sent);
            initialise(protocol, settings, &mut link)
        };
        assert_eq!(sent, dev.written, "on_sent sees exactly what is written");
        (result, seen)
    }

    pub fn settings() -> InitSettings {
        InitSettings {
            decoder: DecoderSettings::default(),
            stations: vec![],
            timeout: Duration::from_secs(2),
        }
    }
}
