//! Recorded device sessions: a header (format version, the device profile with its device table
//! and roles), then every chunk of raw bytes exactly as it arrived, with its arrival time and
//! device index, plus the desktop stand-in events. The format is line-based text, documented in
//! `docs/sessions.md`:
//!
//! ```text
//! leman-session 1
//! header {"recorded_by":"leman 0.1.0","profile":{...}}
//! o 0 1                      device 1 opened (decoder reset)
//! w 1000 1 0d4052455345540d  bytes written to device 1 (hex)
//! c 2500000 1 4031...        a chunk read from device 1 (hex), at 2.5 ms
//! l 9000000 1 "unplugged"    device 1 lost (a JSON string says why)
//! e 3000000 {"kind":"mouse_move","x":0.5,"y":0.5}
//! end 5
//! ```
//!
//! Times are integer nanoseconds from the start of the recording and never decrease. The `end`
//! line carries the number of records, so a file cut at a line boundary is still detected.

use crate::devices::desktop::DesktopEvent;
use crate::devices::profile::Profile;
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// The session format version this build writes and reads.
pub const SESSION_VERSION: u32 = 1;

const MAGIC: &str = "leman-session";

/// What a session starts with.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SessionHeader {
    /// Program and version that wrote it.
    pub recorded_by: String,
    /// The device profile in force: the device table (protocol, transport and decoder settings)
    /// and the role bindings. Record device indices index `profile.devices`.
    pub profile: Profile,
}

impl SessionHeader {
    /// A header for `profile`, written by this build.
    pub fn new(profile: Profile) -> Self {
        Self {
            recorded_by: format!("leman {}", env!("CARGO_PKG_VERSION")),
            profile,
        }
    }
}

/// One timed record.
#[derive(Debug, Clone, PartialEq)]
pub enum Record {
    /// Bytes read from a device, exactly as one read returned them.
    Chunk {
        /// Arrival time.
        at: Duration,
        /// Index into the profile's devices.
        device: usize,
        /// The bytes.
        bytes: Vec<u8>,
    },
    /// Bytes written to a device (initialisation commands).
    Sent {
        /// When they were written.
        at: Duration,
        /// Index into the profile's devices.
        device: usize,
        /// The bytes.
        bytes: Vec<u8>,
    },
    /// The device was (re)opened; its decoder starts afresh.
    Opened {
        /// When.
        at: Duration,
        /// Index into the profile's devices.
        device: usize,
    },
    /// The device was lost (error, unplugged).
    Lost {
        /// When.
        at: Duration,
        /// Index into the profile's devices.
        device: usize,
        /// Why.
        error: String,
    },
    /// A desktop stand-in event.
    Desktop {
        /// When the window delivered it.
        at: Duration,
        /// The event.
        event: DesktopEvent,
    },
}

impl Record {
    /// The record's time.
    pub fn at(&self) -> Duration {
        match self {
            Record::Chunk { at, .. }
            | Record::Sent { at, .. }
            | Record::Opened { at, .. }
            | Record::Lost { at, .. }
            | Record::Desktop { at, .. } => *at,
        }
    }

    /// The device index, if the record belongs to one.
    pub fn device(&self) -> Option<usize> {
        match self {
            Record::Chunk { device, .. }
            | Record::Sent { device, .. }
            | Record::Opened { device, .. }
            | Record::Lost { device, .. } => Some(*device),
            Record::Desktop { .. } => None,
        }
    }

    /// Appends the record's line (with its newline).
    pub fn write_line(&self, out: &mut String) {
        use std::fmt::Write as _;
        let ns = |at: &Duration| at.as_nanos();
        // Writing into a String cannot fail.
        let _ = match self {
            Record::Chunk { at, device, bytes } => {
                writeln!(out, "c {} {} {}", ns(at), device, hex(bytes))
            }
            Record::Sent { at, device, bytes } => {
                writeln!(out, "w {} {} {}", ns(at), device, hex(bytes))
            }
            Record::Opened { at, device } => writeln!(out, "o {} {}", ns(at), device),
            Record::Lost { at, device, error } => writeln!(
                out,
                "l {} {} {}",
                ns(at),
                device,
                serde_json::to_string(error).unwrap_or_else(|_| "\"?\"".into())
            ),
            Record::Desktop { at, event } => writeln!(
                out,
                "e {} {}",
                ns(at),
                serde_json::to_string(event).unwrap_or_else(|_| "{}".into())
            ),
        };
    }
}

