//! Polhemus FASTRAK records (ASCII `F` and binary `f` modes) -> [`PoseSample`]s.
//!
//! # Record layout
//! Byte 1 is `'0'`, byte 2 the station `'1'..='4'`, byte 3 the status (space when healthy, a
//! letter otherwise), then the items of the output list (`O` command) in order:
//!
//! | item | meaning | ASCII bytes | binary bytes |
//! | --- | --- | --- | --- |
//! | 0 | space | 1 | 1 |
//! | 1 | CR LF | 2 | 2 |
//! | 2 | position x, y, z | 3 × 7 (`Sxxx.xx`) | 3 × f32 LE |
//! | 4 | Euler azimuth, elevation, roll (degrees) | 3 × 7 | 3 × f32 LE |
//! | 11 | quaternion q0 (scalar), q1, q2, q3 | 4 × 7 (`Sx.xxxx`) | 4 × f32 LE |
//! | 16 | stylus switch | `stylus_bytes` | `stylus_bytes` |
//!
//! The stylus item is 1 or 2 bytes ([`FastrakSettings::stylus_bytes`], default 2 as Vrui and
//! VRPN read it); its last byte is the switch state, `'0'`/`'1'` (or 0/1). The same width is used
//! in ASCII mode. One output list applies to every station.
//!
//! The `S` status record (55 bytes, `'2'`, station, `'S'`, ..., CR LF) becomes a
//! [`StatusEvent::Report`] holding its text.
//!
//! # Resynchronisation
//! The decoder looks for `'0'`, a station digit and a space or letter (or `'2'`, a station digit,
//! `'S'`), waits for the whole record and checks every item: spaces are spaces, CR LF is CR LF,
//! ASCII fields are numbers, binary values are finite and plausible (|position| ≤ 1000 units,
//! |angle| ≤ 360.5°, quaternion length within 5% of 1). A record that fails loses its first byte
//! and the scan goes on; everything skipped is reported as [`DeviceEvent::Dropped`]. A status
//! header is given up as soon as a byte that cannot be in a status record arrives (its body is
//! printable up to its CR LF), not after 55 bytes: with a short output list a false one in
//! garbage would otherwise hold back several data records.
//!
//! # Units and axes
//! Positions are inches (default) or centimetres ([`LengthUnit`]), converted to metres. The
//! transmitter frame is right-handed with +X forward, +Y right and +Z down. We map it to ours
//! (+X right, +Y up, +Z toward the user) by the fixed rotation
//! `ours = (t_y, -t_z, -t_x)`: the transmitter's +X points away from the user (into the
//! screen). Orientation `R_t = Rz(azimuth)·Ry(elevation)·Rx(roll)` (or the quaternion) is
//! re-expressed as `C·R_t·Cᵀ` with the same rotation `C`, so a sensor with zero angles has the
//! identity orientation in our frame and its local axes follow the same mapping. How the
//! transmitter is mounted relative to the world is a calibration matter (`tracking`), not the
//! decoder's.

use super::decoder::{Decoder, DropTally};
use super::sample::{DeviceEvent, PoseSample, RawOrientation, StatusEvent};
use crate::pose::Pose;
use glam::{DMat3, DQuat, DVec3, EulerRot};
use serde::{Deserialize, Serialize};

/// ASCII or binary records.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FastrakFormat {
    /// `F`: ASCII numbers in fixed-width fields.
    #[default]
    Ascii,
    /// `f`: IEEE-754 f32 little-endian values.
    Binary,
}

/// The unit positions are sent in (`U` inches, `u` centimetres).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LengthUnit {
    /// Inches (the device's default).
    #[default]
    Inches,
    /// Centimetres.
    Centimetres,
}

impl LengthUnit {
    /// Metres per unit.
    pub fn metres(self) -> f64 {
        match self {
            LengthUnit::Inches => 0.0254,
            LengthUnit::Centimetres => 0.01,
        }
    }
}

/// What the FASTRAK was told to send.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default)]
pub struct FastrakSettings {
    /// The output list (items 0, 1, 2, 4, 11, 16; at most 32). Default `[2, 4, 1]`.
    pub items: Vec<u8>,
    /// Position unit. Default inches.
    pub units: LengthUnit,
    /// Width of the stylus item (16): 1 or 2 bytes. Default 2.
    pub stylus_bytes: u8,
}

