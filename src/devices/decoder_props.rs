//! Property tests over every decoder: arbitrary bytes in arbitrary fragments never panic and
//! never report more bytes dropped than went in; valid packets after arbitrary garbage are
//! still found with their values.

use super::decoder::Decoder;
use super::encode;
use super::fastrak::{FastrakDecoder, FastrakFormat, FastrakSettings};
use super::logitech::LogitechDecoder;
use super::magellan::MagellanDecoder;
use super::opentrack::OpentrackDecoder;
use super::protocol::{Framing, Protocol, decoder_for};
use super::sample::DeviceEvent;
use super::spaceball::SpaceballDecoder;
use super::spacemouse_hid::SpacemouseHidDecoder;
use super::test_util::{axes, dropped, poses};
use proptest::prelude::*;

/// Feeds `bytes` split at the given cut points (sorted, deduplicated, in range).
fn feed_split(dec: &mut dyn Decoder, bytes: &[u8], cuts: &[usize]) -> Vec<DeviceEvent> {
    let mut cuts: Vec<usize> = cuts.iter().map(|c| c % (bytes.len() + 1)).collect();
    cuts.sort_unstable();
    cuts.dedup();
    let mut out = Vec::new();
    let mut at = 0;
    for c in cuts.into_iter().chain([bytes.len()]) {
        dec.feed(&bytes[at..c], &mut out);
        at = c;
    }
    out
}