/// A whole session in memory.
#[derive(Debug, Clone, PartialEq)]
pub struct Session {
    /// The header.
    pub header: SessionHeader,
    /// The records in file order (time never decreases).
    pub records: Vec<Record>,
}

/// A session file that cannot be read; names the file and where in it.
#[derive(Debug, thiserror::Error)]
pub enum SessionError {
    /// The file could not be read or written.
    #[error("session {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// The content is wrong at a known place.
    #[error("session {path}: line {line} (byte offset {offset}): {message}")]
    Corrupt {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// Byte offset of the start of that line.
        offset: usize,
        /// What is wrong.
        message: String,
    },
    /// A recording's `.NAME.partial` file is already there: a recording to the same target
    /// was cut short (and holds records not yet recovered) or is still running. It is never
    /// written over.
    #[error(
        "session {target}: {partial} already exists: a recording to this file was cut short or \
         is still running; keep what it holds with `leman record --recover {partial} --out \
         NEW.session`, or remove it"
    )]
    PartialExists {
        /// The session file the new recording was to make.
        target: PathBuf,
        /// The partial file found beside it.
        partial: PathBuf,
    },
}

fn hex(bytes: &[u8]) -> String {
    const DIGITS: &[u8; 16] = b"0123456789abcdef";
    let mut s = String::with_capacity(bytes.len() * 2);
    for b in bytes {
        s.push(DIGITS[usize::from(b >> 4)] as char);
        s.push(DIGITS[usize::from(b & 15)] as char);
    }
    s
}

fn unhex(text: &str) -> Result<Vec<u8>, String> {
    let digit = |c: u8| -> Result<u8, String> {
        match c {
            b'0'..=b'9' => Ok(c - b'0'),
            b'a'..=b'f' => Ok(c - b'a' + 10),
            b'A'..=b'F' => Ok(c - b'A' + 10),
            _ => Err(format!("{:?} is not a hex digit", char::from(c))),
        }
    };
    let b = text.as_bytes();
    if !b.len().is_multiple_of(2) {
        return Err(format!("odd number of hex digits ({})", b.len()));
    }
    b.chunks_exact(2)
        .map(|pair| Ok(digit(pair[0])? << 4 | digit(pair[1])?))
        .collect()
}

impl Session {
    /// An empty session for `profile`.
    pub fn new(profile: Profile) -> Self {
        Self {
            header: SessionHeader::new(profile),
            records: Vec::new(),
        }
    }

    /// The first two lines (magic with version, header).
    fn header_text(header: &SessionHeader) -> String {
        let json = serde_json::to_string(header).unwrap_or_else(|_| "{}".into());
        format!("{MAGIC} {SESSION_VERSION}\nheader {json}\n")
    }

    /// The whole file's text.
    pub fn to_text(&self) -> String {
        let mut out = Self::header_text(&self.header);
        for r in &self.records {
            r.write_line(&mut out);
        }
        out.push_str(&format!("end {}\n", self.records.len()));
        out
    }

    /// Writes the session atomically.
    pub fn save(&self, path: &Path) -> Result<(), SessionError> {
        crate::files::write_atomic(path, self.to_text().as_bytes()).map_err(|e| SessionError::Io {
            path: e.path,
            source: e.source,
        })
    }

    /// Reads a session file.
    pub fn load(path: &Path) -> Result<Self, SessionError> {
        Self::parse(&read_file(path)?, path)
    }

    /// Reads what can be read of a cut-short or damaged session file: [`Session::recover`].
    pub fn recover_file(path: &Path) -> Result<Recovered, SessionError> {
        Self::recover(&read_file(path)?, path)
    }

    /// Parses session bytes; `path` names the file in errors. Never panics.
    pub fn parse(bytes: &[u8], path: &Path) -> Result<Self, SessionError> {
        let read = Self::recover(bytes, path)?;
        match read.dropped {
            None => Ok(read.session),
            // Cut inside its last line or before `end` (no line end after the fault), as a
            // killed recording's buffered writes leave a file: recoverable.
            Some(stop) if !bytes[bytes.len() - stop.bytes..].contains(&b'\n') => {
                Err(with_recovery_hint(stop.reason))
            }
            Some(stop) => Err(stop.reason),
        }
    }

