//! 3Dconnexion HID reports (split and combined styles, buttons) and the length-prefixed capture
//! format `leman decode` reads.

fn put_i16(out: &mut Vec<u8>, values: &[i32]) {
    for &v in values {
        let v = v.clamp(i32::from(i16::MIN), i32::from(i16::MAX)) as i16;
        out.extend(v.to_le_bytes());
    }
}

/// Split style: report ID 1 (X, Y, Z) and report ID 2 (RX, RY, RZ), 7 bytes each. Values are
/// raw device counts in the device's frame, clamped to i16.
pub fn split_reports(raw: [i32; 6]) -> [Vec<u8>; 2] {
    let mut t = vec![1];
    put_i16(&mut t, &raw[..3]);
    let mut r = vec![2];
    put_i16(&mut r, &raw[3..]);
    [t, r]
}

/// Combined style: report ID 1 with all six axes, 13 bytes.
pub fn combined_report(raw: [i32; 6]) -> Vec<u8> {
    let mut out = vec![1];
    put_i16(&mut out, &raw);
    out
}

/// Report ID 3: a bitmap of `bytes` bytes with the 0-based `pressed` buttons set (buttons that
/// do not fit are left out).
pub fn buttons_report(pressed: &[u8], bytes: usize) -> Vec<u8> {
    let mut out = vec![0u8; 1 + bytes];
    out[0] = 3;
    for &b in pressed {
        if let Some(byte) = out.get_mut(1 + usize::from(b / 8)) {
            *byte |= 1 << (b % 8);
        }
    }
    out
}

/// The capture format of `leman decode --protocol spacemouse-hid`: each report preceded by its
/// length as one byte (reports longer than 255 bytes are cut to 255).
pub fn length_prefixed(reports: &[Vec<u8>]) -> Vec<u8> {
    let mut out = Vec::new();
    for r in reports {
        let len = r.len().min(255);
        out.push(len as u8);
        out.extend(&r[..len]);
    }
    out
}
