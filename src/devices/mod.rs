//! Devices: raw bytes in, samples out. Protocol decoders (one file per protocol) are pure;
//! transports (serial, HID, UDP, replay), recording and the hub sit at the edge.

pub mod decoder;
pub mod sample;
