//! Devices: raw bytes in, samples out. Protocol decoders (one file per protocol) are pure;
//! transports (serial, HID, UDP, replay), recording and the hub sit at the edge.

pub mod decoder;
#[cfg(test)]
mod decoder_props;
pub mod desktop;
pub mod driver;
pub mod encode;
pub mod enumerate;
pub mod fastrak;
pub mod found;
pub mod fuzz_harness;
pub mod hub;
pub mod logitech;
pub mod magellan;
pub mod opentrack;
pub mod profile;
pub mod protocol;
pub mod replay;
pub mod sample;
pub mod sample_sessions;
pub mod session;
pub mod spaceball;
pub mod spacemouse_hid;
#[cfg(test)]
mod test_util;
pub mod transport;
