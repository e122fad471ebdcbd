//! `ugv-can`: decode candump output with golf_car.dbc, encode messages for cansend.
//!
//! ```text
//! candump -L vcan0 | ugv-can decode            # or: candump vcan0 | ugv-can decode --json
//! cansend vcan0 $(ugv-can encode STEERING_CMD Enable=1 TargetAngle=12.5 MaxRate=60 --counter 3)
//! ```

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader, Write};
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand};
use golf_car_can::candump::{Compact, TextFrame, parse_line};
use golf_car_can::e2e::{E2eRx, protect};
use golf_car_can::{E2eError, MessageSpec, NETWORK, NetworkSpec, Payload, SignalSpec};

#[derive(Parser, Debug)]
#[command(
    name = "ugv-can",
    // `ugv-can 0.1.0 (golf-car-can)`: the binary, its crate's version and name.
    version = concat!(env!("CARGO_PKG_VERSION"), " (", env!("CARGO_PKG_NAME"), ")"),
    about = "Decode and encode golf car CAN frames (golf_car.dbc)"
)]
struct Cli {
    /// Use this DBC instead of the built-in golf_car.dbc.
    #[arg(long, global = true, value_name = "FILE")]
    dbc: Option<PathBuf>,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Decode candump lines (`candump -l` log form or plain `candump iface` form) from a
    /// file or stdin, checking E2E counter and CRC per interface.
    Decode {
        /// Input file; stdin when absent or `-`.
        input: Option<PathBuf>,
        /// One JSON object per frame instead of text.
        #[arg(long)]
        json: bool,
        /// Do not check E2E counters and CRCs.
        #[arg(long)]
        no_e2e: bool,
    },
    /// Encode a message from SIGNAL=value pairs into `ID#DATA`, counter and CRC filled in.
    /// Values are physical (e.g. TargetAngle=12.5) or value-table labels (Gear=forward);
    /// signals not given are raw 0.
    Encode {
        /// Message name (case-insensitive) or ID (0x100).
        message: String,
        /// SIGNAL=value pairs.
        signals: Vec<String>,
        /// The E2E rolling counter (0-15).
        #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u8).range(0..16))]
        counter: u8,
    },
    /// List the messages and signals of the DBC.
    List,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("ugv-can: {e:#}");
            ExitCode::from(2)
        }
    }
}

fn run(cli: Cli) -> Result<ExitCode> {
    let loaded;
    let network: &NetworkSpec = match &cli.dbc {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("reading {}", path.display()))?;
            loaded =
                NetworkSpec::from_dbc(&text).with_context(|| format!("in {}", path.display()))?;
            &loaded
        }
        None => &NETWORK,
    };
    match cli.command {
        Command::Decode {
            input,
            json,
            no_e2e,
        } => decode(network, input, json, !no_e2e),
        Command::Encode {
            message,
            signals,
            counter,
        } => {
            println!("{}", encode(network, &message, &signals, counter)?);
            Ok(ExitCode::SUCCESS)
        }
        Command::List => {
            list(network);
            Ok(ExitCode::SUCCESS)
        }
    }
}

/// Decimal places that show a signal's resolution.
fn decimals(s: &SignalSpec) -> usize {
    let places = -s.factor.abs().log10();
    if places <= 0.0 {
        0
    } else {
        (places.ceil() as usize).min(9)
    }
}

/// The longest line `decode` reads whole, bytes: far beyond any candump line (a
/// classic frame's log line is under 60); the head of a longer one is kept for the
/// error, the rest skipped, so memory stays bounded whatever the input.
const MAX_LINE: usize = 4096;

/// How much of a line an error message shows.
const LINE_EXCERPT_CHARS: usize = 120;

/// A line for an error message: quoted, cut at [`LINE_EXCERPT_CHARS`] characters with
/// a marker of how much was cut.
fn quoted(line: &str) -> String {
    let line = line.trim_end_matches(['\r', '\n']);
    match line.char_indices().nth(LINE_EXCERPT_CHARS) {
        None => format!("{line:?}"),
        Some((cut, _)) => format!(
            "{:?}... ({} more characters)",
            &line[..cut],
            line[cut..].chars().count()
        ),
    }
}

