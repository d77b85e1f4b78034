//! Listing what is plugged in: serial ports (`serialport::available_ports`) and HID devices
//! (`hidapi`), marking HID devices in the supported SpaceMouse table. Serial trackers and 3D
//! mice (FASTRAK, Spaceball, Magellan, Logitech) cannot be told apart by the port alone: a
//! serial port is only a candidate until a profile names its protocol.

use crate::devices::protocol::{Framing, Protocol};
use serde::Serialize;

/// USB details of a serial port, when the system provides them.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct UsbInfo {
    /// Vendor id.
    pub vendor_id: u16,
    /// Product id.
    pub product_id: u16,
    /// Serial number.
    pub serial: Option<String>,
    /// Manufacturer string.
    pub manufacturer: Option<String>,
    /// Product string.
    pub product: Option<String>,
}

/// One serial port.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct SerialEntry {
    /// Device path.
    pub path: String,
    /// `usb`, `pci`, `bluetooth` or `unknown`.
    pub kind: String,
    /// USB details when known.
    pub usb: Option<UsbInfo>,
    /// Serial protocols this port could carry (all of them: the port does not say).
    pub candidates: Vec<Protocol>,
}

/// One HID device (interface).
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct HidEntry {
    /// Vendor id.
    pub vendor_id: u16,
    /// Product id.
    pub product_id: u16,
    /// Serial number.
    pub serial: Option<String>,
    /// Manufacturer string.
    pub manufacturer: Option<String>,
    /// Product string.
    pub product: Option<String>,
    /// Interface number.
    pub interface: i32,
    /// System path.
    pub path: String,
    /// Model name from the supported table, when it is a supported 3D mouse.
    pub supported_model: Option<String>,
    /// `spacemouse-hid` when supported.
    pub protocol: Option<Protocol>,
}

impl HidEntry {
    /// An interface of the device `vendor_id:product_id` at `path`, marked from the supported
    /// table ([`match_hid`]); no serial, manufacturer or product strings, interface 0.
    pub fn new(vendor_id: u16, product_id: u16, path: impl Into<String>) -> Self {
        let matched = match_hid(vendor_id, product_id);
        Self {
            vendor_id,
            product_id,
            serial: None,
            manufacturer: None,
            product: None,
            interface: 0,
            path: path.into(),
            supported_model: matched.map(|(_, m)| m.to_string()),
            protocol: matched.map(|(p, _)| p),
        }
    }
}

/// Everything found.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Default)]
pub struct DeviceList {
    /// Serial ports.
    pub serial: Vec<SerialEntry>,
    /// Why serial ports could not be listed, if they could not.
    pub serial_error: Option<String>,
    /// HID devices.
    pub hid: Vec<HidEntry>,
    /// Why HID devices could not be listed, if they could not.
    pub hid_error: Option<String>,
    /// Remarks for the user.
    pub notes: Vec<String>,
}

/// The serial protocols (byte streams), as candidates for an unidentified serial port.
pub fn serial_protocols() -> Vec<Protocol> {
    Protocol::ALL
        .into_iter()
        .filter(|p| p.framing() == Framing::Stream)
        .collect()
}

/// The protocol and model a HID vendor/product pair is, if supported.
pub fn match_hid(vendor_id: u16, product_id: u16) -> Option<(Protocol, &'static str)> {
    crate::devices::spacemouse_hid::is_supported(vendor_id, product_id)
        .map(|model| (Protocol::SpacemouseHid, model))
}

/// Lists serial ports and HID devices. Never fails: a listing that cannot be made is reported in
/// `serial_error` / `hid_error`.
pub fn list_devices() -> DeviceList {
    let mut out = DeviceList::default();
    match serialport::available_ports() {
        Ok(ports) => {
            for p in ports {
                let (kind, usb) = match p.port_type {
                    serialport::SerialPortType::UsbPort(u) => (
                        "usb",
                        Some(UsbInfo {
                            vendor_id: u.vid,
                            product_id: u.pid,
                            serial: u.serial_number,
                            manufacturer: u.manufacturer,
                            product: u.product,
                        }),
                    ),
                    serialport::SerialPortType::PciPort => ("pci", None),
                    serialport::SerialPortType::BluetoothPort => ("bluetooth", None),
                    serialport::SerialPortType::Unknown => ("unknown", None),
                };
                out.serial.push(SerialEntry {
                    path: p.port_name,
                    kind: kind.into(),
                    usb,
                    candidates: serial_protocols(),
                });
            }
        }
        Err(e) => out.serial_error = Some(e.to_string()),
    }
    if out.serial.iter().all(|s| s.usb.is_none()) {
        out.notes.push(
            "this build lists serial ports without libudev, so USB vendor/product details of \
             serial adapters may be missing"
                .into(),
        );
    }
    out.notes.push(
        "serial trackers and 3D mice (fastrak, spaceball, magellan, logitech) cannot be \
         identified from the port: name the protocol in a device profile"
            .into(),
    );
    match list_hid() {
        Ok(hid) => out.hid = hid,
        Err(e) => out.hid_error = Some(e),
    }
    out.notes.push(
        "OpenTrack sends UDP to port 4242 by default: use a profile with an opentrack device"
            .into(),
    );
    out
}

