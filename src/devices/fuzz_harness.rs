//! The body of the `cargo fuzz` targets in `fuzz/` (one per protocol), kept in the library so
//! it is compiled and unit-tested with everything else; the targets only call [`fuzz_decoder`].

use super::decoder::Decoder;
use super::protocol::{Framing, Protocol, decoder_for};
use super::sample::DeviceEvent;

/// Merges consecutive [`DeviceEvent::Dropped`] events. Decoders report drops at the end of each
/// read, so merged event lists do not depend on how the bytes were chunked.
pub fn merge_drops(events: Vec<DeviceEvent>) -> Vec<DeviceEvent> {
    let mut out: Vec<DeviceEvent> = Vec::with_capacity(events.len());
    for e in events {
        if let (DeviceEvent::Dropped { bytes }, Some(DeviceEvent::Dropped { bytes: last })) =
            (&e, out.last_mut())
        {
            *last = last.saturating_add(*bytes);
            continue;
        }
        out.push(e);
    }
    out
}

/// Feeds fuzz input to a fresh decoder for `protocol` and panics if an invariant breaks:
///
/// - stream protocols: `data[0]` picks a chunk size (1..=64) for the rest; the events must equal
///   those of one single read (drops merged), no more bytes may be dropped than were fed, and
///   the decoder may hold at most 256 bytes afterwards;
/// - message protocols: the rest is cut into messages, each preceded by its length byte (like
///   the `spacemouse-hid` capture format);
/// - always: every pose is valid (finite, unit quaternion) and every axis value is finite and
///   within [-1, 1].
pub fn fuzz_decoder(protocol: Protocol, data: &[u8]) {
    let Some((&first, rest)) = data.split_first() else {
        return;
    };
    let mut dec = decoder_for(protocol);
    let mut events = Vec::new();
    match protocol.framing() {
        Framing::Stream => {
            let chunk = 1 + usize::from(first % 64);
            for piece in rest.chunks(chunk) {
                dec.feed(piece, &mut events);
            }
            assert!(
                dec.pending() <= 256,
                "{protocol} holds {} bytes",
                dec.pending()
            );
            let mut whole = Vec::new();
            decoder_for(protocol).feed(rest, &mut whole);
            assert_eq!(
                merge_drops(events.clone()),
                merge_drops(whole),
                "{protocol}: chunking changed the events"
            );
        }
        Framing::Message => {
            let mut at = 0;
            while let Some(&len) = rest.get(at) {
                let end = (at + 1 + usize::from(len)).min(rest.len());
                dec.feed(&rest[at + 1..end], &mut events);
                at = end;
            }
        }
    }
    let dropped: usize = events
        .iter()
        .map(|e| match e {
            DeviceEvent::Dropped { bytes } => *bytes,
            _ => 0,
        })
        .sum();
    assert!(dropped <= rest.len(), "{protocol}: dropped more than fed");
    for e in &events {
        match e {
            DeviceEvent::Pose(p) => assert!(p.pose.is_valid(), "{protocol}: bad pose {p:?}"),
            DeviceEvent::Axes(a) => assert!(
                a.value.iter().all(|v| v.is_finite() && v.abs() <= 1.0),
                "{protocol}: bad axes {a:?}"
            ),
            _ => {}
        }
    }
}

/// Feeds `data` to `decoder` in one read and returns the events (a convenience for callers
/// that hold a whole capture).
pub fn decode_all(decoder: &mut dyn Decoder, data: &[u8]) -> Vec<DeviceEvent> {
    let mut out = Vec::new();
    decoder.feed(data, &mut out);
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::devices::encode;
    use proptest::prelude::*;

    #[test]
    fn harness_accepts_real_streams_for_every_protocol() {
        let mut stream = vec![0u8];
        stream.extend(encode::spaceball::encode_banner("2.43"));
        stream.extend(encode::spaceball::encode_d(
            0x0D11,
            [1, -2, 0x5E5E, 4, 5, 6],
        ));
        fuzz_decoder(Protocol::Spaceball, &stream);
        let mut hid = vec![0u8];
        hid.extend(encode::spacemouse_hid::length_prefixed(&[
            encode::spacemouse_hid::combined_report([1, 2, 3, 4, 5, 6]),
        ]));
        fuzz_decoder(Protocol::SpacemouseHid, &hid);
        fuzz_decoder(Protocol::Opentrack, &[]);
    }

    #[test]
    fn chunking_never_changes_events_on_real_streams_with_garbage() {
        use crate::devices::fastrak::{FastrakFormat, FastrakSettings};
        let fs = FastrakSettings::default();
        let rec = encode::fastrak::FastrakRecord {
            station: 1,
            status: b' ',
            position: [1.0, 2.0, 3.0],
            euler_deg: [4.0, 5.0, 6.0],
            quaternion: [1.0, 0.0, 0.0, 0.0],
            stylus: false,
        };
        let streams: Vec<(Protocol, Vec<u8>)> = vec![
            (
                Protocol::FastrakAscii,
                encode::fastrak::encode_record(FastrakFormat::Ascii, &fs, &rec),
            ),
            (
                Protocol::FastrakBinary,
                encode::fastrak::encode_record(FastrakFormat::Binary, &fs, &rec),
            ),
            (
                Protocol::Spaceball,
                encode::spaceball::encode_d(0x0D0D, [1, 2, 0x5E11, 4, 5, 6]),
            ),
            (
                Protocol::Magellan,
                encode::magellan::encode_d([1, -2, 3, -4, 5, -6]),
            ),
            (
                Protocol::Logitech,
                encode::logitech::report(0, [1, -2, 3], [4, 5, 6]).to_vec(),
            ),
        ];
        for (protocol, packet) in streams {
            let mut data = b"\x00garbage\r0".to_vec();
            for _ in 0..3 {
                data.extend(&packet);
                data.extend(b"\xff\x80x");
            }
            data.extend(&packet[..packet.len() / 2]);
            for chunk_selector in 0..64u8 {
                let mut input = vec![chunk_selector];
                input.extend(&data);
                fuzz_decoder(protocol, &input);
            }
            // And the packets were really decoded (the check above is not vacuous).
            let events = decode_all(decoder_for(protocol).as_mut(), &data);
            let measurements = events
                .iter()
                .filter(|e| matches!(e, DeviceEvent::Pose(_) | DeviceEvent::Axes(_)))
                .count();
            assert_eq!(measurements, 3, "{protocol}: {events:?}");
        }
    }

    proptest! {
        #[test]
        fn harness_holds_on_arbitrary_input(data in proptest::collection::vec(any::<u8>(), 0..400)) {
            for p in Protocol::ALL {
                fuzz_decoder(p, &data);
            }
        }
    }
}
