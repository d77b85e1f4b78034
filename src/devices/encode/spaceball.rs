//! Spaceball packets: `D` axes, `.` and `K` buttons, the reset banner. Payloads are escaped.

/// Escapes a payload (`0x11` -> `^Q`, `0x13` -> `^S`, `0x0D` -> `^M`, `^` -> `^^`).
pub fn escape(payload: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(payload.len() + 4);
    for &b in payload {
        match b {
            0x11 => out.extend(b"^Q"),
            0x13 => out.extend(b"^S"),
            0x0D => out.extend(b"^M"),
            b'^' => out.extend(b"^^"),
            other => out.push(other),
        }
    }
    out
}

fn packet(kind: u8, payload: &[u8]) -> Vec<u8> {
    let mut out = vec![kind];
    out.extend(escape(payload));
    out.push(b'\r');
    out
}

/// A `D` packet: period counter (1/16 ms) and raw Tx, Ty, Tz, Rx, Ry, Rz as on the wire.
pub fn encode_d(period: u16, axes: [i16; 6]) -> Vec<u8> {
    let mut payload = period.to_be_bytes().to_vec();
    for a in axes {
        payload.extend(a.to_be_bytes());
    }
    packet(b'D', &payload)
}

/// A `.` packet (4000FLX) holding 0-based `pressed` buttons (0..=11) and the right-handed flag.
pub fn encode_dot(pressed: &[u8], right_handed: bool) -> Vec<u8> {
    let (mut first, mut second) = (0u8, 0u8);
    for &b in pressed {
        match b {
            0..=5 => second |= 1 << b,
            6 => second |= 0x80,
            7..=11 => first |= 1 << (b - 7),
            _ => {}
        }
    }
    if right_handed {
        first |= 0x20;
    }
    packet(b'.', &[first, second])
}

/// A `K` packet with its two button bytes as sent.
pub fn encode_k(payload: [u8; 2]) -> Vec<u8> {
    packet(b'K', &payload)
}

/// The reset banner: an `@1` line, then `@2 Firmware version <firmware> ...`.
pub fn encode_banner(firmware: &str) -> Vec<u8> {
    let mut out = b"@1 Spaceball alive and well after a reset.\r".to_vec();
    out.extend(format!("@2 Firmware version {firmware} created on 24-Apr-1995.\r").bytes());
    out
}