/// Lists the HID devices (interfaces) alone, marking supported 3D mice; the error says why they
/// could not be listed.
pub fn list_hid() -> Result<Vec<HidEntry>, String> {
    let api = hidapi::HidApi::new().map_err(|e| e.to_string())?;
    Ok(api
        .device_list()
        .map(|d| HidEntry {
            serial: d.serial_number().map(str::to_string),
            manufacturer: d.manufacturer_string().map(str::to_string),
            product: d.product_string().map(str::to_string),
            interface: d.interface_number(),
            ..HidEntry::new(d.vendor_id(), d.product_id(), d.path().to_string_lossy())
        })
        .collect())
}

/// The listing as text for a terminal.
pub fn format_text(list: &DeviceList) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    let _ = writeln!(s, "Serial ports:");
    if let Some(e) = &list.serial_error {
        let _ = writeln!(s, "  (cannot list: {e})");
    } else if list.serial.is_empty() {
        let _ = writeln!(s, "  (none)");
    }
    for p in &list.serial {
        let usb = p.usb.as_ref().map_or(String::new(), |u| {
            format!(
                " usb {:04x}:{:04x} {} {}",
                u.vendor_id,
                u.product_id,
                u.manufacturer.as_deref().unwrap_or(""),
                u.product.as_deref().unwrap_or("")
            )
        });
        let _ = writeln!(
            s,
            "  {} [{}]{}  could be: {}",
            p.path,
            p.kind,
            usb.trim_end(),
            p.candidates
                .iter()
                .map(|c| c.name())
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    let _ = writeln!(s, "HID devices:");
    if let Some(e) = &list.hid_error {
        let _ = writeln!(s, "  (cannot list: {e})");
    } else if list.hid.is_empty() {
        let _ = writeln!(s, "  (none)");
    }
    for h in &list.hid {
        let mark = match (&h.supported_model, h.protocol) {
            (Some(m), Some(p)) => format!("  SUPPORTED: {m} ({p})"),
            _ => String::new(),
        };
        let _ = writeln!(
            s,
            "  {:04x}:{:04x} {} {} (interface {}){}",
            h.vendor_id,
            h.product_id,
            h.manufacturer.as_deref().unwrap_or("?"),
            h.product.as_deref().unwrap_or("?"),
            h.interface,
            mark
        );
    }
    if list.hid.iter().any(|h| h.supported_model.is_some()) {
        let _ = writeln!(
            s,
            "  (`leman run` without --profile flies the view with a SUPPORTED one)"
        );
    }
    for n in &list.notes {
        let _ = writeln!(s, "note: {n}");
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hid_table_marks_spacemice_only() {
        assert_eq!(
            match_hid(0x046D, 0xC626),
            Some((Protocol::SpacemouseHid, "SpaceNavigator"))
        );
        assert_eq!(
            match_hid(0x046D, 0xC52B),
            None,
            "a Logitech receiver is no 3D mouse"
        );
        assert!(!serial_protocols().contains(&Protocol::Opentrack));
        assert!(serial_protocols().contains(&Protocol::Spaceball));
    }

    #[test]
    fn text_listing_marks_supported_devices() {
        let list = DeviceList {
            serial: vec![SerialEntry {
                path: "/dev/ttyS0".into(),
                kind: "unknown".into(),
                usb: None,
                candidates: serial_protocols(),
            }],
            hid: vec![HidEntry {
                manufacturer: Some("3Dconnexion".into()),
                product: Some("SpaceMouse Compact".into()),
                ..HidEntry::new(0x256F, 0xC635, "/dev/hidraw0")
            }],
            ..DeviceList::default()
        };
        let text = format_text(&list);
        assert!(
            text.contains("/dev/ttyS0 [unknown]  could be: fastrak-ascii"),
            "{text}"
        );
        assert!(
            text.contains("SUPPORTED: SpaceMouse Compact (spacemouse-hid)"),
            "{text}"
        );
        assert!(
            text.contains("`leman run` without --profile flies"),
            "{text}"
        );
        // Only a supported one is said to fly the view.
        let mut other = list.clone();
        other.hid[0] = HidEntry::new(0x1234, 0x5678, "/dev/hidraw1");
        assert!(!format_text(&other).contains("leman run"));
        let json = serde_json::to_value(&list).expect("json");
        assert_eq!(json["hid"][0]["protocol"], "spacemouse-hid");
    }

    #[test]
    fn listing_the_real_machine_never_fails() {
        let list = list_devices();
        assert!(!list.notes.is_empty());
    }
}