    /// Reads what can be read of a cut-short or damaged session (a recording killed before it
    /// stopped leaves its `.NAME.partial` file without an `end` line, often cut inside a line):
    /// the header and every record up to the first line that is cut short, damaged or out of
    /// place. Fails only when the header itself cannot be read. Never panics.
    pub fn recover(bytes: &[u8], path: &Path) -> Result<Recovered, SessionError> {
        let mut reading = Reading {
            header: None,
            records: Vec::new(),
            ended: false,
            lines: 0,
            last_at: Duration::ZERO,
        };
        let mut offset = 0usize;
        let mut stop = None;
        while offset < bytes.len() {
            reading.lines += 1;
            let start = offset;
            match read_line(bytes, path, &mut reading, start) {
                Ok(next) => offset = next,
                Err(reason) => {
                    stop = Some(Dropped {
                        reason,
                        bytes: bytes.len() - start,
                    });
                    break;
                }
            }
        }
        let Some(header) = reading.header else {
            return Err(stop.map_or_else(|| no_header(bytes, path, reading.lines), |s| s.reason));
        };
        if stop.is_none() && !reading.ended {
            stop = Some(Dropped {
                reason: no_end(bytes, path, reading.lines, reading.records.len()),
                bytes: 0,
            });
        }
        Ok(Recovered {
            session: Session {
                header,
                records: reading.records,
            },
            dropped: stop,
        })
    }

    /// The chunks of one device, in order.
    pub fn chunks(&self, device: usize) -> impl Iterator<Item = (Duration, &[u8])> {
        self.records.iter().filter_map(move |r| match r {
            Record::Chunk {
                at,
                device: d,
                bytes,
            } if *d == device => Some((*at, bytes.as_slice())),
            _ => None,
        })
    }

    /// Time of the last record.
    pub fn duration(&self) -> Duration {
        self.records.last().map_or(Duration::ZERO, Record::at)
    }
}

/// What [`Session::recover`] read of a session file.
#[derive(Debug)]
pub struct Recovered {
    /// The header and the records read before the first fault.
    pub session: Session,
    /// Why reading stopped short of a whole file, if it did: `None` exactly when the file is
    /// a whole session (header, records, a correct `end`).
    pub dropped: Option<Dropped>,
}

/// Where and why [`Session::recover`] stopped, and what it left unread.
#[derive(Debug)]
pub struct Dropped {
    /// The fault: a cut-short or damaged line (its line number and byte offset), a wrong `end`
    /// count, data after `end`, or a missing `end` line.
    pub reason: SessionError,
    /// Bytes left unread from the faulty line to the end of the file (0 when only the `end`
    /// line is missing).
    pub bytes: usize,
}

/// What [`read_line`] has read so far (for [`Session::recover`]).
struct Reading {
    header: Option<SessionHeader>,
    records: Vec<Record>,
    /// Whether a correct `end` line was read.
    ended: bool,
    /// Lines read, the faulty one included.
    lines: usize,
    /// Time of the last record read (times never decrease).
    last_at: Duration,
}

/// Turns an I/O error on the file at `path` into a [`SessionError::Io`] naming it.
fn io_at(path: &Path) -> impl Fn(std::io::Error) -> SessionError + '_ {
    move |source| SessionError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// The bytes of the file at `path`; an error names it.
fn read_file(path: &Path) -> Result<Vec<u8>, SessionError> {
    std::fs::read(path).map_err(io_at(path))
}

/// `error` with a pointer to `leman record --recover`, for a file cut short after its header.
fn with_recovery_hint(error: SessionError) -> SessionError {
    match error {
        SessionError::Corrupt {
            path,
            line,
            offset,
            message,
        } => SessionError::Corrupt {
            path,
            line,
            offset,
            message: format!(
                "{message}; `leman record --recover FILE --out NEW` keeps the records before it"
            ),
        },
        io => io,
    }
}

fn no_header(bytes: &[u8], path: &Path, lines: usize) -> SessionError {
    SessionError::Corrupt {
        path: path.to_path_buf(),
        line: lines.max(1),
        offset: bytes.len(),
        message: "truncated: no header".into(),
    }
}

fn no_end(bytes: &[u8], path: &Path, lines: usize, records: usize) -> SessionError {
    SessionError::Corrupt {
        path: path.to_path_buf(),
        line: lines + 1,
        offset: bytes.len(),
        message: format!(
            "truncated: no `end` line after {records} records (the recording was cut short)"
        ),
    }
}

