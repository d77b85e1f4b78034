//! Magellan packets: nibble-encoded `d` axes and `k` buttons, the version reply.

use crate::devices::magellan::NIBBLE_CHARS;

fn nibble_char(v: u32) -> u8 {
    NIBBLE_CHARS[(v & 0xF) as usize]
}

/// A `d` packet from raw axes X, Y, Z, A, B, C (each clamped to -32768..=32767, sent as
/// value + 32768).
pub fn encode_d(raw: [i32; 6]) -> Vec<u8> {
    let mut out = vec![b'd'];
    for r in raw {
        let v = (r.clamp(-32768, 32767) + 32768) as u32;
        for shift in [12, 8, 4, 0] {
            out.push(nibble_char(v >> shift));
        }
    }
    out.push(b'\r');
    out
}

/// A `k` packet with `chars` (3 or 4) characters holding 0-based `pressed` buttons; buttons
/// that do not fit are left out.
pub fn encode_k(pressed: &[u8], chars: usize) -> Vec<u8> {
    let chars = chars.clamp(3, 4);
    let mut bits: u32 = 0;
    for &b in pressed {
        if usize::from(b) < 4 * chars {
            bits |= 1 << b;
        }
    }
    let mut out = vec![b'k'];
    for i in 0..chars {
        out.push(nibble_char(bits >> (4 * i)));
    }
    out.push(b'\r');
    out
}

/// The reply to `vQ`.
pub fn encode_version() -> Vec<u8> {
    b"v  MAGELLAN  Version 6.60  3Dconnexion GmbH 05/11/01\r".to_vec()
}