/// Read the next line (up to `\n`, which is dropped with a `\r` before it) into
/// `line`, keeping at most `max` bytes of it. Returns the line's whole length in bytes
/// (more than `max` when it was cut), or `None` at the end of the input.
fn read_line(
    reader: &mut impl BufRead,
    max: usize,
    line: &mut Vec<u8>,
) -> std::io::Result<Option<u64>> {
    line.clear();
    let mut length = 0u64;
    let mut any = false;
    loop {
        let chunk = match reader.fill_buf() {
            Ok(c) => c,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e),
        };
        if chunk.is_empty() {
            break;
        }
        any = true;
        let (part, used, done) = match chunk.iter().position(|&b| b == b'\n') {
            Some(i) => (&chunk[..i], i + 1, true),
            None => (chunk, chunk.len(), false),
        };
        let room = max.saturating_sub(line.len()).min(part.len());
        line.extend_from_slice(&part[..room]);
        length += part.len() as u64;
        reader.consume(used);
        if done {
            break;
        }
    }
    if !any {
        return Ok(None);
    }
    if line.last() == Some(&b'\r') && length <= max as u64 {
        line.pop();
        length -= 1;
    }
    Ok(Some(length))
}

/// Decode candump lines from `input` (stdin when absent or `-`), one frame a line of
/// text or JSON on stdout, checking E2E per interface when `e2e`; a summary on stderr.
/// Fails (exit 1) when any line was malformed.
fn decode(
    network: &NetworkSpec,
    input: Option<PathBuf>,
    json: bool,
    e2e: bool,
) -> Result<ExitCode> {
    let mut reader = open_input(input)?;
    let mut out = std::io::stdout().lock();
    let mut receivers: BTreeMap<String, E2eRx<'_>> = BTreeMap::new();
    let (mut frames, mut malformed) = (0u64, 0u64);
    let mut bytes = Vec::new();
    let mut n = 0u64;
    loop {
        n += 1;
        let length = match read_line(&mut reader, MAX_LINE, &mut bytes)
            .with_context(|| format!("reading line {n}"))?
        {
            None => break,
            Some(length) => length,
        };
        let frame = match frame_of_line(n, length, &bytes) {
            Line::Blank => continue,
            Line::Malformed => {
                malformed += 1;
                continue;
            }
            Line::Frame(frame) => frame,
        };
        frames += 1;
        let iface = frame.interface.clone().unwrap_or_default();
        let e2e_result = e2e.then(|| {
            receivers
                .entry(iface.clone())
                .or_insert_with(|| E2eRx::new(network))
                .accept_parts(frame.id, frame.extended, frame.remote, &frame.data)
        });
        let message = (!frame.extended)
            .then(|| u16::try_from(frame.id).ok())
            .flatten()
            .and_then(|id| network.message(id));
        let payload = message.and_then(|_| golf_car_can::codec::payload("", &frame.data).ok());
        let decoded = Decoded {
            frame: &frame,
            iface: &iface,
            message,
            payload,
            e2e: e2e_result.as_ref().map(|r| r.as_ref().map(|_| ())),
        };
        if json {
            writeln!(out, "{}", decoded.json())?;
        } else {
            writeln!(out, "{}", decoded.text())?;
        }
    }
    out.flush()?;
    summarise(&receivers, frames, malformed)?;
    Ok(if malformed > 0 {
        ExitCode::FAILURE
    } else {
        ExitCode::SUCCESS
    })
}

/// The input to decode: the file, or stdin when absent or `-`.
fn open_input(input: Option<PathBuf>) -> Result<Box<dyn BufRead>> {
    Ok(match input.as_deref() {
        None => Box::new(BufReader::new(std::io::stdin())),
        Some(p) if p.as_os_str() == "-" => Box::new(BufReader::new(std::io::stdin())),
        Some(p) => Box::new(BufReader::new(
            std::fs::File::open(p).with_context(|| format!("opening {}", p.display()))?,
        )),
    })
}

/// What a line of the input holds.
enum Line {
    /// Nothing (blank or white space).
    Blank,
    /// Not a frame (too long, not UTF-8, not candump): reported on stderr.
    Malformed,
    Frame(TextFrame),
}