/// Reads the line starting at byte `start` (line number `reading.lines`) into `reading`;
/// returns the offset of the next line.
fn read_line(
    bytes: &[u8],
    path: &Path,
    reading: &mut Reading,
    start: usize,
) -> Result<usize, SessionError> {
    let line_no = reading.lines;
    let corrupt = |message: String| SessionError::Corrupt {
        path: path.to_path_buf(),
        line: line_no,
        offset: start,
        message,
    };
    let rest = &bytes[start..];
    let Some(nl) = rest.iter().position(|&b| b == b'\n') else {
        return Err(corrupt(format!(
            "truncated: the last line has no end ({} bytes)",
            rest.len()
        )));
    };
    let next = start + nl + 1;
    let line =
        std::str::from_utf8(&rest[..nl]).map_err(|e| corrupt(format!("not UTF-8 text ({e})")))?;
    if reading.ended {
        return Err(corrupt("data after the `end` line".into()));
    }
    if line_no == 1 {
        let version = line
            .strip_prefix(MAGIC)
            .and_then(|v| v.trim().parse::<u32>().ok())
            .ok_or_else(|| corrupt(format!("not a leman session (expected `{MAGIC} N`)")))?;
        if version != SESSION_VERSION {
            return Err(corrupt(format!(
                "session format version {version} is not supported (this build reads \
                 {SESSION_VERSION})"
            )));
        }
        return Ok(next);
    }
    if line_no == 2 {
        let json = line
            .strip_prefix("header ")
            .ok_or_else(|| corrupt("expected the `header` line".into()))?;
        let h: SessionHeader =
            serde_json::from_str(json).map_err(|e| corrupt(format!("bad header: {e}")))?;
        h.profile
            .validate(path)
            .map_err(|e| corrupt(format!("bad profile in header: {e}")))?;
        reading.header = Some(h);
        return Ok(next);
    }
    let devices = reading
        .header
        .as_ref()
        .map_or(0, |h| h.profile.devices.len());
    let (tag, rest) = line.split_once(' ').unwrap_or((line, ""));
    if tag == "end" {
        let n: usize = rest
            .trim()
            .parse()
            .map_err(|_| corrupt(format!("bad record count {rest:?}")))?;
        if n != reading.records.len() {
            return Err(corrupt(format!(
                "the file says {n} records but holds {}: lines are missing or extra",
                reading.records.len()
            )));
        }
        reading.ended = true;
        return Ok(next);
    }
    let mut fields = rest.splitn(3, ' ');
    let at_ns: u64 = fields
        .next()
        .and_then(|t| t.parse().ok())
        .ok_or_else(|| corrupt("bad or missing time".into()))?;
    let at = Duration::from_nanos(at_ns);
    if at < reading.last_at {
        return Err(corrupt(format!(
            "time goes backwards ({} ns after {} ns)",
            at_ns,
            reading.last_at.as_nanos()
        )));
    }
    let mut device = || -> Result<usize, SessionError> {
        let d: usize = fields
            .next()
            .and_then(|t| t.parse().ok())
            .ok_or_else(|| corrupt("bad or missing device index".into()))?;
        if d >= devices {
            return Err(corrupt(format!(
                "device index {d} but the header has {devices} devices"
            )));
        }
        Ok(d)
    };
    let record = match tag {
        "c" | "w" => {
            let device = device()?;
            let bytes = unhex(fields.next().unwrap_or("")).map_err(corrupt)?;
            if bytes.is_empty() {
                return Err(corrupt("empty chunk".into()));
            }
            if tag == "c" {
                Record::Chunk { at, device, bytes }
            } else {
                Record::Sent { at, device, bytes }
            }
        }
        "o" => Record::Opened {
            at,
            device: device()?,
        },
        "l" => {
            let device = device()?;
            let error: String = serde_json::from_str(fields.next().unwrap_or(""))
                .map_err(|e| corrupt(format!("bad lost reason: {e}")))?;
            Record::Lost { at, device, error }
        }
        "e" => {
            let json = [fields.next(), fields.next()]
                .into_iter()
                .flatten()
                .collect::<Vec<_>>()
                .join(" ");
            let event: DesktopEvent = serde_json::from_str(&json)
                .map_err(|e| corrupt(format!("bad desktop event: {e}")))?;
            Record::Desktop { at, event }
        }
        _ => return Err(corrupt(format!("unknown record type {tag:?}"))),
    };
    reading.last_at = at;
    reading.records.push(record);
    Ok(next)
}

