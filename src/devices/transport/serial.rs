//! Serial ports through the `serialport` crate, with each protocol's line settings.

use super::{Opener, Transport, TransportError};
use crate::devices::profile::{FlowControl, Parity, SerialLine};
use std::io::{Read, Write};
use std::time::Duration;

/// An open serial port.
pub struct SerialTransport {
    port: Box<dyn serialport::SerialPort>,
    path: String,
}

impl SerialTransport {
    /// Opens `path` with `line` settings; reads wait at most `read_timeout`.
    pub fn open(
        path: &str,
        line: &SerialLine,
        read_timeout: Duration,
    ) -> Result<Self, TransportError> {
        let builder = serialport::new(path, line.baud)
            .data_bits(match line.data_bits {
                5 => serialport::DataBits::Five,
                6 => serialport::DataBits::Six,
                7 => serialport::DataBits::Seven,
                _ => serialport::DataBits::Eight,
            })
            .parity(match line.parity {
                Parity::None => serialport::Parity::None,
                Parity::Odd => serialport::Parity::Odd,
                Parity::Even => serialport::Parity::Even,
            })
            .stop_bits(if line.stop_bits == 2 {
                serialport::StopBits::Two
            } else {
                serialport::StopBits::One
            })
            .flow_control(match line.flow_control {
                FlowControl::None => serialport::FlowControl::None,
                FlowControl::Software => serialport::FlowControl::Software,
                FlowControl::Hardware => serialport::FlowControl::Hardware,
            })
            .timeout(read_timeout);
        let port = builder.open().map_err(|e| TransportError::Open {
            what: path.to_string(),
            message: e.to_string(),
        })?;
        Ok(Self {
            port,
            path: path.to_string(),
        })
    }

    /// Wraps an already open port (tests use one end of a pseudo-terminal pair).
    pub fn from_port(port: Box<dyn serialport::SerialPort>, path: impl Into<String>) -> Self {
        Self {
            port,
            path: path.into(),
        }
    }
}

impl Transport for SerialTransport {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, TransportError> {
        match self.port.read(buf) {
            Ok(0) if !buf.is_empty() => Err(TransportError::Closed {
                what: self.path.clone(),
            }),
            Ok(n) => Ok(n),
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::TimedOut
                        | std::io::ErrorKind::WouldBlock
                        | std::io::ErrorKind::Interrupted
                ) =>
            {
                Ok(0)
            }
            Err(e) => Err(TransportError::Io {
                what: self.path.clone(),
                message: e.to_string(),
            }),
        }
    }

    fn write(&mut self, bytes: &[u8]) -> Result<(), TransportError> {
        self.port
            .write_all(bytes)
            .and_then(|()| self.port.flush())
            .map_err(|e| TransportError::Io {
                what: self.path.clone(),
                message: e.to_string(),
            })
    }

    fn describe(&self) -> String {
        format!("serial {}", self.path)
    }
}

/// Opens a serial port by path (again after each loss).
#[derive(Debug, Clone)]
pub struct SerialOpener {
    /// Device path.
    pub path: String,
    /// Line settings.
    pub line: SerialLine,
    /// Longest a read waits.
    pub read_timeout: Duration,
}

impl Opener for SerialOpener {
    fn open(&mut self) -> Result<Box<dyn Transport>, TransportError> {
        Ok(Box::new(SerialTransport::open(
            &self.path,
            &self.line,
            self.read_timeout,
        )?))
    }

    fn describe(&self) -> String {
        format!("serial {}", self.path)
    }
}
