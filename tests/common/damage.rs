//! Random damage to a text file, shared by the file-format property tests: a number swapped
//! for an extreme value, a line deleted or repeated, the text cut short, a byte inserted.

use proptest::prelude::*;

/// Values that break naive code: zeros, signs, overflow of `f32` and the integer types, NaN
/// and the infinities, a step-sized fraction and big counts.
const NASTY: &[&str] = &[
    "0",
    "-0.0",
    "-1",
    "1",
    "0.5",
    "3",
    "1e30",
    "-1e30",
    "1e-30",
    "1e39",
    "nan",
    "inf",
    "-inf",
    "4294967296",
    "-4294967297",
    "18446744073709551616",
    "1000000",
    "\"text\"",
    "[]",
];

/// One piece of damage to a character file's text.
#[derive(Debug, Clone)]
pub enum Damage {
    /// Replaces the number at this index (modulo the count) with `NASTY[value % len]`; in
    /// the part before the file's bulk data (see [`apply`]) when `early`, anywhere otherwise.
    Number {
        index: usize,
        value: usize,
        early: bool,
    },
    /// Deletes the line at this index (modulo the count).
    DeleteLine(usize),
    /// Repeats the line at this index (modulo the count).
    RepeatLine(usize),
    /// Keeps this fraction of the bytes, in thousandths.
    Truncate(u16),
    /// Inserts a byte at this position (modulo the length).
    InsertByte { at: usize, byte: u8 },
}

pub fn damage() -> impl Strategy<Value = Damage> {
    prop_oneof![
        6 => (any::<usize>(), any::<usize>(), any::<bool>())
            .prop_map(|(index, value, early)| Damage::Number { index, value, early }),
        1 => any::<usize>().prop_map(Damage::DeleteLine),
        1 => any::<usize>().prop_map(Damage::RepeatLine),
        1 => (0u16..1000).prop_map(Damage::Truncate),
        1 => (any::<usize>(), any::<u8>()).prop_map(|(at, byte)| Damage::InsertByte { at, byte }),
    ]
}

/// Byte ranges of the numeric literals in `text` (a digit, optionally after a sign, and the
/// digits, dots, exponents and signs that follow).
pub fn number_spans(text: &[u8]) -> Vec<(usize, usize)> {
    let mut spans = Vec::new();
    let mut i = 0;
    while i < text.len() {
        let starts_number = text[i].is_ascii_digit()
            || (matches!(text[i], b'-' | b'+') && text.get(i + 1).is_some_and(u8::is_ascii_digit));
        let after_word = i > 0 && (text[i - 1].is_ascii_alphanumeric() || text[i - 1] == b'_');
        if starts_number && !after_word {
            let begin = i;
            i += 1;
            while i < text.len()
                && (text[i].is_ascii_digit() || matches!(text[i], b'.' | b'e' | b'E' | b'-' | b'+'))
            {
                i += 1;
            }
            spans.push((begin, i));
        } else {
            i += 1;
        }
    }
    spans
}

/// Where `needle` first occurs in `haystack`.
pub fn find(haystack: &[u8], needle: &[u8]) -> Option<usize> {
    haystack.windows(needle.len()).position(|w| w == needle)
}

/// Applies `d` to `text`; `bulk` marks where the file's bulk data begins (numbers chosen
/// `early` come from before it), e.g. the line of a character's skin table.
pub fn apply(text: &mut Vec<u8>, d: &Damage, bulk: &[u8]) {
    match *d {
        Damage::Number {
            index,
            value,
            early,
        } => {
            let mut spans = number_spans(text);
            if early {
                let end = find(text, bulk).unwrap_or(text.len());
                spans.retain(|&(a, _)| a < end);
            }
            if let Some(&(a, b)) = spans.get(index % spans.len().max(1)) {
                text.splice(a..b, NASTY[value % NASTY.len()].bytes());
            }
        }
        Damage::DeleteLine(k) | Damage::RepeatLine(k) => {
            let starts: Vec<usize> = std::iter::once(0)
                .chain(
                    text.iter()
                        .enumerate()
                        .filter(|(_, c)| **c == b'\n')
                        .map(|(i, _)| i + 1),
                )
                .filter(|&i| i < text.len())
                .collect();
            if starts.is_empty() {
                return;
            }
            let line = k % starts.len();
            let a = starts[line];
            let b = starts.get(line + 1).copied().unwrap_or(text.len());
            if matches!(d, Damage::DeleteLine(_)) {
                text.drain(a..b);
            } else {
                let copy: Vec<u8> = text[a..b].to_vec();
                text.splice(a..a, copy);
            }
        }
        Damage::Truncate(per_mille) => {
            let keep = text.len() * per_mille as usize / 1000;
            text.truncate(keep);
        }
        Damage::InsertByte { at, byte } => {
            let at = at % (text.len() + 1);
            text.insert(at, byte);
        }
    }
}

/// `text` with every damage in `damages` applied in turn (`bulk` as for [`apply`]).
pub fn damaged(mut text: Vec<u8>, damages: &[Damage], bulk: &[u8]) -> Vec<u8> {
    for d in damages {
        apply(&mut text, d, bulk);
    }
    text
}
