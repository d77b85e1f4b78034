//! FASTRAK initialisation: stop streaming, set format, units and each station's output list,
//! check the device answers a status request, then stream continuously.

use super::{DriverError, InitSettings, Link};
use crate::devices::fastrak::{LengthUnit, STATUS_RECORD_LEN};
use crate::devices::protocol::Protocol;
use std::time::Duration;

/// The commands sent before the status request, in order.
pub fn setup_commands(protocol: Protocol, settings: &InitSettings) -> Vec<Vec<u8>> {
    let f = &settings.decoder.fastrak;
    let mut cmds: Vec<Vec<u8>> = vec![
        if protocol == Protocol::FastrakBinary {
            b"f\r".to_vec()
        } else {
            b"F\r".to_vec()
        },
        match f.units {
            LengthUnit::Inches => b"U\r".to_vec(),
            LengthUnit::Centimetres => b"u\r".to_vec(),
        },
    ];
    let stations: Vec<u8> = if settings.stations.is_empty() {
        vec![1]
    } else {
        settings.stations.clone()
    };
    let items = f
        .items
        .iter()
        .map(u8::to_string)
        .collect::<Vec<_>>()
        .join(",");
    for st in stations {
        cmds.push(format!("l{st},1\r").into_bytes());
        cmds.push(format!("O{st},{items}\r").into_bytes());
    }
    cmds
}

/// True when `rx` holds a complete status record (`2`, station, `S`, ..., CR LF).
pub fn has_status_record(rx: &[u8]) -> bool {
    rx.windows(3)
        .enumerate()
        .filter(|(_, w)| w[0] == b'2' && (b'1'..=b'4').contains(&w[1]) && w[2] == b'S')
        .any(|(at, _)| {
            rx.get(at + STATUS_RECORD_LEN - 2..at + STATUS_RECORD_LEN) == Some(b"\r\n".as_slice())
        })
}

/// Runs the FASTRAK initialisation.
pub fn initialise(
    protocol: Protocol,
    settings: &InitSettings,
    link: &mut Link<'_>,
) -> Result<(), DriverError> {
    link.send(b"c\r")?;
    link.drain(Duration::from_millis(200))?;
    for cmd in setup_commands(protocol, settings) {
        link.send(&cmd)?;
    }
    link.clear_received();
    link.send(b"S\r")?;
    link.wait_for(
        "status record (reply to `S`)",
        settings.timeout,
        has_status_record,
    )?;
    link.send(b"C\r")?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::super::test_support::{run, scripted, settings};
    use super::*;
    use crate::devices::encode::fastrak::encode_status_record;

    #[test]
    fn configures_checks_status_and_starts_streaming() {
        let mut dev = scripted(vec![(b"S\r".to_vec(), encode_status_record(1, "ok"))]);
        let mut s = settings();
        s.stations = vec![1, 2];
        s.decoder.fastrak.units = LengthUnit::Centimetres;
        let (result, seen) = run(Protocol::FastrakBinary, &s, &mut dev);
        result.expect("init");
        assert_eq!(seen, encode_status_record(1, "ok"));
        let text = String::from_utf8_lossy(&dev.written).to_string();
        assert_eq!(
            text, "c\rf\ru\rl1,1\rO1,2,4,1\rl2,1\rO2,2,4,1\rS\rC\r",
            "command sequence"
        );
    }

    #[test]
    fn a_silent_tracker_times_out() {
        let mut dev = scripted(vec![]);
        let (result, _) = run(Protocol::FastrakAscii, &settings(), &mut dev);
        assert!(matches!(result, Err(DriverError::Timeout { .. })));
        assert!(!String::from_utf8_lossy(&dev.written).contains("C\r"));
    }

    #[test]
    fn status_record_detection_needs_the_whole_record() {
        let rec = encode_status_record(3, "x");
        assert!(has_status_record(&rec));
        assert!(!has_status_record(&rec[..rec.len() - 1]));
        let mut noisy = b"01 garbage".to_vec();
        noisy.extend(&rec);
        assert!(has_status_record(&noisy));
    }
}
