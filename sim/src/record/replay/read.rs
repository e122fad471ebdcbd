//! Reading a recording back for replay, and refusing what cannot be replayed: a
//! damaged file (a record that fails its CRC or its own lengths, [`scan`]), message
//! times outside the run ([`check_times`]), a channel or metadata a replay needs
//! missing or invalid ([`check_channels`]); all before anything is replayed, each
//! error naming the file and, where there is one, the byte offset.

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use firmware_bridge::laser::LaserFrame;
use foxglove::Decode;
use foxglove::schemas::LaserScan;
use golf_car_can::spec::NetworkSpec;
use ugv_controller::config::ControllerConfig;
use ugv_controller::control::COMMAND_PERIOD;

use super::scan::{self, RawMessage, ScanError, Scanned};
use crate::record::{CONFIG_ATTACHMENT, RUN_METADATA, RunInfo, direction, topics};

/// Why a recording cannot be replayed.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    #[error("reading {path}: {source}")]
    Read {
        path: String,
        #[source]
        source: std::io::Error,
    },
    #[error("{path} is not an MCAP file: {source}")]
    NotMcap {
        path: String,
        #[source]
        source: mcap::McapError,
    },
    #[error(
        "{path} is not a ugv-hil recording: it has no {RUN_METADATA:?} metadata record (or it was cut off before one)"
    )]
    Foreign { path: String },
    #[error("{path}: damaged at byte {offset}: {what}")]
    Damaged {
        path: String,
        offset: u64,
        what: String,
    },
    #[error(
        "{path}: damaged at byte {offset}: message {index} on {topic} has log time {log_time} ns, {message}"
    )]
    BadTime {
        path: String,
        offset: u64,
        index: usize,
        topic: String,
        log_time: u64,
        message: String,
    },
    #[error("{path}: metadata {RUN_METADATA:?}, field {field}: {message}")]
    BadInfo {
        path: String,
        field: String,
        message: String,
    },
    #[error("{path}: no {CONFIG_ATTACHMENT} attachment (the controller's configuration)")]
    NoConfig { path: String },
    #[error("{path}: {CONFIG_ATTACHMENT}: {source}")]
    Config {
        path: String,
        #[source]
        source: ugv_controller::config::ConfigError,
    },
    #[error(
        "{path}: no messages on {topic}: every recording has them from its start (the file is damaged, or cut before them)"
    )]
    MissingTopic { path: String, topic: &'static str },
    #[error("{path}: the channel {topic}: {message}")]
    BadChannel {
        path: String,
        topic: String,
        message: String,
    },
    #[error("{path}: message {index} on {topic} at byte {offset}: {message}")]
    BadMessage {
        path: String,
        index: usize,
        offset: u64,
        topic: String,
        message: String,
    },
    #[error("the controller: {0}")]
    Controller(#[from] ugv_controller::control::ControllerError),
    #[error("golf_car.dbc: {0}")]
    Dbc(#[from] golf_car_can::spec::SpecError),
    #[error("the controller's CAN port: {0}")]
    Bus(#[from] firmware_bridge::BridgeError),
}

impl ReplayError {
    /// Whether the recording itself is damaged or invalid (a record, a message time,
    /// a channel, the metadata or the attached configuration), as opposed to a file
    /// that cannot be read or is no recording at all, or a failure of the replay.
    pub fn is_damaged(&self) -> bool {
        matches!(
            self,
            ReplayError::Damaged { .. }
                | ReplayError::BadTime { .. }
                | ReplayError::BadInfo { .. }
                | ReplayError::NoConfig { .. }
                | ReplayError::Config { .. }
                | ReplayError::MissingTopic { .. }
                | ReplayError::BadChannel { .. }
                | ReplayError::BadMessage { .. }
        )
    }
}

/// The longest time between two messages, in the order the file holds them, ns: a
/// recording logs every step (the simulator's, 2 ms to 10 ms) or every tick (the
/// controller's own, 10 ms, with the ticks a stalled loop skipped logged as one
/// record), so a longer gap is a damaged time, not a pause.
pub const MAX_GAP_NS: u64 = 60_000_000_000;

/// The topics a replay feeds the controller from and compares against: every
/// recording has them from its start.
pub const REQUIRED_TOPICS: [&str; 3] = [topics::CAN_RAW, topics::NMEA, topics::LASER];

/// The GPS line's baud rate of a recording that does not say (the scenarios' default).
pub(super) const DEFAULT_GPS_BAUD: u32 = 115_200;

/// One input the controller received.
#[derive(Debug)]
pub(super) enum Input {
    Gps(Vec<u8>),
    Laser(Box<LaserFrame>),
    Can { id: u16, data: Vec<u8> },
}

/// A frame on the bus, at its log time.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(super) struct Command {
    pub ns: u64,
    pub id: u32,
    pub data: Vec<u8>,
}

/// A recording read back.
#[derive(Debug)]
pub struct Recorded {
    pub info: RunInfo,
    pub config: ControllerConfig,
    pub(super) inputs: Vec<(u64, Input)>,
    pub(super) commands: Vec<Command>,
    /// Where and why the recording stops being whole before the file's end: cut off by
    /// a kill, or entries its recorder lost ([`topics::CONTROLLER_DROPPED`]).
    pub truncated: Option<String>,
    /// A recording cut off by a kill, or whose recorder lost entries: every input and
    /// command before this instant (ns on the log time) is in the file, some at or
    /// after it may be lost. See [`whole_until`].
    pub whole_until_ns: Option<u64>,
    /// Frames the replay cannot inject (extended IDs: not on this bus).
    pub skipped: u64,
    /// The controller's own recording: when its loop took each replanning from its
    /// planning thread, controller seconds.
    pub(super) plans_taken_at: Vec<f64>,
    /// The controller's own recording: the ticks its loop skipped (first tick's
    /// index, how many).
    pub(super) ticks_skipped: Vec<(u64, u64)>,
    /// The controller's own recording: when it was asked to stop (a signal),
    /// controller seconds.
    pub(super) stop_requested: Option<f64>,
}

fn field<T: serde::de::DeserializeOwned>(
    path: &str,
    meta: &BTreeMap<String, String>,
    key: &str,
) -> Result<T, ReplayError> {
    let bad = |message: String| ReplayError::BadInfo {
        path: path.to_owned(),
        field: key.to_owned(),
        message,
    };
    let text = meta.get(key).ok_or_else(|| bad("missing".to_owned()))?;
    serde_json::from_str(text).map_err(|e| bad(e.to_string()))
}

fn f32_meta(meta: &BTreeMap<String, String>, key: &str) -> Result<f32, String> {
    meta.get(key)
        .ok_or_else(|| format!("its metadata has no {key}"))?
        .parse()
        .map_err(|e| format!("its metadata {key}: {e}"))
}

fn hex_bytes(text: &str) -> Option<Vec<u8>> {
    if !text.len().is_multiple_of(2) || text.len() > 16 {
        return None;
    }
    (0..text.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(text.get(i..i + 2)?, 16).ok())
        .collect()
}

impl Recorded {
    /// Read `path`; a file cut off (no summary, a partial last record) is read up to
    /// its last whole record, and [`Recorded::truncated`] says where it stopped.
    pub fn read(path: &Path) -> Result<Recorded, ReplayError> {
        let name = path.display().to_string();
        let bytes = std::fs::read(path).map_err(|source| ReplayError::Read {
            path: name.clone(),
            source,
        })?;
        Recorded::parse(&name, &bytes)
    }

    /// Read an MCAP held in memory; `name` names it in errors. Everything is checked
    /// before anything is decoded: the records ([`scan`]), the run's metadata and
    /// configuration, the channels ([`check_channels`]) and the message times
    /// ([`check_times`]).
    pub fn parse(name: &str, bytes: &[u8]) -> Result<Recorded, ReplayError> {
        let file = scan::scan(bytes).map_err(|e| match e {
            ScanError::NotMcap(source) => ReplayError::NotMcap {
                path: name.to_owned(),
                source,
            },
            ScanError::Damaged(d) => ReplayError::Damaged {
                path: name.to_owned(),
                offset: d.offset,
                what: d.what,
            },
        })?;
        let (info, config) = run_info(name, &file)?;
        let lasers = check_channels(name, &file)?;
        check_times(name, info.epoch_unix_ns, &file)?;
        let mut decoder = Decoder::new(name, &file, &info, lasers)?;
        for (index, m) in file.messages.iter().enumerate() {
            decoder.take(index, m)?;
        }
        let cut = file.cut.as_ref().map(|c| {
            let why = format!(
                "cut at byte {} of {}, after {} whole chunks: {}",
                c.offset,
                file.len,
                file.chunks.len(),
                c.why
            );
            (whole_until(&file, decoder.latest_remapped), why)
        });
        let lost = decoder.dropped.map(|(from, n)| {
            let why = format!(
                "the controller's recorder lost {n} entries from {:.3} s on (its queue was full)",
                decoder.seconds(from)
            );
            (from, why)
        });
        // Whole up to the earlier of a cut and a loss; both said.
        let whole_until_ns = cut.iter().chain(&lost).map(|(ns, _)| *ns).min();
        let truncated = cut
            .into_iter()
            .chain(lost)
            .map(|(_, why)| why)
            .reduce(|a, b| format!("{a}; {b}"));
        let mut d = decoder;
        // In log-time order (HIL's CAN frames carry the kernel's receive times, the
        // rest the simulator's): the replay delivers each at the first tick after it.
        d.inputs.sort_by_key(|(ns, _)| *ns);
        d.commands.sort_by_key(|c| c.ns);
        Ok(Recorded {
            info,
            config,
            inputs: d.inputs,
            commands: d.commands,
            truncated,
            whole_until_ns,
            skipped: d.skipped,
            plans_taken_at: d.plans_taken_at,
            ticks_skipped: d.ticks_skipped,
            stop_requested: d.stop_requested,
        })
    }
}

/// Where a file cut by a kill stops being whole, ns on the log time.
///
/// Every recording logs in time order (the file's order is its log times' order), so
/// the messages logged before the last one read are all there, and only those at
/// its log time may be partly lost: everything before it is whole. A HIL
/// recording's CAN frames go on the kernel's receive times (`wall_unix_ns`), which
/// its tap reads in order: a frame lost with the cut came no earlier than the latest
/// one read, so everything before that instant is whole too. The earlier of the two.
fn whole_until(file: &Scanned<'_>, latest_remapped: Option<u64>) -> u64 {
    let last = file.messages.last().map_or(0, |m| m.log_time);
    latest_remapped.map_or(last, |k| k.min(last))
}

/// The run's metadata and the controller's configuration.
fn run_info(name: &str, file: &Scanned<'_>) -> Result<(RunInfo, ControllerConfig), ReplayError> {
    let meta = file
        .run_metadata
        .as_ref()
        .ok_or_else(|| ReplayError::Foreign {
            path: name.to_owned(),
        })?;
    let controller_toml = file
        .config
        .as_ref()
        .map(|c| String::from_utf8_lossy(c).into_owned())
        .ok_or_else(|| ReplayError::NoConfig {
            path: name.to_owned(),
        })?;
    let info = RunInfo {
        mode: field(name, meta, "mode")?,
        scenario: field(name, meta, "scenario")?,
        physics_hz: field(name, meta, "physics_hz")?,
        epoch_unix_ns: field(name, meta, "epoch_unix_ns")?,
        can_interface: field(name, meta, "can_interface")?,
        gps_sentences: field(name, meta, "gps_sentences")?,
        // Recordings made before the field: the scenarios' default line.
        gps_baud: match meta.contains_key("gps_baud") {
            true => field(name, meta, "gps_baud")?,
            false => DEFAULT_GPS_BAUD,
        },
        controller_toml,
    };
    if !(info.physics_hz.is_finite() && info.physics_hz > 0.0) {
        return Err(ReplayError::BadInfo {
            path: name.to_owned(),
            field: "physics_hz".to_owned(),
            message: format!("{} is not a positive rate", info.physics_hz),
        });
    }
    let config = ControllerConfig::from_toml(
        &info.controller_toml,
        &format!("{name}: {CONFIG_ATTACHMENT}"),
    )
    .map_err(|source| ReplayError::Config {
        path: name.to_owned(),
        source,
    })?;
    Ok((info, config))
}

/// Every message on a channel the file defines, messages on each of
/// [`REQUIRED_TOPICS`], and the laser's constant fields (its channels' metadata) a
/// valid scan's: the frame each laser channel's scans are filled into.
fn check_channels(
    name: &str,
    file: &Scanned<'_>,
) -> Result<HashMap<u16, Box<LaserFrame>>, ReplayError> {
    let mut counts: HashMap<&str, u64> = HashMap::new();
    for m in &file.messages {
        let Some(ch) = file.channels.get(&m.channel) else {
            return Err(ReplayError::Damaged {
                path: name.to_owned(),
                offset: m.offset,
                what: format!(
                    "a message on channel {}, which no channel record defines",
                    m.channel
                ),
            });
        };
        *counts.entry(ch.topic.as_str()).or_default() += 1;
    }
    if let Some(topic) = REQUIRED_TOPICS
        .into_iter()
        .find(|t| !counts.contains_key(t))
    {
        return Err(ReplayError::MissingTopic {
            path: name.to_owned(),
            topic,
        });
    }
    let mut lasers = HashMap::new();
    for ch in file.channels.values().filter(|c| c.topic == topics::LASER) {
        let frame = laser_template(&ch.metadata).map_err(|message| ReplayError::BadChannel {
            path: name.to_owned(),
            topic: ch.topic.clone(),
            message,
        })?;
        lasers.insert(ch.id, frame);
    }
    Ok(lasers)
}

/// A laser channel's constant fields (its metadata), checked as a scan's are
/// ([`LaserFrame::validate`], with one beam).
fn laser_template(meta: &BTreeMap<String, String>) -> Result<Box<LaserFrame>, String> {
    let mut f = Box::<LaserFrame>::default();
    f.angle_min = f32_meta(meta, "angle_min")?;
    f.angle_increment = f32_meta(meta, "angle_increment")?;
    f.time_increment = f32_meta(meta, "time_increment")?;
    f.scan_time = f32_meta(meta, "scan_time")?;
    f.range_min = f32_meta(meta, "range_min")?;
    f.range_max = f32_meta(meta, "range_max")?;
    f.set_beams(&[0.0], &[0.0]).map_err(|e| e.to_string())?;
    f.validate()
        .map_err(|e| format!("its metadata are no scan's: {e}"))?;
    Ok(f)
}

/// Message times within the run. Every recording logs in time order from its epoch,
/// so each message's log time must be
/// - at or after the epoch (the run's start),
/// - at or after the message before it in the file, and at most [`MAX_GAP_NS`] after
///   it,
/// - within its chunk's first and last times (the chunk's header), and at or before
///   the last one the summary's statistics give (a whole file).
fn check_times(name: &str, epoch: u64, file: &Scanned<'_>) -> Result<(), ReplayError> {
    let mut previous: Option<u64> = None;
    for (index, m) in file.messages.iter().enumerate() {
        let t = m.log_time;
        let s = |ns: u64| ns as f64 * 1e-9;
        let why = if t < epoch {
            Some(format!("{:.3} s before the run's start", s(epoch - t)))
        } else if let Some(p) = previous.filter(|p| t < *p) {
            Some(format!(
                "{:.3} s before the message before it (a recording logs in time order)",
                s(p - t)
            ))
        } else if let Some(p) = previous.filter(|p| t - p > MAX_GAP_NS) {
            Some(format!(
                "{:.3} s after the message before it (at most {:.0} s apart)",
                s(t - p),
                s(MAX_GAP_NS)
            ))
        } else if let Some((lo, hi)) = m.chunk_times.filter(|(lo, hi)| t < *lo || t > *hi) {
            Some(format!("outside its chunk's times {lo} to {hi} ns"))
        } else {
            file.end_time
                .filter(|end| t > *end)
                .map(|end| format!("{:.3} s after the recording's end", s(t - end)))
        };
        if let Some(message) = why {
            return Err(ReplayError::BadTime {
                path: name.to_owned(),
                offset: m.offset,
                index,
                topic: file
                    .channels
                    .get(&m.channel)
                    .map_or_else(String::new, |c| c.topic.clone()),
                log_time: t,
                message,
            });
        }
        previous = Some(t);
    }
    Ok(())
}

/// The messages decoded into the controller's inputs and commands.
struct Decoder<'a> {
    name: &'a str,
    channels: &'a HashMap<u16, mcap::records::Channel>,
    spec: NetworkSpec,
    lasers: HashMap<u16, Box<LaserFrame>>,
    epoch_ns: u64,
    /// HIL: the wall clock at simulated time 0 ([`hil_wall_offset`]).
    wall_offset: Option<i128>,
    /// The latest CAN frame's time taken from its kernel receive time.
    latest_remapped: Option<u64>,
    inputs: Vec<(u64, Input)>,
    commands: Vec<Command>,
    skipped: u64,
    plans_taken_at: Vec<f64>,
    ticks_skipped: Vec<(u64, u64)>,
    stop_requested: Option<f64>,
    /// The controller's own recording: the first entry its recorder lost (ns on the
    /// log time), and how many it lost in all.
    dropped: Option<(u64, u64)>,
}

/// HIL: a CAN frame's log time is the tick that read it, its kernel receive time
/// rides along (wall_unix_ns). The simulator stamps each NMEA sentence with the wall
/// clock when it handled the tick (never before the tick's deadline), so the smallest
/// wall - log difference is the wall clock at simulated time 0, to within the least
/// late tick: the frames go on the log time at their kernel time through it.
fn hil_wall_offset(file: &Scanned<'_>) -> Option<i128> {
    file.messages
        .iter()
        .filter(|m| {
            file.channels
                .get(&m.channel)
                .is_some_and(|c| c.topic == topics::NMEA)
        })
        .filter_map(|m| {
            let v: serde_json::Value = serde_json::from_slice(&m.data).ok()?;
            Some(i128::from(v["wall_unix_ns"].as_u64()?) - i128::from(m.log_time))
        })
        .min()
}

impl<'a> Decoder<'a> {
    fn new(
        name: &'a str,
        file: &'a Scanned<'_>,
        info: &RunInfo,
        lasers: HashMap<u16, Box<LaserFrame>>,
    ) -> Result<Decoder<'a>, ReplayError> {
        Ok(Decoder {
            name,
            channels: &file.channels,
            spec: NetworkSpec::from_dbc(golf_car_can::GOLF_CAR_DBC)?,
            lasers,
            epoch_ns: info.epoch_unix_ns,
            wall_offset: hil_wall_offset(file),
            latest_remapped: None,
            inputs: Vec::new(),
            commands: Vec::new(),
            skipped: 0,
            plans_taken_at: Vec::new(),
            ticks_skipped: Vec::new(),
            stop_requested: None,
            dropped: None,
        })
    }

    /// Controller seconds of log time `ns`.
    fn seconds(&self, ns: u64) -> f64 {
        (i128::from(ns) - i128::from(self.epoch_ns)) as f64 * 1e-9
    }

    /// Controller seconds `s` as ns on the log time, as the writer puts them there.
    fn ns(&self, s: f64) -> u64 {
        ugv_controller::record::log_ns(self.epoch_ns, s)
    }

    /// Message `index` of the file.
    fn take(&mut self, index: usize, m: &RawMessage<'_>) -> Result<(), ReplayError> {
        // Checked: every message is on a channel the file defines.
        let Some(ch) = self.channels.get(&m.channel) else {
            return Ok(());
        };
        let bad = |message: String| ReplayError::BadMessage {
            path: self.name.to_owned(),
            index,
            offset: m.offset,
            topic: ch.topic.clone(),
            message,
        };
        let json =
            || serde_json::from_slice::<serde_json::Value>(&m.data).map_err(|e| bad(e.to_string()));
        let ns = m.log_time;
        match ch.topic.as_str() {
            topics::NMEA => {
                let v = json()?;
                let s = v["sentence"]
                    .as_str()
                    .ok_or_else(|| bad("no \"sentence\" text".to_owned()))?;
                self.inputs
                    .push((ns, Input::Gps(format!("{s}\r\n").into_bytes())));
            }
            topics::LASER => {
                let scan = LaserScan::decode(&*m.data).map_err(|e| bad(e.to_string()))?;
                let mut frame = self
                    .lasers
                    .get(&m.channel)
                    .cloned()
                    .ok_or_else(|| bad("no laser channel".to_owned()))?;
                frame.stamp_ns = scan.timestamp.map_or(0, |t| t.total_nanos());
                let ranges: Vec<f32> = scan.ranges.iter().map(|r| *r as f32).collect();
                let intensities: Vec<f32> = scan.intensities.iter().map(|r| *r as f32).collect();
                frame
                    .set_beams(&ranges, &intensities)
                    .map_err(|e| bad(e.to_string()))?;
                self.inputs.push((ns, Input::Laser(frame)));
            }
            topics::CAN_RAW => self.can(ns, json()?).map_err(bad)?,
            topics::CONTROLLER_PLANNING => self.plans_taken_at.push(self.seconds(ns)),
            topics::CONTROLLER_STOP => {
                let at = self.seconds(ns);
                self.stop_requested.get_or_insert(at);
            }
            topics::CONTROLLER_SKIPPED => {
                let n = json()?["ticks"]
                    .as_u64()
                    .ok_or_else(|| bad("no numeric \"ticks\"".to_owned()))?;
                let first = (self.seconds(ns) / COMMAND_PERIOD).round().max(0.0) as u64;
                self.ticks_skipped.push((first, n));
            }
            topics::CONTROLLER_DROPPED => {
                let v = json()?;
                let (Some(from), Some(n)) = (v["from"].as_f64(), v["entries"].as_u64()) else {
                    return Err(bad("no numeric \"from\" and \"entries\"".to_owned()));
                };
                let from_ns = self.ns(from).min(ns);
                let (first, lost) = self.dropped.get_or_insert((from_ns, 0));
                *first = (*first).min(from_ns);
                *lost += n;
            }
            _ => {}
        }
        Ok(())
    }

    /// A `/can/raw` frame at log time `ns`: a command when the controller sent it, an
    /// input otherwise. The controller's own recording says which (`sent`: its port
    /// hears every frame on its IDs, a second sender's too); the simulator's, which
    /// sees the bus, goes by the DBC's senders (`direction`).
    fn can(&mut self, ns: u64, v: serde_json::Value) -> Result<(), String> {
        let id = v["id"]
            .as_u64()
            .and_then(|i| u32::try_from(i).ok())
            .ok_or_else(|| "no numeric \"id\"".to_owned())?;
        let bytes = v["data"]
            .as_str()
            .and_then(hex_bytes)
            .ok_or_else(|| "\"data\" is not 0 to 8 hex bytes".to_owned())?;
        let extended = v["extended"].as_bool().unwrap_or(false);
        let ns = match (self.wall_offset, v["wall_unix_ns"].as_u64()) {
            (Some(offset), Some(wall)) => {
                let at = u64::try_from(i128::from(wall) - offset).unwrap_or(ns);
                if at.abs_diff(ns) > MAX_GAP_NS {
                    return Err(format!(
                        "its kernel receive time (wall_unix_ns {wall}) is {:.3} s from its log time",
                        at.abs_diff(ns) as f64 * 1e-9
                    ));
                }
                self.latest_remapped = self.latest_remapped.max(Some(at));
                at
            }
            _ => ns,
        };
        let sent = v["sent"]
            .as_bool()
            .unwrap_or_else(|| direction(&self.spec, id) == "rx");
        if sent {
            self.commands.push(Command {
                ns,
                id,
                data: bytes,
            });
            return Ok(());
        }
        match u16::try_from(id) {
            Ok(id) if !extended && id < 0x800 => {
                self.inputs.push((ns, Input::Can { id, data: bytes }))
            }
            _ => self.skipped += 1,
        }
        Ok(())
    }
}