impl Default for FastrakSettings {
    fn default() -> Self {
        Self {
            items: vec![2, 4, 1],
            units: LengthUnit::Inches,
            stylus_bytes: 2,
        }
    }
}

/// Settings that cannot describe a record.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FastrakSettingsError {
    /// An output-list item this decoder does not know.
    #[error("FASTRAK output item {0} is not supported (use 0, 1, 2, 4, 11, 16)")]
    UnknownItem(u8),
    /// More than 32 items.
    #[error("FASTRAK output list has {0} items (at most 32)")]
    TooManyItems(usize),
    /// Empty output list.
    #[error("FASTRAK output list is empty")]
    Empty,
    /// Stylus width other than 1 or 2.
    #[error("FASTRAK stylus item width must be 1 or 2 bytes, not {0}")]
    StylusBytes(u8),
}

/// One output-list item.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FastrakItem {
    /// 0: a space.
    Space,
    /// 1: CR LF.
    CrLf,
    /// 2: position x, y, z.
    Position,
    /// 4: Euler azimuth, elevation, roll.
    Euler,
    /// 11: quaternion, scalar first.
    Quaternion,
    /// 16: stylus switch.
    Stylus,
}

impl FastrakItem {
    /// The item for an output-list number.
    pub fn from_number(n: u8) -> Option<Self> {
        Some(match n {
            0 => FastrakItem::Space,
            1 => FastrakItem::CrLf,
            2 => FastrakItem::Position,
            4 => FastrakItem::Euler,
            11 => FastrakItem::Quaternion,
            16 => FastrakItem::Stylus,
            _ => return None,
        })
    }

    /// Bytes this item takes in a record.
    pub fn len(self, format: FastrakFormat, stylus_bytes: u8) -> usize {
        match (self, format) {
            (FastrakItem::Space, _) => 1,
            (FastrakItem::CrLf, _) => 2,
            (FastrakItem::Position | FastrakItem::Euler, FastrakFormat::Ascii) => 21,
            (FastrakItem::Position | FastrakItem::Euler, FastrakFormat::Binary) => 12,
            (FastrakItem::Quaternion, FastrakFormat::Ascii) => 28,
            (FastrakItem::Quaternion, FastrakFormat::Binary) => 16,
            (FastrakItem::Stylus, _) => usize::from(stylus_bytes),
        }
    }
}

impl FastrakSettings {
    /// The validated item list.
    pub fn parsed_items(&self) -> Result<Vec<FastrakItem>, FastrakSettingsError> {
        if self.items.is_empty() {
            return Err(FastrakSettingsError::Empty);
        }
        if self.items.len() > 32 {
            return Err(FastrakSettingsError::TooManyItems(self.items.len()));
        }
        if !(1..=2).contains(&self.stylus_bytes) {
            return Err(FastrakSettingsError::StylusBytes(self.stylus_bytes));
        }
        self.items
            .iter()
            .map(|&n| FastrakItem::from_number(n).ok_or(FastrakSettingsError::UnknownItem(n)))
            .collect()
    }

    /// Length of one data record in `format`, or an error for bad settings.
    pub fn record_len(&self, format: FastrakFormat) -> Result<usize, FastrakSettingsError> {
        Ok(3 + self
            .parsed_items()?
            .iter()
            .map(|i| i.len(format, self.stylus_bytes))
            .sum::<usize>())
    }
}

/// Length of the `S` status record.
pub const STATUS_RECORD_LEN: usize = 55;

/// `C`: ours_from_transmitter, a proper rotation (+X fwd, +Y right, +Z down -> +X right, +Y up,
/// +Z toward the user).
fn ours_from_transmitter() -> DMat3 {
    DMat3::from_cols(
        DVec3::new(0.0, 0.0, -1.0),
        DVec3::new(1.0, 0.0, 0.0),
        DVec3::new(0.0, -1.0, 0.0),
    )
}

/// A position in the transmitter frame (device units) -> metres in our frame.
pub fn position_m_from_raw(raw: [f64; 3], units: LengthUnit) -> DVec3 {
    ours_from_transmitter() * (DVec3::from_array(raw) * units.metres())
}

/// Metres in our frame -> a position in the transmitter frame (device units). Inverse of
/// [`position_m_from_raw`].
pub fn raw_from_position_m(p: DVec3, units: LengthUnit) -> [f64; 3] {
    (ours_from_transmitter().transpose() * p / units.metres()).to_array()
}

