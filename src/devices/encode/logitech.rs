//! Logitech 3D Mouse / Head Tracker 16-byte reports.

use crate::devices::logitech::{REPORT_LEN, flags};

/// One report: `flag_bits` (fringe, out of range, stand, suspend, buttons; bit 7 is set here),
/// positions in 1/1000 inch (21-bit two's complement; clamped), angles pitch, yaw, roll in
/// counts (40 per degree; 14 bits kept).
pub fn report(
    flag_bits: u8,
    position_counts: [i32; 3],
    angle_counts: [u16; 3],
) -> [u8; REPORT_LEN] {
    let mut out = [0u8; REPORT_LEN];
    out[0] = flags::HEADER | (flag_bits & 0x7F);
    for (i, p) in position_counts.into_iter().enumerate() {
        let v = (p.clamp(-(1 << 20), (1 << 20) - 1) as u32) & 0x1F_FFFF;
        out[1 + 3 * i] = ((v >> 14) & 0x7F) as u8;
        out[2 + 3 * i] = ((v >> 7) & 0x7F) as u8;
        out[3 + 3 * i] = (v & 0x7F) as u8;
    }
    for (i, a) in angle_counts.into_iter().enumerate() {
        out[10 + 2 * i] = ((a >> 7) & 0x7F) as u8;
        out[11 + 2 * i] = (a & 0x7F) as u8;
    }
    out
}
