//! Transports: how bytes reach a driver. Serial ports ([`serial`]), USB HID ([`hid`]), UDP
//! ([`udp`]) and recorded sessions ([`replay`]). A transport moves bytes and nothing else; the
//! [`Opener`] makes (and after a loss remakes) a transport, so the hub can reconnect.

pub mod hid;
pub mod replay;
pub mod serial;
pub mod udp;

use std::time::Duration;

/// A transport failure; names the device it concerns.
#[derive(Debug, thiserror::Error)]
pub enum TransportError {
    /// The device could not be opened.
    #[error("cannot open {what}: {message}")]
    Open {
        /// The device (path, vendor:product, address).
        what: String,
        /// Why.
        message: String,
    },
    /// Reading or writing failed (unplugged, hung up, ...).
    #[error("{what}: {message}")]
    Io {
        /// The device.
        what: String,
        /// Why.
        message: String,
    },
    /// The other end closed or the recorded session is over.
    #[error("{what}: closed")]
    Closed {
        /// The device.
        what: String,
    },
}

/// An open connection to one device.
pub trait Transport: Send {
    /// Reads what is available into `buf`, waiting at most the transport's read timeout.
    /// `Ok(0)` means nothing arrived in that time. Message transports (HID, UDP) return exactly
    /// one message per call (cut to `buf`'s length).
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, TransportError>;

    /// Writes all of `bytes` (initialisation commands, HID output reports).
    fn write(&mut self, bytes: &[u8]) -> Result<(), TransportError>;

    /// What this is connected to, for messages.
    fn describe(&self) -> String;

    /// For transports that replay a recording: the recorded arrival time of the chunk the last
    /// `read` returned. Live transports return `None` and the hub stamps arrival on its clock.
    fn recorded_arrival(&self) -> Option<Duration> {
        None
    }

    /// Whether the device's initialisation sequence must run after opening (false for
    /// replays, which hold no answers to commands).
    fn needs_init(&self) -> bool {
        true
    }
}

/// Makes a transport; called again after a loss to reconnect.
pub trait Opener: Send {
    /// Opens a fresh connection.
    fn open(&mut self) -> Result<Box<dyn Transport>, TransportError>;

    /// What it opens, for messages.
    fn describe(&self) -> String;
}

/// An [`Opener`] from a closure (tests, custom wiring).
pub struct FnOpener<F> {
    what: String,
    open: F,
}

impl<F> FnOpener<F>
where
    F: FnMut() -> Result<Box<dyn Transport>, TransportError> + Send,
{
    /// Wraps `open`, described as `what`.
    pub fn new(what: impl Into<String>, open: F) -> Self {
        Self {
            what: what.into(),
            open,
        }
    }
}

impl<F> Opener for FnOpener<F>
where
    F: FnMut() -> Result<Box<dyn Transport>, TransportError> + Send,
{
    fn open(&mut self) -> Result<Box<dyn Transport>, TransportError> {
        (self.open)()
    }

    fn describe(&self) -> String {
        self.what.clone()
    }
}
