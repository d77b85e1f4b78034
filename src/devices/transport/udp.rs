//! UDP (OpenTrack "UDP over network", default port 4242): each read returns one datagram.

use super::{Opener, Transport, TransportError};
use std::net::UdpSocket;
use std::time::Duration;

/// A bound UDP socket.
pub struct UdpTransport {
    socket: UdpSocket,
    what: String,
}

impl UdpTransport {
    /// Binds `addr` (`0.0.0.0:4242`, `127.0.0.1:0`); reads wait at most `read_timeout`.
    pub fn bind(addr: &str, read_timeout: Duration) -> Result<Self, TransportError> {
        let open_err = |e: std::io::Error| TransportError::Open {
            what: format!("udp {addr}"),
            message: e.to_string(),
        };
        let socket = UdpSocket::bind(addr).map_err(open_err)?;
        socket
            .set_read_timeout(Some(read_timeout.max(Duration::from_millis(1))))
            .map_err(open_err)?;
        let what = match socket.local_addr() {
            Ok(a) => format!("udp {a}"),
            Err(_) => format!("udp {addr}"),
        };
        Ok(Self { socket, what })
    }

    /// The address actually bound (useful with port 0).
    pub fn local_addr(&self) -> Option<std::net::SocketAddr> {
        self.socket.local_addr().ok()
    }
}

impl Transport for UdpTransport {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, TransportError> {
        match self.socket.recv_from(buf) {
            Ok((n, _from)) => Ok(n),
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock
                        | std::io::ErrorKind::TimedOut
                        | std::io::ErrorKind::Interrupted
                ) =>
            {
                Ok(0)
            }
            Err(e) => Err(TransportError::Io {
                what: self.what.clone(),
                message: e.to_string(),
            }),
        }
    }

    fn write(&mut self, _bytes: &[u8]) -> Result<(), TransportError> {
        // OpenTrack takes no commands; nothing to send.
        Ok(())
    }

    fn describe(&self) -> String {
        self.what.clone()
    }
}

/// Binds a UDP socket (again after each loss).
#[derive(Debug, Clone)]
pub struct UdpOpener {
    /// Address to bind.
    pub bind: String,
    /// Longest a read waits.
    pub read_timeout: Duration,
}

impl Opener for UdpOpener {
    fn open(&mut self) -> Result<Box<dyn Transport>, TransportError> {
        Ok(Box::new(UdpTransport::bind(&self.bind, self.read_timeout)?))
    }

    fn describe(&self) -> String {
        format!("udp {}", self.bind)
    }
}
