//! The interface every protocol decoder implements.

use super::sample::DeviceEvent;

/// A streaming protocol decoder: bytes arrive in arbitrary fragments; complete packets come out
/// as events. Implementations never panic on any input, resynchronise after garbage and report
/// discarded bytes as [`DeviceEvent::Dropped`].
pub trait Decoder: Send {
    /// Feeds the next chunk of bytes as it arrived and appends every event it completes.
    fn feed(&mut self, bytes: &[u8], out: &mut Vec<DeviceEvent>);

    /// Forgets any partial packet (after a reconnect).
    fn reset(&mut self);

    /// Bytes held in a partial packet, waiting for the rest. At the end of a capture these
    /// are a truncated packet (`leman decode` reports them as dropped).
    fn pending(&self) -> usize {
        0
    }
}

/// Counts discarded bytes and reports them as one [`DeviceEvent::Dropped`] just before the next
/// event (or at the end of a feed), so drops appear in arrival order.
#[derive(Debug, Default, Clone, PartialEq, Eq)]
pub struct DropTally {
    pending: usize,
}

impl DropTally {
    /// Records `bytes` more discarded bytes.
    pub fn add(&mut self, bytes: usize) {
        self.pending = self.pending.saturating_add(bytes);
    }

    /// Emits the pending count as one `Dropped` event, if any.
    pub fn flush(&mut self, out: &mut Vec<DeviceEvent>) {
        if self.pending > 0 {
            out.push(DeviceEvent::Dropped {
                bytes: self.pending,
            });
            self.pending = 0;
        }
    }

    /// Emits the pending count (if any), then `event`.
    pub fn push(&mut self, event: DeviceEvent, out: &mut Vec<DeviceEvent>) {
        self.flush(out);
        out.push(event);
    }

    /// Forgets the pending count.
    pub fn clear(&mut self) {
        self.pending = 0;
    }
}

/// Splits a byte stream into CR-terminated frames (Spaceball, Magellan) with a bounded buffer.
/// A frame longer than `max_frame` bytes without a CR loses its oldest bytes, which are counted
/// as dropped; the frame's tail is kept so a packet that began in it can still be found.
#[derive(Debug, Clone)]
pub(crate) struct CrFramer {
    buf: Vec<u8>,
    max_frame: usize,
}

impl CrFramer {
    pub(crate) fn new(max_frame: usize) -> Self {
        Self {
            buf: Vec::with_capacity(max_frame),
            max_frame: max_frame.max(1),
        }
    }

    /// Feeds one byte; returns the finished frame (without its CR) when `byte` is a CR.
    pub(crate) fn push(&mut self, byte: u8, drops: &mut DropTally) -> Option<Vec<u8>> {
        if byte == b'\r' {
            return Some(std::mem::take(&mut self.buf));
        }
        if self.buf.len() >= 2 * self.max_frame {
            let excess = self.buf.len() - self.max_frame;
            self.buf.drain(..excess);
            drops.add(excess);
        }
        self.buf.push(byte);
        None
    }

    pub(crate) fn clear(&mut self) {
        self.buf.clear();
    }

    /// Bytes held now.
    pub(crate) fn len(&self) -> usize {
        self.buf.len()
    }
}
