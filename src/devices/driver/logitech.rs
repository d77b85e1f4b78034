//! Logitech 3D mouse / head tracker initialisation: reset, diagnostics, stream.

use super::{DriverError, InitSettings, Link};
use std::time::Duration;

/// Runs the Logitech initialisation. The diagnostics reply (`0xBF 0x3F` when all tests pass) is
/// required to show the device is there; a failing result is passed on (the decoder drops the
/// two bytes) but does not stop streaming.
pub fn initialise(settings: &InitSettings, link: &mut Link<'_>) -> Result<(), DriverError> {
    link.send(b"*R")?;
    link.drain(Duration::from_millis(200))?;
    link.clear_received();
    link.send(b"*\x05")?;
    link.wait_for("diagnostics reply (to `*` 0x05)", settings.timeout, |rx| {
        rx.iter()
            .position(|&b| b & 0x80 != 0)
            .is_some_and(|at| rx.len() >= at + 2)
    })?;
    link.send(b"*S")?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::super::test_support::{run, scripted, settings};
    use crate::devices::protocol::Protocol;

    #[test]
    fn resets_checks_diagnostics_and_streams() {
        let mut dev = scripted(vec![(b"*\x05".to_vec(), vec![0xBF, 0x3F])]);
        let (result, seen) = run(Protocol::Logitech, &settings(), &mut dev);
        result.expect("init");
        assert_eq!(seen, vec![0xBF, 0x3F]);
        assert_eq!(dev.written, b"*R*\x05*S");
    }
}