/// Streams a session to `<dir>/.<name>.partial` while recording and renames it over the target on
/// [`SessionWriter::finish`], so the target is either absent/old or complete. If the program dies
/// first, the partial file stays: it has no `end` line, so loading it fails with a clear
/// "truncated" error, and [`Session::recover`] (`leman record --recover`) keeps its records up
/// to the writer's last flush (the header at once, then every [`FLUSH_EVERY`], driven by the
/// records written and by [`SessionWriter::flush_if_due`]).
pub struct SessionWriter {
    file: std::io::BufWriter<std::fs::File>,
    partial: PathBuf,
    target: PathBuf,
    count: usize,
    last_at: Duration,
    /// Recording time of the last flush to the operating system.
    flushed_at: Duration,
    /// Records written since the last flush (still in the buffer).
    unflushed: usize,
    line: String,
}

/// How much recording time a [`SessionWriter`] may hold in its buffer: a recording killed
/// before it stops loses at most the records of about this long (the records before it are in
/// the `.partial` file for `leman record --recover`).
pub const FLUSH_EVERY: Duration = Duration::from_secs(1);

impl std::fmt::Debug for SessionWriter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SessionWriter")
            .field("target", &self.target)
            .field("count", &self.count)
            .finish()
    }
}

impl SessionWriter {
    /// Starts a session file at `target` with `header`, writing into `.NAME.partial` beside
    /// it. Refuses ([`SessionError::PartialExists`]) when that partial file is already there:
    /// it is either the only copy of a recording that was cut short, or another recorder's.
    pub fn create(target: &Path, header: &SessionHeader) -> Result<Self, SessionError> {
        let io = io_at(target);
        let dir = match target.parent() {
            Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let name = target
            .file_name()
            .ok_or_else(|| io(std::io::Error::other("path has no file name")))?;
        let mut partial_name = std::ffi::OsString::from(".");
        partial_name.push(name);
        partial_name.push(".partial");
        let partial = dir.join(partial_name);
        let file = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&partial)
            .map_err(|e| match e.kind() {
                std::io::ErrorKind::AlreadyExists => SessionError::PartialExists {
                    target: target.to_path_buf(),
                    partial: partial.clone(),
                },
                _ => io(e),
            })?;
        let mut file = std::io::BufWriter::new(file);
        // The header goes out at once: without it nothing of a killed recording is recoverable.
        file.write_all(Session::header_text(header).as_bytes())
            .and_then(|()| file.flush())
            .map_err(&io)?;
        Ok(Self {
            file,
            partial,
            target: target.to_path_buf(),
            count: 0,
            last_at: Duration::ZERO,
            flushed_at: Duration::ZERO,
            unflushed: 0,
            line: String::new(),
        })
    }

    /// Appends one record. A record earlier than the previous one is stored at the previous
    /// time (times in a session never decrease). The buffer goes to the file once a record is
    /// [`FLUSH_EVERY`] or more (recording time) after the last flush.
    pub fn write(&mut self, record: &Record) -> Result<(), SessionError> {
        self.line.clear();
        if record.at() < self.last_at {
            let mut r = record.clone();
            set_at(&mut r, self.last_at);
            r.write_line(&mut self.line);
        } else {
            self.last_at = record.at();
            record.write_line(&mut self.line);
        }
        self.file
            .write_all(self.line.as_bytes())
            .map_err(io_at(&self.partial))?;
        self.count += 1;
        self.unflushed += 1;
        self.flush_if_due(self.last_at)
    }

    /// Hands the buffered records to the operating system if there are any and `now`
    /// (recording time, the clock the records are stamped on) is [`FLUSH_EVERY`] or more after
    /// the last flush. [`SessionWriter::write`] calls it for each record; a recorder calls it
    /// on a timer too, so that records made just before a device falls silent do not wait in
    /// the buffer for the next one.
    pub fn flush_if_due(&mut self, now: Duration) -> Result<(), SessionError> {
        if self.unflushed == 0 || now.saturating_sub(self.flushed_at) < FLUSH_EVERY {
            return Ok(());
        }
        self.file.flush().map_err(io_at(&self.partial))?;
        self.flushed_at = now;
        self.unflushed = 0;
        Ok(())
    }

    /// Records written so far.
    pub fn count(&self) -> usize {
        self.count
    }

