//! OpenTrack UDP datagrams.

use crate::devices::opentrack::DATAGRAM_LEN;

/// One datagram: X, Y, Z (cm), yaw, pitch, roll (degrees) as little-endian f64.
pub fn datagram(values: [f64; 6]) -> [u8; DATAGRAM_LEN] {
    let mut out = [0u8; DATAGRAM_LEN];
    for (chunk, v) in out.chunks_exact_mut(8).zip(values) {
        chunk.copy_from_slice(&v.to_le_bytes());
    }
    out
}
