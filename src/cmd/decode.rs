//! `leman decode`: runs one protocol decoder over a raw byte capture, or every device of a
//! recorded session through its own decoder, and prints one event per line.

use anyhow::{Context, bail};
use leman::clock::{Clock, RealClock};
use leman::devices::decoder::Decoder;
use leman::devices::fastrak::{FastrakSettings, LengthUnit};
use leman::devices::opentrack::DATAGRAM_LEN;
use leman::devices::profile::DeviceKind;
use leman::devices::protocol::{DecoderSettings, Framing, Protocol, decoder_with_settings};
use leman::devices::sample::DeviceEvent;
use leman::devices::session::{Record, Session};
use leman::devices::spacemouse_hid::split_length_prefixed;
use std::io::Write;
use std::path::PathBuf;
use std::time::Duration;

/// Arguments of `leman decode`.
#[derive(Debug, Default, clap::Args)]
pub struct Args {
    /// Protocol of a raw capture: fastrak-ascii, fastrak-binary, spaceball, magellan,
    /// spacemouse-hid, opentrack, logitech. For a session file it selects which devices to
    /// decode (default: all).
    #[arg(long, short = 'p')]
    pub protocol: Option<Protocol>,
    /// A raw byte capture (plain bytes; spacemouse-hid: reports each preceded by a one-byte
    /// length; opentrack: consecutive 48-byte datagrams) or a session file (`leman-session`).
    pub file: PathBuf,
    /// One JSON object per line: {"kind": "pose"|"axes"|"buttons"|"status"|"dropped", ...}.
    #[arg(long)]
    pub json: bool,
    /// FASTRAK output list the device was set to (`O` command), comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "2,4,1")]
    pub fastrak_items: Vec<u8>,
    /// FASTRAK position unit: inches or cm.
    #[arg(long, default_value = "inches", value_parser = parse_unit)]
    pub fastrak_units: Option<LengthUnit>,
    /// Width of the FASTRAK stylus item (16): 1 or 2 bytes.
    #[arg(long, default_value_t = 2)]
    pub stylus_bytes: u8,
    /// Feed a raw stream capture in chunks of this many bytes (default 65536) to
    /// reproduce fragmented reads; the output does not depend on it (consecutive drops are
    /// merged into one `dropped` event).
    #[arg(long)]
    pub chunk: Option<usize>,
    /// Print to stderr how many bytes and events there were and how long decoding alone took
    /// (raw captures only; printing is not counted).
    #[arg(long)]
    pub stats: bool,
}

fn parse_unit(s: &str) -> Result<LengthUnit, String> {
    match s.to_ascii_lowercase().as_str() {
        "inches" | "inch" | "in" => Ok(LengthUnit::Inches),
        "cm" | "centimetres" | "centimeters" => Ok(LengthUnit::Centimetres),
        other => Err(format!("unknown unit {other:?} (use inches or cm)")),
    }
}

/// Prints events as JSON lines or readable lines; an optional prefix names time and device.
struct Printer<W: Write> {
    out: W,
    json: bool,
}

impl<W: Write> Printer<W> {
    fn print(
        &mut self,
        events: &[DeviceEvent],
        context: Option<(f64, &str)>,
    ) -> std::io::Result<()> {
        for e in events {
            if self.json {
                let line = e.to_json_line();
                match context {
                    // Session: `t_s` and `device` go right after `kind` (whose value has no
                    // comma), so `kind` stays first.
                    Some((t_s, device)) => match line.split_once(',') {
                        Some((kind, rest)) => writeln!(
                            self.out,
                            "{kind},\"t_s\":{},\"device\":{},{rest}",
                            serde_json::json!(t_s),
                            serde_json::json!(device)
                        )?,
                        None => writeln!(self.out, "{line}")?,
                    },
                    None => writeln!(self.out, "{line}")?,
                }
            } else {
                match context {
                    Some((t_s, device)) => {
                        writeln!(self.out, "{t_s:10.6} {device:<12} {}", e.describe())?
                    }
                    None => writeln!(self.out, "{}", e.describe())?,
                }
            }
        }
        Ok(())
    }
}

/// Runs `leman decode`. A closed output pipe (`| head`) ends it quietly.
pub fn run(args: Args) -> anyhow::Result<()> {
    match decode(args) {
        Err(e)
            if e.downcast_ref::<std::io::Error>()
                .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe) =>
        {
            Ok(())
        }
        other => other,
    }
}

fn decode(args: Args) -> anyhow::Result<()> {
    let bytes = std::fs::read(&args.file)
        .with_context(|| format!("cannot read {}", args.file.display()))?;
    let stdout = std::io::stdout().lock();
    let mut printer = Printer {
        out: std::io::BufWriter::new(stdout),
        json: args.json,
    };
    if bytes.starts_with(b"leman-session") {
        decode_session(&args, &bytes, &mut printer)?;
    } else {
        decode_raw(&args, &bytes, &mut printer)?;
    }
    printer.out.flush()?;
    Ok(())
}