fn no_non_finite(events: &[DeviceEvent]) -> bool {
    events.iter().all(|e| match e {
        DeviceEvent::Pose(p) => p.pose.is_valid(),
        DeviceEvent::Axes(a) => a.value.iter().all(|v| v.is_finite() && v.abs() <= 1.0),
        _ => true,
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(crate::proptest_cases::cases_or(256)))]

    #[test]
    fn arbitrary_bytes_never_panic_and_stay_accounted(
        bytes in proptest::collection::vec(any::<u8>(), 0..600),
        cuts in proptest::collection::vec(any::<usize>(), 0..8),
    ) {
        for protocol in Protocol::ALL {
            let mut dec = decoder_for(protocol);
            let events = match protocol.framing() {
                Framing::Stream => feed_split(dec.as_mut(), &bytes, &cuts),
                Framing::Message => {
                    // Arbitrary message boundaries.
                    feed_split(dec.as_mut(), &bytes, &cuts)
                }
            };
            prop_assert!(no_non_finite(&events), "{protocol}: {events:?}");
            prop_assert!(dropped(&events) <= bytes.len(), "{protocol}");
            if protocol.framing() == Framing::Stream {
                prop_assert!(dec.pending() <= 256, "{protocol} holds {}", dec.pending());
            }
        }
    }

    #[test]
    fn fastrak_finds_records_after_garbage(
        garbage in proptest::collection::vec(any::<u8>(), 0..200),
        pos in proptest::array::uniform3(-99.0f64..99.0),
        euler in proptest::array::uniform3(-179.0f64..179.0),
        binary in any::<bool>(),
        cut in any::<usize>(),
    ) {
        let format = if binary { FastrakFormat::Binary } else { FastrakFormat::Ascii };
        let s = FastrakSettings::default();
        let record = encode::fastrak::FastrakRecord {
            station: 2, status: b' ', position: pos, euler_deg: euler,
            quaternion: [1.0, 0.0, 0.0, 0.0], stylus: false,
        };
        let one = encode::fastrak::encode_record(format, &s, &record);
        let mut bytes = garbage.clone();
        for _ in 0..3 { bytes.extend(&one); }
        let events = feed_split(&mut FastrakDecoder::with_defaults(format), &bytes, &[cut]);
        // Garbage may itself hold a valid record by chance: the last three must be ours.
        let p = poses(&events);
        prop_assert!(p.len() >= 3, "{:?}", events);
        for sample in &p[p.len() - 3..] {
            for (got, want) in sample.raw_position.iter().zip(pos) {
                prop_assert!((got - want).abs() < 0.006);
            }
        }
        prop_assert!(dropped(&events) <= garbage.len());
    }

    #[test]
    fn fastrak_any_output_list_survives_garbage(
        items in proptest::collection::vec(proptest::sample::select(vec![0u8, 1, 2, 4, 11, 16]), 1..8),
        stylus_bytes in 1u8..=2,
        binary in any::<bool>(),
        garbage in proptest::collection::vec(any::<u8>(), 0..300),
        cut in any::<usize>(),
    ) {
        let format = if binary { FastrakFormat::Binary } else { FastrakFormat::Ascii };
        let mut items = items;
        items.push(1); // records end with CR LF, as every real configuration does
        let settings = FastrakSettings { items, stylus_bytes, ..FastrakSettings::default() };
        let make = || FastrakDecoder::new(format, settings.clone());
        let mut dec = make().map_err(|e| TestCaseError::fail(e.to_string()))?;
        let events = feed_split(&mut dec, &garbage, &[cut]);
        prop_assert!(no_non_finite(&events));
        let record = encode::fastrak::FastrakRecord {
            station: 4, status: b' ', position: [1.0, -2.0, 3.0], euler_deg: [10.0, 20.0, 30.0],
            quaternion: [1.0, 0.0, 0.0, 0.0], stylus: true,
        };
        let one = encode::fastrak::encode_record(format, &settings, &record);
        let mut bytes = garbage.clone();
        for _ in 0..3 { bytes.extend(&one); }
        let mut dec = make().map_err(|e| TestCaseError::fail(e.to_string()))?;
        let events = feed_split(&mut dec, &bytes, &[cut]);
        let p = poses(&events);
        prop_assert!(p.len() >= 3, "{:?}", events);
        prop_assert!(p[p.len() - 3..].iter().all(|s| s.station == 4));
    }

    #[test]
    fn spaceball_finds_packets_after_garbage(
        garbage in proptest::collection::vec(any::<u8>(), 0..200),
        raw in proptest::array::uniform6(any::<i16>()),
        cut in any::<usize>(),
    ) {
        let mut bytes = garbage.clone();
        for _ in 0..3 { bytes.extend(encode::spaceball::encode_d(0x0D11, raw)); }
        let events = feed_split(&mut SpaceballDecoder::new(), &bytes, &[cut]);
        let a = axes(&events);
        prop_assert!(a.len() >= 3, "{:?}", events);
        prop_assert!(a[a.len() - 3..].iter().all(|s| s.raw == raw.map(i32::from)));
    }

    #[test]
    fn magellan_finds_packets_after_garbage(
        garbage in proptest::collection::vec(any::<u8>(), 0..200),
        raw in proptest::array::uniform6(-32768i32..32768),
        cut in any::<usize>(),
    ) {
        let mut bytes = garbage.clone();
        for _ in 0..3 { bytes.extend(encode::magellan::encode_d(raw)); }
        let events = feed_split(&mut MagellanDecoder::new(), &bytes, &[cut]);
        let a = axes(&events);
        prop_assert!(a.len() >= 3, "{:?}", events);
        prop_assert!(a[a.len() - 3..].iter().all(|s| s.raw == raw));
    }

    #[test]
    fn logitech_finds_reports_after_garbage(
        garbage in proptest::collection::vec(any::<u8>(), 0..200),
        pos in proptest::array::uniform3(-(1i32 << 20)..(1 << 20)),
        ang in proptest::array::uniform3(0u16..16384),
        cut in any::<usize>(),
    ) {
        let mut bytes = garbage.clone();
        for _ in 0..3 { bytes.extend(encode::logitech::report(0, pos, ang)); }
        let events = feed_split(&mut LogitechDecoder::new(), &bytes, &[cut]);
        let p = poses(&events);
        prop_assert!(p.len() >= 3, "{:?}", events);
        prop_assert!(p[p.len() - 3..].iter().all(|s| s.raw_position == pos.map(f64::from)));
        prop_assert!(dropped(&events) <= garbage.len());
    }

    #[test]
    fn hid_finds_reports_after_garbage_reports(
        garbage in proptest::collection::vec(proptest::collection::vec(any::<u8>(), 0..20), 0..10),
        raw in proptest::array::uniform6(any::<i16>()),
        combined in any::<bool>(),
    ) {
        let mut dec = SpacemouseHidDecoder::new();
        let mut out = Vec::new();
        for g in &garbage { dec.feed(g, &mut out); }
        let raw = raw.map(i32::from);
        out.clear();
        if combined {
            dec.feed(&encode::spacemouse_hid::combined_report(raw), &mut out);
        } else {
            for r in encode::spacemouse_hid::split_reports(raw) { dec.feed(&r, &mut out); }
        }
        let a = axes(&out);
        prop_assert_eq!(a.last().map(|s| s.raw), Some(raw));
    }

    #[test]
    fn opentrack_finds_datagrams_after_garbage_datagrams(
        garbage in proptest::collection::vec(proptest::collection::vec(any::<u8>(), 0..100), 0..10),
        values in proptest::array::uniform6(-1000.0f64..1000.0),
    ) {
        let mut dec = OpentrackDecoder::new();
        let mut out = Vec::new();
        for g in &garbage { dec.feed(g, &mut out); }
        prop_assert!(no_non_finite(&out));
        out.clear();
        dec.feed(&encode::opentrack::datagram(values), &mut out);
        let p = poses(&out);
        prop_assert_eq!(p.len(), 1);
        prop_assert_eq!(p[0].raw_position, [values[0], values[1], values[2]]);
    }
}
