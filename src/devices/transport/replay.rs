//! A transport that plays back one device's chunks from a recorded session, each exactly as it
//! arrived, either as fast as possible or when a clock (usually a
//! [`crate::clock::VirtualClock`]) reaches the recorded time. It reports each chunk's recorded
//! arrival time, so a hub reading it stamps samples with the original times.

use super::{Transport, TransportError};
use crate::clock::Clock;
use crate::devices::session::Session;
use std::collections::VecDeque;
use std::sync::Arc;
use std::time::Duration;

/// When a replayed chunk is delivered.
#[derive(Clone)]
pub enum Pacing {
    /// Immediately, one chunk per read.
    AsFastAsPossible,
    /// When the clock reaches the chunk's recorded time.
    Clock(Arc<dyn Clock>),
}

impl std::fmt::Debug for Pacing {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Pacing::AsFastAsPossible => f.write_str("AsFastAsPossible"),
            Pacing::Clock(_) => f.write_str("Clock"),
        }
    }
}

/// Plays back one device's recorded chunks.
pub struct ReplayTransport {
    chunks: VecDeque<(Duration, Vec<u8>)>,
    pacing: Pacing,
    read_timeout: Duration,
    last_arrival: Option<Duration>,
    what: String,
}

impl ReplayTransport {
    /// The chunks of `device` in `session`. With [`Pacing::Clock`], a read waits (in real
    /// time, polling every millisecond) at most `read_timeout` for the clock to reach the next
    /// chunk.
    pub fn new(session: &Session, device: usize, pacing: Pacing, read_timeout: Duration) -> Self {
        let name = session
            .header
            .profile
            .devices
            .get(device)
            .map_or("?", |d| d.name.as_str());
        Self::from_chunks(
            session
                .chunks(device)
                .map(|(t, b)| (t, b.to_vec()))
                .collect(),
            pacing,
            read_timeout,
            format!("replay of device {device} ({name})"),
        )
    }

    /// Plays back the given `(arrival, bytes)` chunks.
    pub fn from_chunks(
        chunks: VecDeque<(Duration, Vec<u8>)>,
        pacing: Pacing,
        read_timeout: Duration,
        what: String,
    ) -> Self {
        Self {
            chunks,
            pacing,
            read_timeout,
            last_arrival: None,
            what,
        }
    }

    /// Chunks not yet delivered.
    pub fn remaining(&self) -> usize {
        self.chunks.len()
    }
}

impl Transport for ReplayTransport {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, TransportError> {
        let Some((at, _)) = self.chunks.front() else {
            return Err(TransportError::Closed {
                what: self.what.clone(),
            });
        };
        let at = *at;
        if let Pacing::Clock(clock) = &self.pacing {
            let mut waited = Duration::ZERO;
            while clock.now() < at {
                if waited >= self.read_timeout {
                    return Ok(0);
                }
                std::thread::sleep(Duration::from_millis(1));
                waited += Duration::from_millis(1);
            }
        }
        let Some((_, bytes)) = self.chunks.front_mut() else {
            return Ok(0);
        };
        let n = bytes.len().min(buf.len());
        buf[..n].copy_from_slice(&bytes[..n]);
        if n == bytes.len() {
            self.chunks.pop_front();
        } else {
            bytes.drain(..n);
        }
        self.last_arrival = Some(at);
        Ok(n)
    }

    fn write(&mut self, _bytes: &[u8]) -> Result<(), TransportError> {
        Ok(())
    }

    fn describe(&self) -> String {
        self.what.clone()
    }

    fn recorded_arrival(&self) -> Option<Duration> {
        self.last_arrival
    }

    fn needs_init(&self) -> bool {
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::clock::VirtualClock;

    fn chunks() -> VecDeque<(Duration, Vec<u8>)> {
        VecDeque::from(vec![
            (Duration::from_millis(10), b"ab".to_vec()),
            (Duration::from_millis(20), b"cde".to_vec()),
        ])
    }

    #[test]
    fn delivers_chunks_with_their_boundaries_and_times_then_closes() {
        let mut t = ReplayTransport::from_chunks(
            chunks(),
            Pacing::AsFastAsPossible,
            Duration::ZERO,
            "t".into(),
        );
        let mut buf = [0u8; 16];
        assert_eq!(t.read(&mut buf).expect("read"), 2);
        assert_eq!(t.recorded_arrival(), Some(Duration::from_millis(10)));
        assert_eq!(t.read(&mut buf).expect("read"), 3);
        assert_eq!(&buf[..3], b"cde");
        assert!(matches!(
            t.read(&mut buf),
            Err(TransportError::Closed { .. })
        ));
    }

    #[test]
    fn clock_pacing_waits_for_the_recorded_time() {
        let clock = VirtualClock::new();
        let mut t = ReplayTransport::from_chunks(
            chunks(),
            Pacing::Clock(Arc::new(clock.clone())),
            Duration::from_millis(2),
            "t".into(),
        );
        let mut buf = [0u8; 16];
        assert_eq!(t.read(&mut buf).expect("read"), 0, "too early");
        clock.set(Duration::from_millis(10));
        assert_eq!(t.read(&mut buf).expect("read"), 2);
        assert_eq!(t.read(&mut buf).expect("read"), 0, "second chunk is later");
        clock.set(Duration::from_millis(25));
        assert_eq!(t.read(&mut buf).expect("read"), 3);
    }
}