fn decode_raw<W: Write>(args: &Args, bytes: &[u8], printer: &mut Printer<W>) -> anyhow::Result<()> {
    let Some(protocol) = args.protocol else {
        bail!(
            "{}: not a session file, so --protocol is needed to decode it as raw bytes",
            args.file.display()
        );
    };
    let settings = DecoderSettings {
        fastrak: FastrakSettings {
            items: args.fastrak_items.clone(),
            units: args.fastrak_units.unwrap_or_default(),
            stylus_bytes: args.stylus_bytes,
        },
    };
    let mut decoder = decoder_with_settings(protocol, &settings)
        .with_context(|| format!("bad decoder settings for {protocol}"))?;
    let (pieces, trailing): (Vec<&[u8]>, usize) = match (protocol, protocol.framing()) {
        (Protocol::SpacemouseHid, _) => {
            let (reports, trailing) = split_length_prefixed(bytes);
            if trailing > 0 {
                tracing::warn!(
                    "{}: last {trailing} bytes do not form a whole length-prefixed report",
                    args.file.display()
                );
            }
            (reports, trailing)
        }
        // OpenTrack: consecutive datagrams; a short tail is fed as one (and rejected).
        (_, Framing::Message) => (bytes.chunks(DATAGRAM_LEN).collect(), 0),
        (_, Framing::Stream) => {
            let chunk = args.chunk.unwrap_or(64 * 1024).max(1);
            (bytes.chunks(chunk).collect(), 0)
        }
    };
    // Events are printed read by read (memory stays bounded); consecutive drops are merged
    // across reads so the output does not depend on the chunking.
    let mut events = Vec::new();
    let mut held_drop = 0usize;
    let clock = RealClock::new();
    let mut decode_time = Duration::ZERO;
    let mut event_count = 0usize;
    for piece in pieces {
        events.clear();
        let start = clock.now();
        decoder.feed(piece, &mut events);
        decode_time += clock.now().saturating_sub(start);
        event_count += events.len();
        let mut merged = Vec::with_capacity(events.len());
        for e in events.drain(..) {
            match e {
                DeviceEvent::Dropped { bytes } => held_drop += bytes,
                other => {
                    if held_drop > 0 {
                        merged.push(DeviceEvent::Dropped { bytes: held_drop });
                        held_drop = 0;
                    }
                    merged.push(other);
                }
            }
        }
        printer.print(&merged, None)?;
    }
    held_drop += trailing + decoder.pending();
    if held_drop > 0 {
        printer.print(&[DeviceEvent::Dropped { bytes: held_drop }], None)?;
    }
    if args.stats {
        let secs = decode_time.as_secs_f64();
        eprintln!(
            "{protocol}: {} bytes -> {event_count} events (before merging drops); decoding took {:.1} ms ({:.1} MB/s)",
            bytes.len(),
            secs * 1e3,
            if secs > 0.0 {
                bytes.len() as f64 / secs / 1e6
            } else {
                f64::INFINITY
            },
        );
    }
    Ok(())
}

fn decode_session<W: Write>(
    args: &Args,
    bytes: &[u8],
    printer: &mut Printer<W>,
) -> anyhow::Result<()> {
    let session = Session::parse(bytes, &args.file)?;
    let devices = &session.header.profile.devices;
    let mut decoders: Vec<Option<Box<dyn Decoder>>> = Vec::with_capacity(devices.len());
    for spec in devices {
        let decoder = match spec.protocol {
            DeviceKind::Wire(p) if args.protocol.is_none_or(|want| want == p) => {
                Some(decoder_with_settings(p, &spec.decoder).with_context(|| {
                    format!(
                        "{}: device {:?} has bad decoder settings",
                        args.file.display(),
                        spec.name
                    )
                })?)
            }
            _ => None,
        };
        decoders.push(decoder);
    }
    if decoders.iter().all(Option::is_none) {
        bail!(
            "{}: no device in this session speaks {}",
            args.file.display(),
            args.protocol
                .map_or("a wire protocol".to_owned(), |p| p.to_string())
        );
    }
    let mut events = Vec::new();
    for record in &session.records {
        let (at, device) = match record {
            Record::Chunk { at, device, .. } | Record::Opened { at, device } => (*at, *device),
            _ => continue,
        };
        let Some(Some(decoder)) = decoders.get_mut(device) else {
            continue;
        };
        match record {
            Record::Opened { .. } => decoder.reset(),
            Record::Chunk { bytes, .. } => {
                events.clear();
                decoder.feed(bytes, &mut events);
                let name = devices.get(device).map_or("?", |d| d.name.as_str());
                printer.print(&events, Some((at.as_secs_f64(), name)))?;
            }
            _ => {}
        }
    }
    for (device, decoder) in decoders.iter().enumerate() {
        if let Some(decoder) = decoder {
            events.clear();
            truncated_at_end(decoder.as_ref(), &mut events);
            let name = devices.get(device).map_or("?", |d| d.name.as_str());
            printer.print(&events, Some((session.duration().as_secs_f64(), name)))?;
        }
    }
    Ok(())
}

/// A partial packet left at the end of the input is reported as dropped.
fn truncated_at_end(decoder: &dyn Decoder, events: &mut Vec<DeviceEvent>) {
    let pending = decoder.pending();
    if pending > 0 {
        events.push(DeviceEvent::Dropped { bytes: pending });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn consecutive_drops_merge() {
        use leman::devices::fuzz_harness::merge_drops;
        let merged = merge_drops(vec![
            DeviceEvent::Dropped { bytes: 1 },
            DeviceEvent::Dropped { bytes: 2 },
            DeviceEvent::Buttons { pressed: vec![] },
            DeviceEvent::Dropped { bytes: 4 },
        ]);
        assert_eq!(
            merged,
            vec![
                DeviceEvent::Dropped { bytes: 3 },
                DeviceEvent::Buttons { pressed: vec![] },
                DeviceEvent::Dropped { bytes: 4 },
            ]
        );
    }

    #[test]
    fn default_args_match_the_clap_defaults() {
        // `Args::default()` is used by `run` wiring; the FASTRAK fields must still form a
        // valid decoder when filled from clap's defaults.
        let settings = FastrakSettings {
            items: vec![2, 4, 1],
            units: parse_unit("inches").unwrap_or_default(),
            stylus_bytes: 2,
        };
        assert_eq!(settings, FastrakSettings::default());
        assert_eq!(parse_unit("cm"), Ok(LengthUnit::Centimetres));
        assert!(parse_unit("feet").is_err());
    }
}
