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
}