    /// Writes the `end` line, syncs and renames the file into place, then syncs the folder
    /// ([`crate::files::sync_dir`]); returns the target path.
    pub fn finish(mut self) -> Result<PathBuf, SessionError> {
        let io = io_at(&self.partial);
        writeln!(self.file, "end {}", self.count).map_err(&io)?;
        let file = self.file.into_inner().map_err(|e| io(e.into_error()))?;
        file.sync_all().map_err(&io)?;
        drop(file);
        std::fs::rename(&self.partial, &self.target).map_err(io_at(&self.target))?;
        if let Some(dir) = self.partial.parent() {
            crate::files::sync_dir(dir);
        }
        Ok(self.target)
    }
}

fn set_at(r: &mut Record, to: Duration) {
    match r {
        Record::Chunk { at, .. }
        | Record::Sent { at, .. }
        | Record::Opened { at, .. }
        | Record::Lost { at, .. }
        | Record::Desktop { at, .. } => *at = to,
    }
}

/// The records a recording's `.partial` file holds now, as [`Session::recover`] reads them
/// (for tests of the writer and the hub).
#[cfg(test)]
pub(crate) fn records_on_disk(partial: &Path) -> Vec<Record> {
    Session::recover_file(partial)
        .expect("a recoverable partial file")
        .session
        .records
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Session {
        let mut s = Session::new(Profile::desktop_default());
        s.records = vec![
            Record::Opened {
                at: Duration::ZERO,
                device: 0,
            },
            Record::Sent {
                at: Duration::from_nanos(5),
                device: 0,
                bytes: b"\r@RESET\r".to_vec(),
            },
            Record::Chunk {
                at: Duration::from_micros(2500),
                device: 0,
                bytes: vec![0, 1, 0xff, b'\n', b' '],
            },
            Record::Desktop {
                at: Duration::from_millis(3),
                event: DesktopEvent::Key {
                    name: "a b".into(),
                    pressed: true,
                },
            },
            Record::Lost {
                at: Duration::from_millis(9),
                device: 0,
                error: "gone \"away\"\nnow".into(),
            },
        ];
        s
    }

    #[test]
    fn text_round_trips_exactly() {
        let s = sample();
        let text = s.to_text();
        let back = Session::parse(text.as_bytes(), Path::new("x.session")).expect("parse");
        assert_eq!(back, s);
        assert_eq!(back.to_text(), text);
    }

    #[test]
    fn every_truncation_is_a_clear_error_and_never_a_panic() {
        let text = sample().to_text();
        let bytes = text.as_bytes();
        for cut in 0..bytes.len() {
            let err = Session::parse(&bytes[..cut], Path::new("cut.session"))
                .expect_err("truncated must fail");
            let msg = err.to_string();
            assert!(msg.contains("cut.session"), "{msg}");
            assert!(msg.contains("byte offset"), "{msg}");
            // Past the header, the error points at the recovery.
            let header_read = text[..cut].matches('\n').count() >= 2;
            assert_eq!(msg.contains("--recover"), header_read, "cut {cut}: {msg}");
        }
    }

    #[test]
    fn corruption_names_the_line_and_offset() {
        let text = sample().to_text();
        let cases = [
            (
                "c 2500000 0 0001ff0a20",
                "c 2500000 0 0001fg0a20",
                "hex digit",
            ),
            ("c 2500000 0 ", "c 2500000 7 ", "device index 7"),
            ("c 2500000 0 ", "c 1 0 ", "time goes backwards"),
            ("c 2500000 0 ", "x 2500000 0 ", "unknown record type"),
            ("end 5", "end 4", "lines are missing"),
        ];
        for (from, to, expect) in cases {
            assert!(text.contains(from), "{from}");
            let bad = text.replacen(from, to, 1);
            let err = Session::parse(bad.as_bytes(), Path::new("bad.session"))
                .expect_err("corrupt must fail")
                .to_string();
            assert!(err.contains("bad.session"), "{err}");
            assert!(err.contains(expect), "{err} lacks {expect}");
            assert!(err.contains("line "), "{err}");
            assert!(
                !err.contains("--recover"),
                "a damaged file is not a cut one: {err}"
            );
        }
        // The offset points at the start of the bad line.
        let bad = text.replacen("c 2500000", "c 25oo000", 1);
        match Session::parse(bad.as_bytes(), Path::new("b")) {
            Err(SessionError::Corrupt { offset, line, .. }) => {
                assert_eq!(&bad.as_bytes()[offset..offset + 2], b"c ");
                assert_eq!(line, 5);
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn arbitrary_bytes_never_panic_and_recovery_keeps_whole_sessions() {
        use proptest::prelude::*;
        let text = sample().to_text().into_bytes();
        proptest!(ProptestConfig::with_cases(crate::proptest_cases::cases_or(300)), |(pos in 0usize..400, byte in any::<u8>(), junk in proptest::collection::vec(any::<u8>(), 0..64))| {
            let mut b = text.clone();
            let i = pos % b.len();
            b[i] = byte;
            for bytes in [&b, &junk] {
                let strict = Session::parse(bytes, Path::new("p"));
                let recovered = Session::recover(bytes, Path::new("p"));
                if let Ok(s) = &strict {
                    // A whole file is recovered whole.
                    let r = recovered.as_ref().expect("a whole file recovers");
                    prop_assert!(r.dropped.is_none());
                    prop_assert_eq!(&r.session, s);
                }
                if let Ok(r) = recovered {
                    // What recovery keeps is a whole session.
                    let again = Session::parse(r.session.to_text().as_bytes(), Path::new("q"));
                    prop_assert_eq!(again.expect("recovered reads back"), r.session);
                }
            }
        });
    }

    #[test]
    fn recover_keeps_every_whole_record_of_any_cut() {
        let whole = sample();
        let text = whole.to_text();
        let bytes = text.as_bytes();
        let line_ends: Vec<usize> = (0..bytes.len()).filter(|&i| bytes[i] == b'\n').collect();
        let header_end = line_ends[1] + 1;
        for cut in 0..=bytes.len() {
            let got = Session::recover(&bytes[..cut], Path::new("cut.session"));
            if cut < header_end {
                let msg = got.expect_err("no header, nothing to recover").to_string();
                assert!(
                    msg.contains("cut.session") && msg.contains("line "),
                    "{msg}"
                );
                continue;
            }
            let got = got.expect("a whole header is enough");
            // Whole lines in the cut, header and `end` not counted.
            let whole_lines = line_ends.iter().filter(|&&e| e < cut).count();
            let kept = (whole_lines - 2).min(whole.records.len());
            assert_eq!(got.session.header, whole.header, "cut {cut}");
            assert_eq!(got.session.records, whole.records[..kept], "cut {cut}");
            let last_whole = line_ends[whole_lines - 1] + 1;
            match got.dropped {
                None => assert_eq!(cut, bytes.len(), "only the whole file has nothing dropped"),
                Some(d) => {
                    assert_eq!(d.bytes, cut - last_whole, "cut {cut}");
                    let msg = d.reason.to_string();
                    assert!(
                        msg.contains("cut.session") && msg.contains("truncated"),
                        "{msg}"
                    );
                }
            }
        }
    }

    #[test]
    fn recover_stops_at_a_damaged_line_and_what_it_keeps_reads_back() {
        let whole = sample();
        let text = whole.to_text();
        // Line 5 is the third record.
        let bad = text.replacen("c 2500000 0 0001ff", "c 2500000 0 0001fg", 1);
        let line5 = bad.find("c 2500000").expect("line 5");
        let got = Session::recover(bad.as_bytes(), Path::new("bad.session")).expect("recover");
        assert_eq!(got.session.records, whole.records[..2]);
        let dropped = got.dropped.expect("a damaged line is reported");
        assert_eq!(dropped.bytes, bad.len() - line5);
        match &dropped.reason {
            SessionError::Corrupt { line, offset, .. } => assert_eq!((*line, *offset), (5, line5)),
            other => panic!("{other:?}"),
        }
        // What was kept is a whole session again.
        let again = Session::parse(got.session.to_text().as_bytes(), Path::new("again"))
            .expect("a recovered session reads strictly");
        assert_eq!(again, got.session);
        // A wrong `end` count keeps every record and says so; a whole file loses nothing.
        let miscounted = text.replacen("end 5", "end 4", 1);
        let got = Session::recover(miscounted.as_bytes(), Path::new("m")).expect("recover");
        assert_eq!(got.session.records, whole.records);
        let reason = got.dropped.expect("reported").reason.to_string();
        assert!(reason.contains("lines are missing"), "{reason}");
        let got = Session::recover(text.as_bytes(), Path::new("w")).expect("recover");
        assert!(got.dropped.is_none());
        assert_eq!(got.session, whole);
    }

    /// A writer of a desktop session `rec.session` in `dir`, its target and its partial file.
    fn desktop_writer(dir: &Path) -> (SessionWriter, PathBuf, PathBuf) {
        let target = dir.join("rec.session");
        let header = SessionHeader::new(Profile::desktop_default());
        let w = SessionWriter::create(&target, &header).expect("create");
        (w, target, dir.join(".rec.session.partial"))
    }

    #[test]
    fn a_killed_recording_keeps_what_came_before_the_last_second() {
        let dir = tempfile::tempdir().expect("tempdir");
        let (mut w, target, partial) = desktop_writer(dir.path());
        let on_disk = || records_on_disk(&partial);
        assert!(on_disk().is_empty(), "the header is out at once");
        // A small record every 100 ms: far less than the buffer holds, so only the flushes
        // put them on disk.
        let at = |ms: u64| Record::Opened {
            at: Duration::from_millis(ms),
            device: 0,
        };
        for ms in (0..=2500).step_by(100) {
            w.write(&at(ms)).expect("write");
            let kept = on_disk().len() as u64;
            // Flushed at each whole second of recording time: everything up to the last one is
            // on disk, so every record more than FLUSH_EVERY old is.
            let want = if ms < 1000 { 0 } else { ms / 1000 * 10 + 1 };
            assert_eq!(kept, want, "at {ms} ms");
            let older = if ms < 1000 { 0 } else { (ms - 1000) / 100 + 1 };
            assert!(kept >= older, "at {ms} ms");
        }
        // Dropping the writer without finishing (an error path) leaves the partial file whole.
        drop(w);
        assert_eq!(on_disk().len(), 26);
        assert!(!target.exists());
        // A new recording to the same file refuses to start over it, naming it and the way to
        // recover it, and leaves it as it was.
        let before = std::fs::read(&partial).expect("read partial");
        let err = SessionWriter::create(&target, &SessionHeader::new(Profile::desktop_default()))
            .expect_err("a partial file is never written over");
        assert!(matches!(&err, SessionError::PartialExists { partial: p, .. } if *p == partial));
        let text = err.to_string();
        assert!(
            text.contains(".rec.session.partial") && text.contains("--recover"),
            "{text}"
        );
        assert_eq!(std::fs::read(&partial).expect("read partial"), before);
        // Once it is recovered elsewhere and removed, the name records again.
        std::fs::remove_file(&partial).expect("remove");
        desktop_writer(dir.path()).0.finish().expect("finish");
        assert!(target.exists());
    }

    #[test]
    fn records_before_a_silence_reach_the_file_on_the_timer() {
        let dir = tempfile::tempdir().expect("tempdir");
        let (mut w, _, partial) = desktop_writer(dir.path());
        let on_disk = || records_on_disk(&partial).len();
        for ms in [100, 200, 300] {
            w.write(&Record::Opened {
                at: Duration::from_millis(ms),
                device: 0,
            })
            .expect("write");
        }
        // The device falls silent: no record comes to carry the flush.
        w.flush_if_due(Duration::from_millis(999)).expect("flush");
        assert_eq!(on_disk(), 0, "not due before a second of recording");
        w.flush_if_due(Duration::from_millis(1000)).expect("flush");
        assert_eq!(on_disk(), 3, "due at a second: all three on disk");
        // The next second counts from that flush, and an empty buffer is not flushed again.
        w.write(&Record::Opened {
            at: Duration::from_millis(1500),
            device: 0,
        })
        .expect("write");
        w.flush_if_due(Duration::from_millis(1999)).expect("flush");
        assert_eq!(on_disk(), 3);
        w.flush_if_due(Duration::from_millis(2000)).expect("flush");
        assert_eq!(on_disk(), 4);
        let path = w.finish().expect("finish");
        assert_eq!(Session::load(&path).expect("load").records.len(), 4);
    }

    #[test]
    fn writer_streams_then_renames_atomically() {
        let dir = tempfile::tempdir().expect("tempdir");
        let target = dir.path().join("rec.session");
        let s = sample();
        let mut w = SessionWriter::create(&target, &s.header).expect("create");
        for r in &s.records {
            w.write(r).expect("write");
        }
        assert!(!target.exists(), "target appears only on finish");
        let path = w.finish().expect("finish");
        assert_eq!(path, target);
        assert_eq!(Session::load(&target).expect("load"), s);
        let names: Vec<_> = std::fs::read_dir(dir.path())
            .expect("list")
            .map(|e| e.expect("entry").file_name())
            .collect();
        assert_eq!(names.len(), 1, "{names:?}");
    }
}
