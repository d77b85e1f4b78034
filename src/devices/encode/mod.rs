//! Pure encoders: wire bytes from known values, one module per protocol. They are the inverse
//! of the decoders and exist for tests, the sample-session generator and fake serial devices.
//! Nothing here reads a clock or does I/O.

pub mod fastrak;
pub mod logitech;
pub mod magellan;
pub mod opentrack;
pub mod spaceball;
pub mod spacemouse_hid;
