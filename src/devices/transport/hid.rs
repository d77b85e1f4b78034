//! USB HID devices through `hidapi` (opened by vendor, product and optionally serial number).
//! Each read returns one input report with its report ID in byte 0.

use super::{Opener, Transport, TransportError};
use crate::devices::profile::HidSpec;
use std::time::Duration;

/// An open HID device.
pub struct HidTransport {
    device: hidapi::HidDevice,
    what: String,
    read_timeout_ms: i32,
}

fn hid_error(what: &str, e: impl std::fmt::Display) -> TransportError {
    TransportError::Io {
        what: what.to_string(),
        message: e.to_string(),
    }
}

impl HidTransport {
    /// Opens the first HID device matching `spec`; unset vendor/product match any device in the
    /// supported SpaceMouse table.
    pub fn open(spec: &HidSpec, read_timeout: Duration) -> Result<Self, TransportError> {
        let what = describe_spec(spec);
        let open_err = |message: String| TransportError::Open {
            what: what.clone(),
            message,
        };
        let api = hidapi::HidApi::new().map_err(|e| open_err(e.to_string()))?;
        let found = api.device_list().find(|d| {
            spec.vendor_id.is_none_or(|v| v == d.vendor_id())
                && spec.product_id.is_none_or(|p| p == d.product_id())
                && spec
                    .serial
                    .as_deref()
                    .is_none_or(|s| d.serial_number() == Some(s))
                && (spec.vendor_id.is_some() && spec.product_id.is_some()
                    || crate::devices::spacemouse_hid::is_supported(d.vendor_id(), d.product_id())
                        .is_some())
        });
        let info = found.ok_or_else(|| open_err("no such HID device is plugged in".into()))?;
        let device = info
            .open_device(&api)
            .map_err(|e| open_err(e.to_string()))?;
        let what = format!(
            "hid {:04x}:{:04x}{}",
            info.vendor_id(),
            info.product_id(),
            info.serial_number()
                .map(|s| format!(" serial {s}"))
                .unwrap_or_default()
        );
        Ok(Self {
            device,
            what,
            read_timeout_ms: i32::try_from(read_timeout.as_millis()).unwrap_or(i32::MAX),
        })
    }
}

/// `hid 046d:c626` style description of what a spec asks for.
pub fn describe_spec(spec: &HidSpec) -> String {
    let id = |v: Option<u16>| v.map_or("any".to_string(), |v| format!("{v:04x}"));
    format!(
        "hid {}:{}{}",
        id(spec.vendor_id),
        id(spec.product_id),
        spec.serial
            .as_deref()
            .map(|s| format!(" serial {s}"))
            .unwrap_or_default()
    )
}

impl Transport for HidTransport {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, TransportError> {
        self.device
            .read_timeout(buf, self.read_timeout_ms)
            .map_err(|e| hid_error(&self.what, e))
    }

    fn write(&mut self, bytes: &[u8]) -> Result<(), TransportError> {
        self.device
            .write(bytes)
            .map(|_| ())
            .map_err(|e| hid_error(&self.what, e))
    }

    fn describe(&self) -> String {
        self.what.clone()
    }
}

/// Opens a HID device matching a spec (again after each loss).
#[derive(Debug, Clone)]
pub struct HidOpener {
    /// Which device.
    pub spec: HidSpec,
    /// Longest a read waits.
    pub read_timeout: Duration,
}

impl Opener for HidOpener {
    fn open(&mut self) -> Result<Box<dyn Transport>, TransportError> {
        Ok(Box::new(HidTransport::open(&self.spec, self.read_timeout)?))
    }

    fn describe(&self) -> String {
        describe_spec(&self.spec)
    }
}