/// A rotation in the transmitter frame -> the same rotation in ours (`C·R·Cᵀ`).
fn ours_from_transmitter_rotation(q_t: DQuat) -> DQuat {
    let c = DQuat::from_mat3(&ours_from_transmitter());
    (c * q_t * c.conjugate()).normalize()
}

/// Euler azimuth, elevation, roll (degrees; `Rz·Ry·Rx` in the transmitter frame) -> our
/// orientation.
pub fn orientation_from_euler_deg(euler_deg: [f64; 3]) -> DQuat {
    let [az, el, roll] = euler_deg.map(f64::to_radians);
    ours_from_transmitter_rotation(DQuat::from_euler(EulerRot::ZYX, az, el, roll))
}

/// Our orientation -> Euler azimuth, elevation, roll in degrees. Inverse of
/// [`orientation_from_euler_deg`] (elevation in [-90, 90]).
pub fn euler_deg_from_orientation(q: DQuat) -> [f64; 3] {
    let c = DQuat::from_mat3(&ours_from_transmitter());
    let q_t = c.conjugate() * q * c;
    let (az, el, roll) = q_t.to_euler(EulerRot::ZYX);
    [az, el, roll].map(f64::to_degrees)
}

/// A FASTRAK quaternion (q0 scalar, q1, q2, q3 in the transmitter frame) -> our orientation.
pub fn orientation_from_quaternion(q: [f64; 4]) -> DQuat {
    ours_from_transmitter_rotation(DQuat::from_xyzw(q[1], q[2], q[3], q[0]).normalize())
}

/// Our orientation -> the FASTRAK quaternion (q0 scalar first), with q0 ≥ 0.
pub fn quaternion_from_orientation(q: DQuat) -> [f64; 4] {
    let c = DQuat::from_mat3(&ours_from_transmitter());
    let mut q_t = (c.conjugate() * q * c).normalize();
    if q_t.w < 0.0 {
        q_t = -q_t;
    }
    [q_t.w, q_t.x, q_t.y, q_t.z]
}

/// Streaming FASTRAK decoder.
#[derive(Debug, Clone)]
pub struct FastrakDecoder {
    format: FastrakFormat,
    settings: FastrakSettings,
    items: Vec<FastrakItem>,
    record_len: usize,
    buf: Vec<u8>,
    drops: DropTally,
}

/// What a candidate record start looks like.
enum Header {
    Invalid,
    NeedMore,
    Data,
    Status,
}

fn is_station(b: u8) -> bool {
    (b'1'..=b'4').contains(&b)
}

fn header_at(bytes: &[u8]) -> Header {
    match bytes {
        [] => Header::NeedMore,
        [b'0'] | [b'2'] => Header::NeedMore,
        [b'0', s] | [b'2', s] if is_station(*s) => Header::NeedMore,
        [b'0', s, st, ..] if is_station(*s) && (*st == b' ' || st.is_ascii_alphabetic()) => {
            Header::Data
        }
        [b'2', s, b'S', ..] if is_station(*s) => Header::Status,
        _ => Header::Invalid,
    }
}

/// Whether `bytes` (a status header and what has arrived after it, any length) can still be the
/// start of a status record: its body is printable ASCII or spaces up to the closing CR LF at
/// bytes 54-55. A byte that breaks this rejects a false header at once, so the records behind
/// it are not held back until 55 bytes have arrived (short output lists fit several records in
/// that).
fn status_so_far(bytes: &[u8]) -> bool {
    let body = STATUS_RECORD_LEN - 2;
    let printable = |b: &u8| b.is_ascii_graphic() || *b == b' ';
    bytes.iter().take(body).all(printable)
        && bytes
            .iter()
            .skip(body)
            .take(2)
            .zip(b"\r\n")
            .all(|(b, want)| b == want)
}

/// Parses one fixed-width ASCII number field (sign `-`, `+` or space, digits, one point).
fn ascii_number(field: &[u8]) -> Option<f64> {
    if !field
        .iter()
        .all(|b| b.is_ascii_digit() || matches!(b, b' ' | b'-' | b'+' | b'.'))
    {
        return None;
    }
    let text = std::str::from_utf8(field).ok()?.trim_start();
    // An embedded space ("- 1.00") or an empty field is not a number.
    if text.is_empty() || text.contains(' ') {
        return None;
    }
    let v: f64 = text.parse().ok()?;
    v.is_finite().then_some(v)
}