/// The frame on line `n` (`length` bytes in all, `bytes` of them kept); a malformed
/// line is reported on stderr.
fn frame_of_line(n: u64, length: u64, bytes: &[u8]) -> Line {
    if length > MAX_LINE as u64 {
        eprintln!(
            "ugv-can: line {n}: {length} bytes, longer than a candump line can be ({MAX_LINE}), skipped: {}",
            quoted(&String::from_utf8_lossy(bytes))
        );
        return Line::Malformed;
    }
    let line = match std::str::from_utf8(bytes) {
        Ok(line) => line,
        Err(e) => {
            eprintln!(
                "ugv-can: line {n}: not UTF-8 text (byte {:#04x} at offset {}), skipped: {}",
                bytes.get(e.valid_up_to()).copied().unwrap_or_default(),
                e.valid_up_to(),
                quoted(&String::from_utf8_lossy(bytes))
            );
            return Line::Malformed;
        }
    };
    if line.trim().is_empty() {
        return Line::Blank;
    }
    match parse_line(line) {
        Ok(f) => Line::Frame(f),
        Err(e) => {
            eprintln!("ugv-can: line {n}: {e}: {}", quoted(line));
            Line::Malformed
        }
    }
}

/// A frame as `decode` shows it: the frame, its interface (empty when not named), its
/// message and payload when the DBC has it, and the E2E check when made.
struct Decoded<'a> {
    frame: &'a TextFrame,
    iface: &'a str,
    message: Option<&'a MessageSpec>,
    payload: Option<Payload>,
    e2e: Option<Result<(), &'a E2eError>>,
}

impl Decoded<'_> {
    /// The frame as one JSON object.
    fn json(&self) -> serde_json::Value {
        let (frame, message) = (self.frame, self.message);
        let mut obj = serde_json::Map::new();
        if let Some(ts) = &frame.timestamp {
            obj.insert("timestamp".into(), ts.clone().into());
        }
        if !self.iface.is_empty() {
            obj.insert("interface".into(), self.iface.to_owned().into());
        }
        obj.insert("id".into(), frame.id.into());
        obj.insert("extended".into(), frame.extended.into());
        if let Some(m) = message {
            obj.insert("message".into(), m.name.to_string().into());
        }
        if let (Some(m), Some(p)) = (message, self.payload) {
            let signals: serde_json::Map<String, serde_json::Value> = m
                .decode_all(&p)
                .into_iter()
                .map(|v| {
                    (
                        v.name.to_owned(),
                        serde_json::to_value(&v).unwrap_or_default(),
                    )
                })
                .collect();
            obj.insert("signals".into(), signals.into());
        } else {
            let hex: String = frame.data.iter().map(|b| format!("{b:02X}")).collect();
            obj.insert("data".into(), hex.into());
        }
        match &self.e2e {
            Some(Ok(())) => {
                obj.insert("e2e".into(), "ok".into());
            }
            Some(Err(e)) => {
                obj.insert("e2e".into(), e.to_string().into());
            }
            None => {}
        }
        serde_json::Value::Object(obj)
    }

    /// The frame as one line of text: candump's compact form, then the message and its
    /// signals, then the E2E check.
    fn text(&self) -> String {
        let frame = self.frame;
        let mut text = String::new();
        if let Some(ts) = &frame.timestamp {
            text.push_str(&format!("({ts}) "));
        }
        if !self.iface.is_empty() {
            text.push_str(&format!("{} ", self.iface));
        }
        let compact = Compact {
            id: frame.id,
            extended: frame.extended,
            data: &frame.data,
        };
        text.push_str(&compact.to_string());
        match (self.message, self.payload) {
            (Some(m), Some(p)) => {
                text.push_str(&format!(" {}", m.name));
                for (s, v) in m.signals.iter().zip(m.decode_all(&p)) {
                    text.push_str(&format!(" {}={:.*}", v.name, decimals(s), v.value));
                    if !v.unit.is_empty() {
                        text.push_str(&format!(" {}", v.unit));
                    }
                    if let Some(label) = v.label {
                        text.push_str(&format!(" ({label})"));
                    }
                }
            }
            (Some(m), None) => text.push_str(&format!(" {}", m.name)),
            (None, _) => text.push_str(" (not in the DBC)"),
        }
        match &self.e2e {
            Some(Ok(())) => text.push_str(" [e2e ok]"),
            Some(Err(e)) => text.push_str(&format!(" [e2e REJECTED: {e}]")),
            None => {}
        }
        text
    }
}

