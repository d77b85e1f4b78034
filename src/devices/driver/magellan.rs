//! Magellan / SpaceMouse serial initialisation: ask the version, then rezero and 3D mode.

use super::{DriverError, InitSettings, Link};

/// Runs the Magellan initialisation.
pub fn initialise(settings: &InitSettings, link: &mut Link<'_>) -> Result<(), DriverError> {
    link.clear_received();
    link.send(b"vQ\r")?;
    link.wait_for("version reply (to `vQ`)", settings.timeout, |rx| {
        rx.iter().position(|&b| b == b'v').is_some_and(|at| {
            let tail = &rx[at..];
            tail.contains(&b'\r')
                && tail
                    .to_ascii_uppercase()
                    .windows(8)
                    .any(|w| w == b"MAGELLAN")
        })
    })?;
    link.send(b"z\r")?;
    link.send(b"m3\r")?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::super::test_support::{run, scripted, settings};
    use crate::devices::encode::magellan::encode_version;
    use crate::devices::protocol::Protocol;

    #[test]
    fn asks_version_then_rezeroes() {
        let mut dev = scripted(vec![(b"vQ\r".to_vec(), encode_version())]);
        let (result, _) = run(Protocol::Magellan, &settings(), &mut dev);
        result.expect("init");
        assert_eq!(dev.written, b"vQ\rz\rm3\r");
    }
}