fn f32_le(bytes: &[u8]) -> Option<f64> {
    let arr: [u8; 4] = bytes.try_into().ok()?;
    let v = f64::from(f32::from_le_bytes(arr));
    v.is_finite().then_some(v)
}

/// Reads `N` values of one item.
fn values<const N: usize>(field: &[u8], format: FastrakFormat) -> Option<[f64; N]> {
    let width = match format {
        FastrakFormat::Ascii => 7,
        FastrakFormat::Binary => 4,
    };
    let mut out = [0.0; N];
    for (i, v) in out.iter_mut().enumerate() {
        let chunk = field.get(i * width..(i + 1) * width)?;
        *v = match format {
            FastrakFormat::Ascii => ascii_number(chunk)?,
            FastrakFormat::Binary => f32_le(chunk)?,
        };
    }
    Some(out)
}

impl FastrakDecoder {
    /// A decoder for `format` with validated settings.
    pub fn new(
        format: FastrakFormat,
        settings: FastrakSettings,
    ) -> Result<Self, FastrakSettingsError> {
        let items = settings.parsed_items()?;
        let record_len = settings.record_len(format)?;
        Ok(Self {
            format,
            settings,
            items,
            record_len,
            buf: Vec::with_capacity(2 * STATUS_RECORD_LEN.max(record_len)),
            drops: DropTally::default(),
        })
    }

    /// A decoder with the device's default output list (`2,4,1`), inches and a 2-byte stylus.
    pub fn with_defaults(format: FastrakFormat) -> Self {
        let settings = FastrakSettings::default();
        let items = vec![FastrakItem::Position, FastrakItem::Euler, FastrakItem::CrLf];
        let record_len = match format {
            FastrakFormat::Ascii => 47,
            FastrakFormat::Binary => 29,
        };
        Self {
            format,
            settings,
            items,
            record_len,
            buf: Vec::with_capacity(2 * STATUS_RECORD_LEN),
            drops: DropTally::default(),
        }
    }

    /// Length of one data record with these settings.
    pub fn record_len(&self) -> usize {
        self.record_len
    }

    /// Parses one complete data record (`rec.len() == record_len`), or `None` if it is not one.
    fn parse_record(&self, rec: &[u8]) -> Option<PoseSample> {
        let station = rec.first().copied().zip(rec.get(1).copied())?.1 - b'0';
        let status_byte = *rec.get(2)?;
        let mut at = 3;
        let mut position = None;
        let mut euler = None;
        let mut quat = None;
        let mut stylus = None;
        for item in &self.items {
            let len = item.len(self.format, self.settings.stylus_bytes);
            let field = rec.get(at..at + len)?;
            at += len;
            match item {
                FastrakItem::Space => (field == b" ").then_some(())?,
                FastrakItem::CrLf => (field == b"\r\n").then_some(())?,
                FastrakItem::Position => {
                    let p = values::<3>(field, self.format)?;
                    p.iter().all(|v| v.abs() <= 1000.0).then_some(())?;
                    position = Some(p);
                }
                FastrakItem::Euler => {
                    let e = values::<3>(field, self.format)?;
                    e.iter().all(|v| v.abs() <= 360.5).then_some(())?;
                    euler = Some(e);
                }
                FastrakItem::Quaternion => {
                    let q = values::<4>(field, self.format)?;
                    let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
                    (0.95..=1.05).contains(&norm).then_some(())?;
                    quat = Some(q);
                }
                FastrakItem::Stylus => {
                    stylus = Some(match field.last()? {
                        b'0' | 0 => false,
                        b'1' | 1 => true,
                        _ => return None,
                    });
                }
            }
        }
        let raw_position = position.unwrap_or([0.0; 3]);
        let (orientation, raw_orientation) = match (quat, euler) {
            (Some(q), _) => (
                orientation_from_quaternion(q),
                RawOrientation::Quaternion(q),
            ),
            (None, Some(e)) => (orientation_from_euler_deg(e), RawOrientation::EulerDeg(e)),
            (None, None) => (DQuat::IDENTITY, RawOrientation::EulerDeg([0.0; 3])),
        };
        let pose = Pose::new(
            position_m_from_raw(raw_position, self.settings.units).as_vec3(),
            orientation.as_quat().normalize(),
        );
        pose.is_valid().then_some(())?;
        Some(PoseSample {
            station,
            pose,
            raw_position,
            raw_orientation,
            pressed: if stylus == Some(true) {
                vec![0]
            } else {
                vec![]
            },
            status: (status_byte != b' ').then_some(char::from(status_byte)),
        })
    }

