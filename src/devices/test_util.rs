//! Helpers shared by the decoder tests (compiled only for tests).

use super::decoder::Decoder;
use super::sample::{AxesSample, DeviceEvent, PoseSample};

/// Feeds `bytes` in one call and returns the events.
pub(crate) fn feed_all<D: Decoder + ?Sized>(dec: &mut D, bytes: &[u8]) -> Vec<DeviceEvent> {
    let mut out = Vec::new();
    dec.feed(bytes, &mut out);
    out
}

/// The poses among `events`.
pub(crate) fn poses(events: &[DeviceEvent]) -> Vec<PoseSample> {
    events
        .iter()
        .filter_map(|e| match e {
            DeviceEvent::Pose(p) => Some(p.clone()),
            _ => None,
        })
        .collect()
}

/// The axes samples among `events`.
pub(crate) fn axes(events: &[DeviceEvent]) -> Vec<AxesSample> {
    events
        .iter()
        .filter_map(|e| match e {
            DeviceEvent::Axes(a) => Some(a.clone()),
            _ => None,
        })
        .collect()
}

/// The button sets among `events`.
pub(crate) fn buttons(events: &[DeviceEvent]) -> Vec<Vec<u8>> {
    events
        .iter()
        .filter_map(|e| match e {
            DeviceEvent::Buttons { pressed } => Some(pressed.clone()),
            _ => None,
        })
        .collect()
}

/// Total bytes reported dropped.
pub(crate) fn dropped(events: &[DeviceEvent]) -> usize {
    events
        .iter()
        .map(|e| match e {
            DeviceEvent::Dropped { bytes } => *bytes,
            _ => 0,
        })
        .sum()
}

/// Splits `bytes` at every possible point into two reads (each with a fresh decoder) and checks
/// that the events are exactly those of one read; returns those. (Drops included: decoders
/// flush them with the next event or at the end of a read, so where a split falls can show.)
pub(crate) fn assert_split_anywhere_same(
    make: impl Fn() -> Box<dyn Decoder>,
    bytes: &[u8],
) -> Vec<DeviceEvent> {
    let whole = feed_all(make().as_mut(), bytes);
    for k in 0..=bytes.len() {
        let mut dec = make();
        let mut out = Vec::new();
        dec.feed(&bytes[..k], &mut out);
        dec.feed(&bytes[k..], &mut out);
        assert_eq!(out, whole, "split at {k} of {}", bytes.len());
    }
    whole
}

/// [`assert_split_anywhere_same`] for a clean stream: one read gives `expected` events and no
/// drops.
pub(crate) fn assert_every_split(
    make: impl Fn() -> Box<dyn Decoder>,
    bytes: &[u8],
    expected: usize,
) {
    let whole = assert_split_anywhere_same(make, bytes);
    assert_eq!(whole.len(), expected, "one read: {whole:?}");
    assert_eq!(dropped(&whole), 0, "one read dropped bytes: {whole:?}");
}
