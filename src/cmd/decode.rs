//! `leman decode`: runs one protocol decoder over a raw byte capture, or every device of a
//! recorded session through its own decoder, and prints one event per line.

use anyhow::{Context, bail};
use leman::devices::decoder::Decoder;
use leman::devices::fastrak::{FastrakSettings, LengthUnit};
use leman::devices::fuzz_harness::merge_drops;
use leman::devices::opentrack::DATAGRAM_LEN;
use leman::devices::profile::DeviceKind;
use leman::devices::protocol::{DecoderSettings, Framing, Protocol, decoder_with_settings};
use leman::devices::sample::DeviceEvent;
use leman::devices::session::{Record, Session};
use leman::devices::spacemouse_hid::split_length_prefixed;
use std::io::Write;
use std::path::PathBuf;

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
    /// Feed a raw stream capture in chunks of this many bytes (default: all at once) to
    /// reproduce fragmented reads; the output does not depend on it (consecutive drops are
    /// merged into one `dropped` event).
    #[arg(long)]
    pub chunk: Option<usize>,
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
    let mut events = Vec::new();
    match (protocol, protocol.framing()) {
        (Protocol::SpacemouseHid, _) => {
            let (reports, trailing) = split_length_prefixed(bytes);
            for report in reports {
                decoder.feed(report, &mut events);
            }
            if trailing > 0 {
                events.push(DeviceEvent::Dropped { bytes: trailing });
                tracing::warn!(
                    "{}: last {trailing} bytes do not form a whole length-prefixed report",
                    args.file.display()
                );
            }
        }
        (_, Framing::Message) => {
            // OpenTrack: consecutive datagrams; a short tail is fed as one (and rejected).
            for datagram in bytes.chunks(DATAGRAM_LEN) {
                decoder.feed(datagram, &mut events);
            }
        }
        (_, Framing::Stream) => {
            let chunk = args.chunk.unwrap_or(bytes.len()).max(1);
            for piece in bytes.chunks(chunk) {
                decoder.feed(piece, &mut events);
            }
            truncated_at_end(decoder.as_ref(), &mut events);
        }
    }
    printer.print(&merge_drops(events), None)?;
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