    fn parse_status(rec: &[u8]) -> Option<StatusEvent> {
        (rec.len() == STATUS_RECORD_LEN && status_so_far(rec)).then_some(())?;
        let body = &rec[..STATUS_RECORD_LEN - 2];
        Some(StatusEvent::Report {
            text: format!(
                "FASTRAK status station {}: {}",
                char::from(rec[1]),
                String::from_utf8_lossy(&body[3..]).trim_end()
            ),
        })
    }
}

impl Decoder for FastrakDecoder {
    fn feed(&mut self, bytes: &[u8], out: &mut Vec<DeviceEvent>) {
        self.buf.extend_from_slice(bytes);
        let mut pos = 0;
        while pos < self.buf.len() {
            let rest = &self.buf[pos..];
            match header_at(rest) {
                Header::Invalid => {
                    self.drops.add(1);
                    pos += 1;
                }
                Header::NeedMore => break,
                Header::Data => {
                    if rest.len() < self.record_len {
                        break;
                    }
                    match self.parse_record(&rest[..self.record_len]) {
                        Some(sample) => {
                            self.drops.push(DeviceEvent::Pose(sample), out);
                            pos += self.record_len;
                        }
                        None => {
                            self.drops.add(1);
                            pos += 1;
                        }
                    }
                }
                Header::Status => {
                    // Wait for the whole record while what has come can still be one.
                    if rest.len() < STATUS_RECORD_LEN && status_so_far(rest) {
                        break;
                    }
                    match rest.get(..STATUS_RECORD_LEN).and_then(Self::parse_status) {
                        Some(status) => {
                            self.drops.push(DeviceEvent::Status(status), out);
                            pos += STATUS_RECORD_LEN;
                        }
                        None => {
                            self.drops.add(1);
                            pos += 1;
                        }
                    }
                }
            }
        }
        self.buf.drain(..pos);
        self.drops.flush(out);
    }

    fn reset(&mut self) {
        self.buf.clear();
        self.drops.clear();
    }

