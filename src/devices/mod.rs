//! Devices: raw bytes in, samples out. Protocol decoders (one file per protocol) are pure;
//! transports (serial, HID, UDP, replay), recording and the hub sit at the edge.

pub mod decoder;
pub mod encode;
pub mod fastrak;
pub mod logitech;
pub mod magellan;
pub mod opentrack;
pub mod protocol;
pub mod sample;
pub mod spaceball;
pub mod spacemouse_hid;
#[cfg(test)]
mod test_util;
