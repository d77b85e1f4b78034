//! Byte masks (one byte per entry, 0 or 1) turned into the ascending list of the set entries'
//! indices: how the constraint pass, the contact bookkeeping and the batches pick their points
//! after a vectorised test, without a branch per entry.

/// For each 8-bit mask, the positions of its set bits, lowest first, padded with zeros, and
/// (last byte) how many there are.
const SET_BITS: [[u8; 9]; 256] = {
    let mut table = [[0u8; 9]; 256];
    let mut mask = 0;
    while mask < 256 {
        let (mut bit, mut k) = (0, 0);
        while bit < 8 {
            if mask & (1 << bit) != 0 {
                table[mask][k] = bit as u8;
                k += 1;
            }
            bit += 1;
        }
        table[mask][8] = k as u8;
        mask += 1;
    }
    table
};

/// Replaces `out` with the indices of the non-zero bytes of `mask` (whose bytes are 0 or 1),
/// in ascending order, eight bytes at a time and without a branch per hit: a multiplication
/// gathers a word's eight low bits into one byte, [`SET_BITS`] gives their positions, all eight
/// slots are written and the count advances by the number of hits. (A loop over the set bits
/// mispredicts its exit about once per word: runs are about half hits.) A length that is not
/// a multiple of 8 ends with a byte-wise tail.
pub(super) fn collect_hits(mask: &[u8], out: &mut Vec<u32>) {
    /// Moves bit `8 i` of a word to bit `56 + i`.
    const GATHER: u64 = 0x0102_0408_1020_4080;
    out.clear();
    // Room for the last word's eight slots, so no push below reallocates (and no zero fill).
    out.reserve(mask.len() + 8);
    for (w, chunk) in mask.chunks_exact(8).enumerate() {
        let word = u64::from_le_bytes([
            chunk[0], chunk[1], chunk[2], chunk[3], chunk[4], chunk[5], chunk[6], chunk[7],
        ]);
        if word == 0 {
            // Most words of a candidate run have no hit (the box filter passes about one
            // point in twelve), and they come in stretches, so this branch predicts well.
            continue;
        }
        let bits = ((word & 0x0101_0101_0101_0101).wrapping_mul(GATHER) >> 56) as usize;
        let base = 8 * w as u32;
        let set = &SET_BITS[bits];
        let keep = out.len() + usize::from(set[8]);
        out.extend_from_slice(&std::array::from_fn::<u32, 8, _>(|j| {
            base + u32::from(set[j])
        }));
        out.truncate(keep);
    }
    let tail = mask.len() - mask.len() % 8;
    for (i, &b) in mask.iter().enumerate().skip(tail) {
        if b != 0 {
            out.push(i as u32);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_noise::Noise;

    #[test]
    fn collect_hits_lists_exactly_the_set_bytes_in_order() {
        let mut noise = Noise(3);
        let mut out = Vec::new();
        for len in [0usize, 5, 8, 13, 16, 64, 200, 203] {
            for density in [0.0f32, 0.1, 0.5, 1.0] {
                let mask: Vec<u8> = (0..len)
                    .map(|_| u8::from(noise.next().abs() < density))
                    .collect();
                collect_hits(&mask, &mut out);
                let want: Vec<u32> = (0..len as u32).filter(|&i| mask[i as usize] == 1).collect();
                assert_eq!(out, want, "length {len}, density {density}");
            }
        }
        // Every pattern of one word, after a full word (so its indices carry the base 8).
        for bits in 0..256u32 {
            let mut mask = vec![1u8; 8];
            mask.extend((0..8).map(|b| u8::from(bits & (1 << b) != 0)));
            collect_hits(&mask, &mut out);
            let want: Vec<u32> = (0..16).filter(|&i| mask[i as usize] == 1).collect();
            assert_eq!(out, want, "pattern {bits:#010b}");
        }
    }
}