    fn pending(&self) -> usize {
        self.buf.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::devices::encode::fastrak::{FastrakRecord, encode_record, encode_status_record};
    use crate::devices::test_util::{
        assert_every_split, assert_split_anywhere_same, feed_all, poses,
    };
    use glam::Quat;

    fn record(station: u8, pos: [f64; 3], euler: [f64; 3]) -> FastrakRecord {
        FastrakRecord {
            station,
            status: b' ',
            position: pos,
            euler_deg: euler,
            quaternion: [1.0, 0.0, 0.0, 0.0],
            stylus: false,
        }
    }

    fn quat_close(a: Quat, b: Quat) -> bool {
        a.dot(b).abs() > 1.0 - 1e-5
    }

    #[test]
    fn default_record_lengths_match_the_manual() {
        let s = FastrakSettings::default();
        assert_eq!(s.record_len(FastrakFormat::Ascii), Ok(47));
        assert_eq!(s.record_len(FastrakFormat::Binary), Ok(29));
        let r = record(1, [1.0, 2.0, 3.0], [10.0, 20.0, 30.0]);
        assert_eq!(encode_record(FastrakFormat::Ascii, &s, &r).len(), 47);
        assert_eq!(encode_record(FastrakFormat::Binary, &s, &r).len(), 29);
    }

    #[test]
    fn ascii_record_decodes_with_units_and_axes() {
        let bytes = b"01   12.00  -3.50  10.00  90.00   0.00   0.00\r\n";
        let events = feed_all(
            &mut FastrakDecoder::with_defaults(FastrakFormat::Ascii),
            bytes,
        );
        let p = poses(&events);
        assert_eq!(p.len(), 1, "{events:?}");
        assert_eq!(p[0].station, 1);
        assert_eq!(p[0].raw_position, [12.0, -3.5, 10.0]);
        assert_eq!(
            p[0].raw_orientation,
            RawOrientation::EulerDeg([90.0, 0.0, 0.0])
        );
        // transmitter (x fwd 12 in, y right -3.5 in, z down 10 in) -> ours (right, up, toward).
        let expect = glam::Vec3::new(-3.5 * 0.0254, -10.0 * 0.0254, -12.0 * 0.0254);
        assert!((p[0].pose.position_m - expect).length() < 1e-6);
        assert_eq!(p[0].status, None);
    }

    #[test]
    fn known_rotations_map_to_expected_quaternions() {
        let d = std::f32::consts::FRAC_PI_2;
        // Azimuth 90°: forward turns to the right (clockwise from above) = -90° about our +Y.
        let q = orientation_from_euler_deg([90.0, 0.0, 0.0]).as_quat();
        assert!(quat_close(q, Quat::from_rotation_y(-d)), "{q:?}");
        let expected = Quat::from_xyzw(0.0, -(0.5f32).sqrt(), 0.0, (0.5f32).sqrt());
        assert!(quat_close(q, expected));
        // Elevation 90°: forward pitches up = +90° about our +X.
        let q = orientation_from_euler_deg([0.0, 90.0, 0.0]).as_quat();
        assert!(quat_close(q, Quat::from_rotation_x(d)), "{q:?}");
        // Roll 90°: right goes down = -90° about our +Z.
        let q = orientation_from_euler_deg([0.0, 0.0, 90.0]).as_quat();
        assert!(quat_close(q, Quat::from_rotation_z(-d)), "{q:?}");
        // A combined rotation composes in the same order in our frame.
        let (a, e, r) = (30.0f32, 20.0f32, 10.0f32);
        let q = orientation_from_euler_deg([a.into(), e.into(), r.into()]).as_quat();
        let expect = Quat::from_rotation_y(-a.to_radians())
            * Quat::from_rotation_x(e.to_radians())
            * Quat::from_rotation_z(-r.to_radians());
        assert!(quat_close(q, expect), "{q:?} vs {expect:?}");
        // The quaternion item describes the same rotation as the Euler item.
        let q_t = DQuat::from_euler(
            EulerRot::ZYX,
            30f64.to_radians(),
            20f64.to_radians(),
            10f64.to_radians(),
        );
        let from_quat = orientation_from_quaternion([q_t.w, q_t.x, q_t.y, q_t.z]).as_quat();
        assert!(quat_close(from_quat, expect));
    }

    #[test]
    fn euler_and_position_conversions_invert() {
        let q = DQuat::from_euler(EulerRot::YXZ, 0.3, -0.4, 1.1);
        let back = orientation_from_euler_deg(euler_deg_from_orientation(q));
        assert!(back.dot(q).abs() > 1.0 - 1e-9);
        let back = orientation_from_quaternion(quaternion_from_orientation(q));
        assert!(back.dot(q).abs() > 1.0 - 1e-9);
        let p = DVec3::new(0.1, -0.2, 0.3);
        for u in [LengthUnit::Inches, LengthUnit::Centimetres] {
            assert!((position_m_from_raw(raw_from_position_m(p, u), u) - p).length() < 1e-12);
        }
    }

    #[test]
    fn every_output_list_item_and_format_round_trips() {
        for format in [FastrakFormat::Ascii, FastrakFormat::Binary] {
            for stylus_bytes in [1, 2] {
                for units in [LengthUnit::Inches, LengthUnit::Centimetres] {
                    let settings = FastrakSettings {
                        items: vec![0, 2, 0, 4, 11, 16, 1],
                        units,
                        stylus_bytes,
                    };
                    let mut dec =
                        FastrakDecoder::new(format, settings.clone()).expect("valid settings");
                    let q_t = DQuat::from_euler(EulerRot::ZYX, 0.5, 0.2, -0.1);
                    let mut r = record(3, [-20.5, 7.25, 3.0], [0.0; 3]);
                    r.quaternion = [q_t.w, q_t.x, q_t.y, q_t.z];
                    r.euler_deg = [28.65, 11.46, -5.73];
                    r.stylus = true;
                    let bytes = encode_record(format, &settings, &r);
                    assert_eq!(bytes.len(), dec.record_len());
                    let events = feed_all(&mut dec, &bytes);
                    let p = poses(&events);
                    assert_eq!(p.len(), 1, "{format:?} {stylus_bytes} {events:?}");
                    assert_eq!(p[0].station, 3);
                    assert_eq!(p[0].pressed, vec![0]);
                    assert!(matches!(
                        p[0].raw_orientation,
                        RawOrientation::Quaternion(_)
                    ));
                    let expect = position_m_from_raw([-20.5, 7.25, 3.0], units).as_vec3();
                    assert!((p[0].pose.position_m - expect).length() < 1e-5);
                    let want = orientation_from_quaternion(r.quaternion).as_quat();
                    assert!(p[0].pose.orientation.dot(want).abs() > 0.9999);
                    r.stylus = false;
                    let p2 = poses(&feed_all(&mut dec, &encode_record(format, &settings, &r)))
                        .first()
                        .map(|p| p.pressed.clone());
                    assert_eq!(p2, Some(vec![]));
                }
            }
        }
    }

    #[test]
    fn stylus_width_must_match_the_device() {
        // A 2-byte stylus record read with a 1-byte setting is one byte too long: the decoder
        // must not invent poses from it at the wrong offsets.
        let two = FastrakSettings {
            items: vec![2, 16, 1],
            stylus_bytes: 2,
            ..FastrakSettings::default()
        };
        let one = FastrakSettings {
            stylus_bytes: 1,
            ..two.clone()
        };
        let rec = record(1, [1.0, 2.0, 3.0], [0.0; 3]);
        for format in [FastrakFormat::Ascii, FastrakFormat::Binary] {
            let bytes = encode_record(format, &two, &rec).repeat(3);
            let mut right = FastrakDecoder::new(format, two.clone()).expect("valid");
            assert_eq!(poses(&feed_all(&mut right, &bytes)).len(), 3);
            let mut wrong = FastrakDecoder::new(format, one.clone()).expect("valid");
            let events = feed_all(&mut wrong, &bytes);
            assert!(poses(&events).is_empty(), "{format:?}: {events:?}");
            assert!(
                events
                    .iter()
                    .any(|e| matches!(e, DeviceEvent::Dropped { .. }))
            );
        }
    }

    #[test]
    fn every_split_point_gives_the_same_events() {
        for format in [FastrakFormat::Ascii, FastrakFormat::Binary] {
            let s = FastrakSettings::default();
            let mut bytes = encode_record(
                format,
                &s,
                &record(2, [1.5, -2.0, 3.25], [45.0, -10.0, 5.0]),
            );
            bytes.extend(encode_status_record(2, "S status text"));
            bytes.extend(encode_record(format, &s, &record(4, [0.0; 3], [0.0; 3])));
            assert_every_split(
                || Box::new(FastrakDecoder::with_defaults(format)),
                &bytes,
                3,
            );
        }
    }

    #[test]
    fn garbage_before_between_and_inside_records_is_dropped_and_counted() {
        for format in [FastrakFormat::Ascii, FastrakFormat::Binary] {
            let s = FastrakSettings::default();
            let good = encode_record(format, &s, &record(1, [5.0, 6.0, 7.0], [1.0, 2.0, 3.0]));
            let mut corrupted = good.clone();
            corrupted[10] = b'x';
            corrupted[11] = 0xFF;
            let mut stream = b"\r\n01x12garbage0".to_vec();
            stream.extend(&good);
            stream.extend(b"zz");
            stream.extend(&corrupted);
            stream.extend(&good);
            let events = feed_all(&mut FastrakDecoder::with_defaults(format), &stream);
            assert_eq!(poses(&events).len(), 2, "{format:?} {events:?}");
            let dropped: usize = events
                .iter()
                .map(|e| match e {
                    DeviceEvent::Dropped { bytes } => *bytes,
                    _ => 0,
                })
                .sum();
            assert_eq!(dropped, stream.len() - 2 * good.len(), "{format:?}");
            assert!(matches!(events[0], DeviceEvent::Dropped { bytes: 15 }));
        }
    }

    #[test]
    fn truncated_record_is_dropped_when_the_next_one_arrives() {
        let s = FastrakSettings::default();
        let good = encode_record(FastrakFormat::Ascii, &s, &record(1, [1.0; 3], [0.0; 3]));
        let mut stream = good[..30].to_vec();
        stream.extend(&good);
        let events = feed_all(
            &mut FastrakDecoder::with_defaults(FastrakFormat::Ascii),
            &stream,
        );
        assert_eq!(poses(&events).len(), 1);
        assert_eq!(events[0], DeviceEvent::Dropped { bytes: 30 });
    }

    #[test]
    fn a_false_status_header_does_not_hold_back_the_records_after_it() {
        // A short output list (space, CR LF) makes 6-byte records: three fit in less than a
        // status record's 55 bytes, which a status-like header in the garbage waited for.
        let s = FastrakSettings {
            items: vec![0, 1],
            ..FastrakSettings::default()
        };
        let one = encode_record(FastrakFormat::Ascii, &s, &record(4, [0.0; 3], [0.0; 3]));
        assert_eq!(one.len(), 6);
        let mut stream = b"21S".to_vec();
        for _ in 0..3 {
            stream.extend(&one);
        }
        let mut dec = FastrakDecoder::new(FastrakFormat::Ascii, s.clone()).expect("valid settings");
        let events = feed_all(&mut dec, &stream);
        assert_eq!(poses(&events).len(), 3, "{events:?}");
        assert_eq!(events[0], DeviceEvent::Dropped { bytes: 3 });
        assert_eq!(dec.pending(), 0);
        // The same events whatever the split.
        let make = || {
            Box::new(FastrakDecoder::new(FastrakFormat::Ascii, s.clone()).expect("valid"))
                as Box<dyn Decoder>
        };
        assert_eq!(assert_split_anywhere_same(make, &stream), events);
        // A real status record still waits for its last byte.
        let status = encode_status_record(2, "ok");
        let mut dec = FastrakDecoder::with_defaults(FastrakFormat::Ascii);
        let mut out = Vec::new();
        dec.feed(&status[..STATUS_RECORD_LEN - 1], &mut out);
        assert!(out.is_empty(), "{out:?}");
        dec.feed(&status[STATUS_RECORD_LEN - 1..], &mut out);
        assert!(matches!(out[..], [DeviceEvent::Status(_)]), "{out:?}");
    }

    #[test]
    fn status_letters_and_status_record() {
        let s = FastrakSettings::default();
        let mut r = record(2, [1.0; 3], [0.0; 3]);
        r.status = b'E';
        let mut bytes = encode_record(FastrakFormat::Ascii, &s, &r);
        bytes.extend(encode_status_record(3, "hello"));
        let events = feed_all(
            &mut FastrakDecoder::with_defaults(FastrakFormat::Ascii),
            &bytes,
        );
        assert_eq!(events.len(), 2, "{events:?}");
        assert_eq!(poses(&events)[0].status, Some('E'));
        match &events[1] {
            DeviceEvent::Status(StatusEvent::Report { text }) => {
                assert!(
                    text.contains("station 3") && text.contains("hello"),
                    "{text}"
                )
            }
            other => panic!("expected status, got {other:?}"),
        }
    }

    #[test]
    fn four_stations_interleave() {
        let s = FastrakSettings::default();
        let mut bytes = Vec::new();
        for st in 1..=4 {
            bytes.extend(encode_record(
                FastrakFormat::Binary,
                &s,
                &record(st, [f64::from(st); 3], [0.0; 3]),
            ));
        }
        let events = feed_all(
            &mut FastrakDecoder::with_defaults(FastrakFormat::Binary),
            &bytes,
        );
        let stations: Vec<u8> = poses(&events).iter().map(|p| p.station).collect();
        assert_eq!(stations, vec![1, 2, 3, 4]);
    }

    #[test]
    fn non_finite_or_implausible_binary_values_are_rejected() {
        let s = FastrakSettings::default();
        let mut bytes = encode_record(FastrakFormat::Binary, &s, &record(1, [1.0; 3], [0.0; 3]));
        bytes[3..7].copy_from_slice(&f32::NAN.to_le_bytes());
        let mut dec = FastrakDecoder::with_defaults(FastrakFormat::Binary);
        let events = feed_all(&mut dec, &bytes);
        assert!(poses(&events).is_empty());
        bytes[3..7].copy_from_slice(&5000.0f32.to_le_bytes());
        assert!(poses(&feed_all(&mut dec, &bytes)).is_empty());
    }

    #[test]
    fn reset_forgets_a_partial_record() {
        let s = FastrakSettings::default();
        let good = encode_record(FastrakFormat::Ascii, &s, &record(1, [1.0; 3], [0.0; 3]));
        let mut dec = FastrakDecoder::with_defaults(FastrakFormat::Ascii);
        let mut out = Vec::new();
        dec.feed(&good[..20], &mut out);
        dec.reset();
        dec.feed(&good, &mut out);
        assert_eq!(out.len(), 1, "{out:?}");
    }
}