/// The totals on stderr, and each interface's E2E statistics.
fn summarise(receivers: &BTreeMap<String, E2eRx<'_>>, frames: u64, malformed: u64) -> Result<()> {
    let rejected: u64 = receivers.values().map(|r| r.stats().rejected()).sum();
    eprintln!("ugv-can: {frames} frames, {rejected} rejected by E2E, {malformed} malformed lines");
    for (iface, rx) in receivers {
        let name = if iface.is_empty() {
            "(no interface)"
        } else {
            iface
        };
        eprintln!("ugv-can: {name}: {}", serde_json::to_string(&rx.stats())?);
    }
    Ok(())
}

fn encode(network: &NetworkSpec, key: &str, pairs: &[String], counter: u8) -> Result<String> {
    let Some(message) = network.find_message(key) else {
        let names: Vec<&str> = network.messages.iter().map(|m| m.name.as_ref()).collect();
        bail!(
            "no message {key:?} in the DBC (messages: {})",
            names.join(", ")
        );
    };
    let mut data = [0u8; 8];
    // The pair that set each signal so far: a second would silently override it.
    let mut given: BTreeMap<&str, &str> = BTreeMap::new();
    for pair in pairs {
        let Some((name, value)) = pair.split_once('=') else {
            bail!("{pair:?} is not SIGNAL=value");
        };
        let Some(signal) = message
            .signals
            .iter()
            .find(|s| s.name.eq_ignore_ascii_case(name))
        else {
            let names: Vec<&str> = message.signals.iter().map(|s| s.name.as_ref()).collect();
            bail!(
                "message {} has no signal {name:?} (signals: {})",
                message.name,
                names.join(", ")
            );
        };
        if signal.is_e2e() {
            bail!(
                "{} is filled in by the E2E protection; use --counter",
                signal.name
            );
        }
        if let Some(earlier) = given.insert(signal.name.as_ref(), pair) {
            bail!(
                "{} is given twice ({earlier:?} and {pair:?}): give each signal once",
                signal.name
            );
        }
        if let Some(v) = signal
            .values
            .iter()
            .find(|v| v.label.eq_ignore_ascii_case(value))
        {
            signal.set_raw(&mut data, i128::from(v.raw))?;
        } else {
            let physical: f64 = value.parse().map_err(|_| {
                let labels: Vec<&str> = signal.values.iter().map(|v| v.label.as_ref()).collect();
                anyhow::anyhow!(
                    "{}: {value:?} is neither a number nor a label{}",
                    signal.name,
                    if labels.is_empty() {
                        String::new()
                    } else {
                        format!(" ({})", labels.join(", "))
                    }
                )
            })?;
            signal.set(&mut data, physical)?;
        }
    }
    protect(message.id, &mut data, counter);
    Ok(Compact {
        id: u32::from(message.id),
        extended: false,
        data: &data,
    }
    .to_string())
}

fn list(network: &NetworkSpec) {
    println!("{} at {} bit/s", network.name, network.baudrate);
    for m in network.messages.iter() {
        let timing = match (m.cycle_time_ms, m.timeout_ms) {
            (Some(c), Some(t)) => format!("every {c} ms, timeout {t} ms"),
            (Some(c), None) => format!("every {c} ms"),
            (None, Some(t)) => format!("timeout {t} ms"),
            (None, None) => "on event".to_owned(),
        };
        println!(
            "{:#05x} {} from {} ({timing})",
            m.id,
            m.name,
            m.senders.join(", ")
        );
        for s in m.signals.iter() {
            let labels: Vec<String> = s
                .values
                .iter()
                .map(|v| format!("{}={}", v.raw, v.label))
                .collect();
            println!(
                "      {:<14} {}|{}@{}{} x{} +{} [{}, {}] {}{}",
                s.name,
                s.start_bit,
                s.size,
                if s.byte_order == golf_car_can::spec::ByteOrder::Intel {
                    1
                } else {
                    0
                },
                if s.signed { "-" } else { "+" },
                s.factor,
                s.offset,
                s.min,
                s.max,
                s.unit,
                if labels.is_empty() {
                    String::new()
                } else {
                    format!(" {{{}}}", labels.join(", "))
                }
            );
        }
    }
}
