//! Spaceball initialisation: reset, await the `@1` banner (and the `@2` firmware line), then
//! the spacenavd command set and Vrui's automatic-data command.

use super::{DriverError, InitSettings, Link, contains};
use std::time::Duration;

/// The reset command.
pub const RESET: &[u8] = b"\r@RESET\r";
/// Sent after the banner: binary communication mode, data settings, request key state.
pub const SETUP: &[u8] = b"\rCB\rMSSV\rk\r";
/// Starts automatic data.
pub const START: &[u8] = b"M\r";

fn firmware_line_complete(rx: &[u8]) -> bool {
    rx.windows(2)
        .position(|w| w == b"@2")
        .is_some_and(|at| rx[at..].contains(&b'\r'))
}

/// Runs the Spaceball initialisation.
pub fn initialise(settings: &InitSettings, link: &mut Link<'_>) -> Result<(), DriverError> {
    link.clear_received();
    link.send(RESET)?;
    link.wait_for("`@1` reset banner", settings.timeout, |rx| {
        contains(rx, b"@1")
    })?;
    // The firmware line names the model; older units may not send it, so a timeout is fine.
    match link.wait_for(
        "`@2` firmware line",
        Duration::from_millis(500),
        firmware_line_complete,
    ) {
        Ok(()) | Err(DriverError::Timeout { .. }) => {}
        Err(e) => return Err(e),
    }
    link.send(SETUP)?;
    link.send(START)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::super::test_support::{run, scripted, settings};
    use super::*;
    use crate::devices::encode::spaceball::encode_banner;
    use crate::devices::protocol::Protocol;

    #[test]
    fn waits_for_the_banner_then_starts_data() {
        let mut dev = scripted(vec![(b"@RESET".to_vec(), encode_banner("2.43"))]);
        let (result, seen) = run(Protocol::Spaceball, &settings(), &mut dev);
        result.expect("init succeeds");
        assert_eq!(seen, encode_banner("2.43"));
        let mut expected = RESET.to_vec();
        expected.extend(SETUP);
        expected.extend(START);
        assert_eq!(dev.written, expected);
    }

    #[test]
    fn times_out_on_the_clock_when_nothing_answers() {
        let mut dev = scripted(vec![]);
        let (result, _) = run(Protocol::Spaceball, &settings(), &mut dev);
        let err = result.expect_err("must time out");
        assert!(err.to_string().contains("@1"), "{err}");
        // 2 s at 50 ms of virtual time per read: about 40 reads, not a real-time wait.
        assert!(dev.clock_now() >= Duration::from_secs(2));
        assert!(dev.clock_now() < Duration::from_millis(2200));
        assert_eq!(dev.written, RESET, "nothing more is sent after a timeout");
    }
}
