//! Replay: a recording's GPS bytes, laser frames and ECU reports fed into the
//! controller library (its loop on memory ports) in lockstep, and the commands it
//! sends compared with the recorded ones.
//!
//! Inputs go in at the controller tick at or after their log time, as SIL's loop
//! delivers them; the controller ticks on SIL's grid (every `COMMAND_PERIOD` on the
//! physics steps). A SIL recording therefore replays byte for byte
//! ([`Tolerance::EXACT`]). A HIL recording was made with the controller in a process of
//! its own, on its own clock and behind a paced serial line, so its commands come at
//! other instants than the replay's: it is compared with [`Tolerance::HIL`], which
//! pairs each replayed command with the recorded one of the same message nearest in
//! time and compares signal values within bounds (README, "Replay"). The controller's
//! own recording (`ugv-controller run --log`: on the car, on the bench, beside a HIL
//! run) holds every input at the tick that took it, the ticks its loop skipped and
//! the ticks it took each replanning at and the one it was asked to stop at: it
//! replays byte for byte too.

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use embedded_can::Frame;
use firmware_bridge::CanPort;
use firmware_bridge::can::membus::{MemBus, MemEndpoint, MemFrame};
use firmware_bridge::laser::LaserFrame;
use firmware_bridge::nmea::ReaderConfig;
use foxglove::Decode;
use foxglove::schemas::LaserScan;
use golf_car_can::spec::NetworkSpec;
use serde::Serialize;
use ugv_controller::config::ControllerConfig;
use ugv_controller::core::{COMMAND_PERIOD, Controller};
use ugv_controller::runtime::{MemGps, MemLaser, Runtime};
use ugv_controller::trace::TraceWriter;

use super::tap::{BusTap, TapFrame};
use super::{CONFIG_ATTACHMENT, RUN_METADATA, RecordMode, RunInfo, direction, topics};

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
    #[error("{path}: message {index} on {topic}: {message}")]
    BadMessage {
        path: String,
        index: usize,
        topic: String,
        message: String,
    },
    #[error("the controller: {0}")]
    Controller(#[from] ugv_controller::core::ControllerError),
    #[error("golf_car.dbc: {0}")]
    Dbc(#[from] golf_car_can::spec::SpecError),
    #[error("the controller's CAN port: {0}")]
    Bus(#[from] firmware_bridge::BridgeError),
}

/// One input the controller received.
#[derive(Debug)]
enum Input {
    Gps(Vec<u8>),
    Laser(Box<LaserFrame>),
    Can { id: u16, data: Vec<u8> },
}

/// A frame on the bus, at its log time.
#[derive(Clone, Debug, PartialEq, Eq)]
struct Command {
    ns: u64,
    id: u32,
    data: Vec<u8>,
}

/// A recording read back.
#[derive(Debug)]
pub struct Recorded {
    pub info: RunInfo,
    pub config: ControllerConfig,
    inputs: Vec<(u64, Input)>,
    commands: Vec<Command>,
    /// Why reading stopped before the file's end (a recording cut off by a kill).
    pub truncated: Option<String>,
    /// Frames the replay cannot inject (extended IDs: not on this bus).
    pub skipped: u64,
    /// The controller's own recording: when its loop took each replanning from its
    /// planning thread, controller seconds.
    plans_taken_at: Vec<f64>,
    /// The controller's own recording: the ticks its loop skipped (first tick's
    /// index, how many).
    ticks_skipped: Vec<(u64, u64)>,
    /// The controller's own recording: when it was asked to stop (a signal),
    /// controller seconds.
    stop_requested: Option<f64>,
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
        .ok_or_else(|| format!("the channel's metadata has no {key}"))?
        .parse()
        .map_err(|e| format!("the channel's metadata {key}: {e}"))
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

    /// Read an MCAP held in memory; `name` names it in errors.
    pub fn parse(name: &str, bytes: &[u8]) -> Result<Recorded, ReplayError> {
        use mcap::records::Record;
        let options = mcap::read::Options::IgnoreEndMagic.into();
        let reader =
            mcap::read::ChunkFlattener::new_with_options(bytes, options).map_err(|source| {
                ReplayError::NotMcap {
                    path: name.to_owned(),
                    source,
                }
            })?;
        let mut channels: HashMap<u16, mcap::records::Channel> = HashMap::new();
        let mut info_meta = None;
        let mut config_text = None;
        let mut messages = Vec::new();
        let mut truncated = None;
        for (n, record) in reader.enumerate() {
            match record {
                Ok(Record::Channel(c)) => {
                    channels.insert(c.id, c);
                }
                Ok(Record::Metadata(m)) if m.name == RUN_METADATA => info_meta = Some(m.metadata),
                Ok(Record::Attachment { header, data, .. }) if header.name == CONFIG_ATTACHMENT => {
                    config_text = Some(String::from_utf8_lossy(&data).into_owned());
                }
                Ok(Record::Message { header, data }) => {
                    messages.push((header.channel_id, header.log_time, data.into_owned()));
                }
                Ok(_) => {}
                // Not even the first record: not an MCAP file.
                Err(source) if n == 0 => {
                    return Err(ReplayError::NotMcap {
                        path: name.to_owned(),
                        source,
                    });
                }
                Err(e) => {
                    truncated = Some(e.to_string());
                    break;
                }
            }
        }
        let meta = info_meta.ok_or_else(|| ReplayError::Foreign {
            path: name.to_owned(),
        })?;
        let info = RunInfo {
            mode: field(name, &meta, "mode")?,
            scenario: field(name, &meta, "scenario")?,
            physics_hz: field(name, &meta, "physics_hz")?,
            epoch_unix_ns: field(name, &meta, "epoch_unix_ns")?,
            can_interface: field(name, &meta, "can_interface")?,
            gps_sentences: field(name, &meta, "gps_sentences")?,
            // Recordings made before the field: the scenarios' default line.
            gps_baud: match meta.contains_key("gps_baud") {
                true => field(name, &meta, "gps_baud")?,
                false => DEFAULT_GPS_BAUD,
            },
            controller_toml: config_text.clone().ok_or_else(|| ReplayError::NoConfig {
                path: name.to_owned(),
            })?,
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
        let spec = NetworkSpec::from_dbc(golf_car_can::GOLF_CAR_DBC)?;
        let mut inputs = Vec::new();
        let mut commands = Vec::new();
        let mut skipped = 0;
        let mut plans_taken_at = Vec::new();
        let mut ticks_skipped = Vec::new();
        let mut stop_requested = None;
        let seconds = |ns: u64| (i128::from(ns) - i128::from(info.epoch_unix_ns)) as f64 * 1e-9;
        // HIL: a CAN frame's log time is the tick that read it, its kernel receive
        // time rides along (wall_unix_ns). The simulator stamps each NMEA sentence
        // with the wall clock when it handled the tick (never before the tick's
        // deadline), so the smallest wall - log difference is the wall clock at
        // simulated time 0, to within the least late tick: the frames go on the log
        // time at their kernel time through it.
        let nmea_channels: Vec<u16> = channels
            .values()
            .filter(|c| c.topic == topics::NMEA)
            .map(|c| c.id)
            .collect();
        let wall_offset: Option<i128> = messages
            .iter()
            .filter(|(channel, _, _)| nmea_channels.contains(channel))
            .filter_map(|(_, ns, data)| {
                let v: serde_json::Value = serde_json::from_slice(data).ok()?;
                Some(i128::from(v["wall_unix_ns"].as_u64()?) - i128::from(*ns))
            })
            .min();
        for (index, (channel, ns, data)) in messages.into_iter().enumerate() {
            let Some(ch) = channels.get(&channel) else {
                continue;
            };
            let bad = |message: String| ReplayError::BadMessage {
                path: name.to_owned(),
                index,
                topic: ch.topic.clone(),
                message,
            };
            let json = || {
                serde_json::from_slice::<serde_json::Value>(&data).map_err(|e| bad(e.to_string()))
            };
            match ch.topic.as_str() {
                topics::NMEA => {
                    let v = json()?;
                    let s = v["sentence"]
                        .as_str()
                        .ok_or_else(|| bad("no \"sentence\" text".to_owned()))?;
                    inputs.push((ns, Input::Gps(format!("{s}\r\n").into_bytes())));
                }
                topics::LASER => {
                    let scan =
                        LaserScan::decode(data.as_slice()).map_err(|e| bad(e.to_string()))?;
                    let frame = laser_frame(&ch.metadata, &scan).map_err(bad)?;
                    inputs.push((ns, Input::Laser(frame)));
                }
                topics::CAN_RAW => {
                    let v = json()?;
                    let id = v["id"]
                        .as_u64()
                        .and_then(|i| u32::try_from(i).ok())
                        .ok_or_else(|| bad("no numeric \"id\"".to_owned()))?;
                    let bytes = v["data"]
                        .as_str()
                        .and_then(hex_bytes)
                        .ok_or_else(|| bad("\"data\" is not 0 to 8 hex bytes".to_owned()))?;
                    let extended = v["extended"].as_bool().unwrap_or(false);
                    let ns = match (wall_offset, v["wall_unix_ns"].as_u64()) {
                        (Some(offset), Some(wall)) => {
                            u64::try_from(i128::from(wall) - offset).unwrap_or(ns)
                        }
                        _ => ns,
                    };
                    if direction(&spec, id) == "rx" {
                        commands.push(Command {
                            ns,
                            id,
                            data: bytes,
                        });
                    } else {
                        match u16::try_from(id) {
                            Ok(id) if !extended && id < 0x800 => {
                                inputs.push((ns, Input::Can { id, data: bytes }));
                            }
                            _ => skipped += 1,
                        }
                    }
                }
                topics::CONTROLLER_PLANNING => plans_taken_at.push(seconds(ns)),
                topics::CONTROLLER_STOP => {
                    stop_requested.get_or_insert(seconds(ns));
                }
                topics::CONTROLLER_SKIPPED => {
                    let n = json()?["ticks"]
                        .as_u64()
                        .ok_or_else(|| bad("no numeric \"ticks\"".to_owned()))?;
                    let first = (seconds(ns) / COMMAND_PERIOD).round().max(0.0) as u64;
                    ticks_skipped.push((first, n));
                }
                _ => {}
            }
        }
        // In log-time order (HIL's CAN frames carry the kernel's receive times, the
        // rest the simulator's): the replay delivers each at the first tick after it.
        inputs.sort_by_key(|(ns, _)| *ns);
        commands.sort_by_key(|c| c.ns);
        Ok(Recorded {
            info,
            config,
            inputs,
            commands,
            truncated,
            skipped,
            plans_taken_at,
            ticks_skipped,
            stop_requested,
        })
    }
}

/// The laser frame a `foxglove.LaserScan` of the recording carries (its constant
/// fields in the channel's metadata).
fn laser_frame(
    meta: &BTreeMap<String, String>,
    scan: &LaserScan,
) -> Result<Box<LaserFrame>, String> {
    let mut f = Box::<LaserFrame>::default();
    f.angle_min = f32_meta(meta, "angle_min")?;
    f.angle_increment = f32_meta(meta, "angle_increment")?;
    f.time_increment = f32_meta(meta, "time_increment")?;
    f.scan_time = f32_meta(meta, "scan_time")?;
    f.range_min = f32_meta(meta, "range_min")?;
    f.range_max = f32_meta(meta, "range_max")?;
    f.stamp_ns = scan.timestamp.map_or(0, |t| t.total_nanos());
    let ranges: Vec<f32> = scan.ranges.iter().map(|r| *r as f32).collect();
    let intensities: Vec<f32> = scan.intensities.iter().map(|r| *r as f32).collect();
    f.set_beams(&ranges, &intensities)
        .map_err(|e| e.to_string())?;
    Ok(f)
}

/// How close a replayed command must come to the recorded ones.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Tolerance {
    /// How far apart in time a replayed and a recorded command may be, seconds: a
    /// replayed command agrees when each signal lies within the range the recorded
    /// commands of its message take over +- this (an envelope in time).
    pub window_s: f64,
    /// How far each value signal may lie outside that range, in units of its DBC
    /// scale factor (0: the bytes must be equal, counter and CRC included). States,
    /// flags and gears must lie within it.
    pub steps: f64,
    /// Signals are judged from this long after the controller's start, seconds
    /// (before, its frames are only counted: missing or extra ones still diverge).
    pub settle_s: f64,
}

impl Tolerance {
    /// SIL: the same frames, bytes and instants.
    pub const EXACT: Tolerance = Tolerance {
        window_s: 0.0,
        steps: 0.0,
        settle_s: 0.0,
    };
    /// HIL: within five command periods (50 ms: the controller process sends on its
    /// own clock, up to 25 ms late in the emulated VM, and the replay ticks on SIL's
    /// grid), value signals within 10 scale steps (0.1 degree of steering, 0.1 m/s of
    /// speed, 5 % of brake), states, flags and gears within the range, all from 1.5 s
    /// after the controller's start; counter and CRC not compared (they follow the
    /// number of frames sent, which the two runs need not share). The settling: the
    /// recorded process read fixes before its first frame and got its first plans
    /// back from its planning thread at instants the recording cannot show, and its
    /// first paths, planned from that start, differ by up to a few degrees of steering
    /// until the replannings after them agree.
    pub const HIL: Tolerance = Tolerance {
        window_s: 5.0 * COMMAND_PERIOD,
        steps: 10.0,
        settle_s: 1.5,
    };

    /// SIL's recordings and the controller's own replay exactly (the same inputs at
    /// the same ticks, the replannings taken at the recorded ticks); HIL's within
    /// [`Tolerance::HIL`].
    pub fn for_mode(mode: RecordMode) -> Tolerance {
        match mode {
            RecordMode::Sil | RecordMode::Field => Tolerance::EXACT,
            RecordMode::Hil => Tolerance::HIL,
        }
    }
}

/// Where the replay first differed from the recording.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Divergence {
    /// Simulated seconds.
    pub time_s: f64,
    pub message: String,
    /// The first signal that differs (absent when a frame is missing or extra).
    pub signal: Option<String>,
    pub recorded: Option<String>,
    pub replayed: Option<String>,
}

/// Per message: commands compared and the largest signal difference.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct MessageStats {
    pub replayed: u64,
    pub recorded: u64,
    pub matched: u64,
    /// Largest |replayed - recorded| per signal, physical units.
    pub max_diff: BTreeMap<String, f64>,
}

/// What a replay found.
#[derive(Clone, Debug, Serialize)]
pub struct ReplayReport {
    pub scenario: String,
    pub mode: RecordMode,
    pub tolerance: Tolerance,
    /// When the replayed controller started, simulated seconds: 0 for SIL, the
    /// recorded controller's first frame for HIL.
    pub controller_start_s: f64,
    /// Simulated seconds replayed, from the controller's start.
    pub replayed_s: f64,
    pub inputs: u64,
    pub divergence: Option<Divergence>,
    pub messages: BTreeMap<String, MessageStats>,
    /// Why the recording ended before its file did, if it did.
    pub truncated: Option<String>,
    pub skipped_frames: u64,
    /// How the controller's loop ended during the replay, if it did.
    pub controller_exit: Option<String>,
    /// Why writing the replayed controller's trace stopped, if it did.
    pub trace_error: Option<String>,
}

impl ReplayReport {
    /// Whether the replay produced the recorded commands.
    pub fn identical(&self) -> bool {
        self.divergence.is_none()
    }
}

struct Comparer<'a> {
    spec: &'a NetworkSpec,
    tol: Tolerance,
    recorded: Vec<(Command, bool)>,
    /// Recorded commands before this index are matched or out of the window.
    first_open: usize,
    messages: BTreeMap<String, MessageStats>,
    divergence: Option<Divergence>,
    epoch_ns: u64,
    /// Value signals are judged from this instant (the controller's start plus the
    /// tolerance's settling), ns on the log time.
    judged_from_ns: u64,
}

impl Comparer<'_> {
    fn name(&self, id: u32) -> String {
        u16::try_from(id)
            .ok()
            .and_then(|i| self.spec.message(i))
            .map_or_else(|| format!("{id:#x}"), |m| m.name.to_string())
    }

    /// Simulated seconds of log time `ns`: negative before the simulator's clock
    /// started (a controller on its own board sends while the simulator waits for it).
    fn time(&self, ns: u64) -> f64 {
        (i128::from(ns) - i128::from(self.epoch_ns)) as f64 * 1e-9
    }

    fn diverge(&mut self, d: Divergence) {
        if self.divergence.is_none() {
            self.divergence = Some(d);
        }
    }

    /// Signals of a frame: name, physical value and the difference allowed (Counter
    /// and Crc left out unless exact). A state, a flag or a gear (a signal with a
    /// value table, or of one bit) must agree exactly: ten steps of a mode are
    /// another mode.
    fn signals(&self, id: u32, data: &[u8]) -> Vec<(String, f64, f64)> {
        let Some(m) = u16::try_from(id).ok().and_then(|i| self.spec.message(i)) else {
            return Vec::new();
        };
        let Ok(p) = golf_car_can::codec::payload("", data) else {
            return Vec::new();
        };
        m.signals
            .iter()
            .zip(m.decode_all(&p))
            .filter(|(_, v)| self.tol.steps == 0.0 || !matches!(v.name, "Counter" | "Crc"))
            .map(|(s, v)| {
                let allowed = if s.size == 1 || !s.values.is_empty() {
                    0.0
                } else {
                    self.tol.steps * s.factor.abs()
                };
                (v.name.to_owned(), v.value, allowed)
            })
            .collect()
    }

    /// Recorded commands that fell out of the window before `ns` without a match.
    fn close_before(&mut self, ns: u64) {
        let window = (self.tol.window_s * 1e9).round() as u64;
        while let Some((c, matched)) = self.recorded.get(self.first_open) {
            if c.ns.saturating_add(window) >= ns {
                break;
            }
            if !matched {
                let d = Divergence {
                    time_s: self.time(c.ns),
                    message: self.name(c.id),
                    signal: None,
                    recorded: Some(hex(&c.data)),
                    replayed: None,
                };
                self.diverge(d);
            }
            self.first_open += 1;
        }
    }

    /// A replayed command: it agrees when some recorded command of the same message
    /// within the window agrees with it on every signal (an envelope in time: the two
    /// controllers may change a state or a value a tick or two apart), and every
    /// recorded command it agrees with is covered. It diverges when none does (the
    /// difference reported against the recorded command nearest in time), or when no
    /// recorded command of the message is within the window at all (an extra frame).
    fn replayed(&mut self, ns: u64, id: u32, data: &[u8]) {
        let name = self.name(id);
        self.messages.entry(name.clone()).or_default().replayed += 1;
        let window = (self.tol.window_s * 1e9).round() as u64;
        let candidates: Vec<usize> = (self.first_open..self.recorded.len())
            .take_while(|&i| self.recorded[i].0.ns <= ns + window)
            .filter(|&i| {
                let c = &self.recorded[i].0;
                c.id == id && c.ns + window >= ns
            })
            .collect();
        let Some(&nearest) = candidates
            .iter()
            .min_by_key(|&&i| self.recorded[i].0.ns.abs_diff(ns))
        else {
            let d = Divergence {
                time_s: self.time(ns),
                message: name,
                signal: None,
                recorded: None,
                replayed: Some(hex(data)),
            };
            self.diverge(d);
            return;
        };
        // While the controller settles, its signals are not judged (its frames are
        // counted all the same).
        let settling = ns < self.judged_from_ns;
        let ours: Vec<(String, f64, f64)> = self
            .signals(id, data)
            .into_iter()
            .map(|(n, v, allowed)| (n, v, if settling { f64::INFINITY } else { allowed }))
            .collect();
        // Per signal, the recorded values' range over the window, and how far outside
        // it the replayed value lies.
        let mut range: Vec<(f64, f64)> = vec![(f64::INFINITY, f64::NEG_INFINITY); ours.len()];
        let mut same_bytes = false;
        for &i in &candidates {
            let rec = &self.recorded[i].0;
            same_bytes |= data == rec.data.as_slice();
            for (k, (_, b, _)) in self
                .signals(id, &rec.data)
                .iter()
                .enumerate()
                .take(ours.len())
            {
                range[k] = (range[k].0.min(*b), range[k].1.max(*b));
            }
        }
        let least: Vec<f64> = ours
            .iter()
            .zip(&range)
            .map(|((_, a, _), (lo, hi))| (lo - a).max(a - hi).max(0.0))
            .collect();
        let agreed = (self.tol.steps > 0.0 || same_bytes || settling)
            && ours
                .iter()
                .zip(&least)
                .all(|((_, _, allowed), diff)| *diff <= allowed + 1e-9);
        if agreed {
            for &i in &candidates {
                self.recorded[i].1 = true;
            }
        }
        let stats = self.messages.entry(name.clone()).or_default();
        for ((signal, _, allowed), diff) in ours.iter().zip(&least) {
            if allowed.is_infinite() {
                continue;
            }
            let max = stats.max_diff.entry(signal.clone()).or_insert(0.0);
            *max = max.max(*diff);
        }
        if agreed {
            stats.matched += 1;
            return;
        }
        let rec = self.recorded[nearest].0.clone();
        let theirs = self.signals(id, &rec.data);
        // The first signal outside the envelope, with the nearest recorded value.
        let (signal, recorded, replayed) = ours
            .iter()
            .zip(&theirs)
            .zip(&least)
            .find(|(((_, _, allowed), _), diff)| **diff > allowed + 1e-9)
            .map_or(
                ("(bytes)".to_owned(), 0.0, 0.0),
                |(((n, a, _), (_, b, _)), _)| (n.clone(), *b, *a),
            );
        let d = Divergence {
            time_s: self.time(ns),
            message: name,
            recorded: Some(format!("{recorded} ({})", hex(&rec.data))),
            replayed: Some(format!("{replayed} ({})", hex(data))),
            signal: Some(signal),
        };
        self.diverge(d);
    }
}

fn hex(data: &[u8]) -> String {
    data.iter().map(|b| format!("{b:02X}")).collect()
}

/// The GPS line's baud rate of a recording that does not say (the scenarios' default).
const DEFAULT_GPS_BAUD: u32 = 115_200;

/// The recorded inputs in the order they reached the controller, each with that time
/// (ns on the log time). SIL: at their log time (memory ports). HIL: a GPS sentence
/// once its last byte crossed the line at the baud rate (ten bits a byte), the line
/// carrying the sentences one after the other from when the simulator queued them;
/// laser frames and CAN frames at their log time (the publish time, the kernel's
/// receive time).
fn arrivals(rec: &Recorded) -> Vec<(u64, &Input)> {
    let ns_per_byte = 10.0 * 1e9 / f64::from(rec.info.gps_baud.max(1));
    let mut line_free = 0u64;
    let mut out: Vec<(u64, &Input)> = rec
        .inputs
        .iter()
        .map(|(ns, input)| match (rec.info.mode, input) {
            (RecordMode::Hil, Input::Gps(bytes)) => {
                let end = (*ns).max(line_free) + (bytes.len() as f64 * ns_per_byte) as u64;
                line_free = end;
                (end, input)
            }
            _ => (*ns, input),
        })
        .collect();
    out.sort_by_key(|(ns, _)| *ns);
    out
}

/// The controller's ticks to replay: (its clock, ns on the log time by which the
/// tick's inputs had arrived): every `COMMAND_PERIOD` on the physics steps from
/// `start_ns` to `last_ns`, as the SIL loop ran it. A HIL recording is replayed on the
/// same grid from the recorded controller's start (its own ticks, read off the bursts
/// of frames it sent, replayed worse in the recordings measured: README, "Replay").
/// The controller's own recording: its loop's ticks, less those it skipped.
fn ticks(rec: &Recorded, start_ns: u64, last_ns: u64) -> impl Iterator<Item = (f64, u64)> {
    let ns_of = move |t: f64| start_ns + (t.max(0.0) * 1e9).round() as u64;
    let dt = 1.0 / rec.info.physics_hz;
    let control_every = ((COMMAND_PERIOD / dt).round() as u64).max(1);
    let skipped = rec.ticks_skipped.clone();
    (0..)
        .map(move |k: u64| (k * control_every) as f64 * dt)
        .map(move |now| (now, ns_of(now)))
        .take_while(move |(_, ns)| *ns <= last_ns)
        .filter(move |(now, _)| {
            let k = (now / COMMAND_PERIOD).round() as u64;
            !skipped
                .iter()
                .any(|&(first, n)| (first..first + n).contains(&k))
        })
}

/// How many bytes of NMEA a serial line (a pty's or a tty's receive buffer) keeps for
/// a reader that has not opened it yet: Linux's N_TTY buffer.
const LINE_BUFFER: usize = 4096;

/// Where the replayed controller's clock starts, nanoseconds on the recording's log
/// time. SIL and the controller's own recording: at the recording's epoch, as the
/// controller's loop did. HIL: at the
/// recorded controller's first frame, since its process started on its own clock some
/// time after the simulator began recording (a controller that starts at the epoch
/// would wait for ECUs that the recording shows enabling only later, and estop).
fn controller_start(rec: &Recorded) -> u64 {
    match rec.info.mode {
        RecordMode::Sil | RecordMode::Field => rec.info.epoch_unix_ns,
        RecordMode::Hil => rec
            .commands
            .first()
            .map_or(rec.info.epoch_unix_ns, |c| c.ns),
    }
}

/// How long before its first frame the recorded controller's CAN socket is taken to
/// have been open: its start-up (socket opened, first inputs read, first tick) within
/// one command period of sending.
const SOCKET_OPEN_BEFORE_NS: u64 = 10_000_000;

/// What a controller starting at `start_ns` finds waiting on its ports, and the index
/// of the first input after that. The GPS line keeps the newest whole sentences that
/// fit its buffer, the laser service keeps its newest frame (the subscriber's
/// history), and a CAN socket holds the frames sent since it was opened
/// ([`SOCKET_OPEN_BEFORE_NS`] before the first frame the controller sent: the
/// reports its first tick read, and why that tick already enabled the ECUs).
fn waiting_at_start<'a>(arrived: &[(u64, &'a Input)], start_ns: u64) -> (Vec<&'a Input>, usize) {
    let first_after = arrived.partition_point(|(ns, _)| *ns < start_ns);
    let before = &arrived[..first_after];
    let mut waiting = Vec::new();
    let mut line_bytes = 0;
    let opened = start_ns.saturating_sub(SOCKET_OPEN_BEFORE_NS);
    for &(ns, input) in before.iter().rev() {
        match input {
            Input::Can { .. } if ns >= opened => waiting.push(input),
            Input::Gps(bytes) if line_bytes + bytes.len() <= LINE_BUFFER => {
                line_bytes += bytes.len();
                waiting.push(input);
            }
            // The line is full: older sentences were lost.
            Input::Gps(_) => line_bytes = LINE_BUFFER + 1,
            Input::Laser(_) if !waiting.iter().any(|i| matches!(i, Input::Laser(_))) => {
                waiting.push(input);
            }
            Input::Laser(_) | Input::Can { .. } => {}
        }
    }
    waiting.reverse();
    (waiting, first_after)
}

/// An input onto the replayed controller's ports; a CAN frame from the ECUs' side of
/// the bus (a standard ID, checked when read, and at most 8 bytes; the memory bus never
/// fails).
fn feed(rt: &mut Runtime<MemGps, MemLaser, MemEndpoint>, ecus: &mut MemEndpoint, input: &Input) {
    match input {
        Input::Gps(bytes) => rt.gps_mut().push(bytes),
        Input::Laser(frame) => rt.laser_mut().push(frame.clone()),
        Input::Can { id, data } => {
            if let Some(f) =
                embedded_can::StandardId::new(*id).and_then(|sid| MemFrame::new(sid, data))
            {
                let _ = embedded_can::nb::Can::transmit(ecus, &f);
            }
        }
    }
}

/// Replay `rec` into the controller library and compare its commands with the
/// recorded ones within `tol`; `trace`, when given, gets the replayed controller's
/// trace (the format of the binary's `--trace`, to set beside the recorded
/// `controller-trace.jsonl`).
pub fn replay(
    rec: &Recorded,
    tol: Tolerance,
    trace: Option<TraceWriter>,
) -> Result<ReplayReport, ReplayError> {
    let spec = NetworkSpec::from_dbc(golf_car_can::GOLF_CAR_DBC)?;
    let bus = MemBus::new();
    // The binary replans on a thread: in HIL its plan is taken at the next tick; its
    // own recording says at which.
    let controller = match rec.info.mode {
        RecordMode::Sil => Controller::new(&rec.config)?,
        RecordMode::Hil => Controller::new(&rec.config)?.with_plans_taken_next_tick(),
        RecordMode::Field => {
            Controller::new(&rec.config)?.with_plans_taken_at(rec.plans_taken_at.clone())
        }
    };
    let can = CanPort::new(bus.endpoint(), "replay");
    ugv_controller::runtime::accept_controller_ids(&can)?;
    let mut rt = Runtime::new(
        controller,
        MemGps::new(ReaderConfig {
            complete_when: rec.info.gps_sentences,
            ..ReaderConfig::default()
        }),
        MemLaser::default(),
        can,
    );
    if let Some(w) = trace {
        rt = rt.with_trace(w);
    }
    // The ECUs' side of the bus: recorded reports go out, the controller's come in.
    let mut ecus: MemEndpoint = bus.endpoint();
    let mut heard: Vec<TapFrame> = Vec::new();
    let start_ns = controller_start(rec);
    let mut cmp = Comparer {
        spec: &spec,
        tol,
        recorded: rec.commands.iter().cloned().map(|c| (c, false)).collect(),
        first_open: 0,
        messages: BTreeMap::new(),
        divergence: None,
        epoch_ns: rec.info.epoch_unix_ns,
        judged_from_ns: start_ns + (tol.settle_s * 1e9).round() as u64,
    };
    for c in &rec.commands {
        let name = cmp.name(c.id);
        cmp.messages.entry(name).or_default().recorded += 1;
    }
    let last_ns = rec
        .inputs
        .last()
        .map(|(ns, _)| *ns)
        .max(rec.commands.last().map(|c| c.ns))
        .unwrap_or(rec.info.epoch_unix_ns);
    let arrived = arrivals(rec);
    let (backlog, mut next_input) = waiting_at_start(&arrived, start_ns);
    for input in backlog {
        feed(&mut rt, &mut ecus, input);
    }
    let mut exit = None;
    let mut replayed_s = 0.0;
    for (now, tick_ns) in ticks(rec, start_ns, last_ns) {
        while let Some((ns, input)) = arrived.get(next_input) {
            if *ns > tick_ns {
                break;
            }
            feed(&mut rt, &mut ecus, input);
            next_input += 1;
        }
        if rec.stop_requested.is_some_and(|t| t <= now + 1e-6) {
            rt.request_stop(now);
        }
        if let Some(e) = rt.step(now) {
            exit = Some(e.describe());
        }
        replayed_s = now;
        // Only the controller talks to this endpoint (a node never hears itself).
        let _ = ecus.drain(&mut heard);
        cmp.close_before(tick_ns);
        for f in heard.drain(..) {
            cmp.replayed(tick_ns, f.id, &f.data);
        }
        if exit.is_some() {
            break;
        }
    }
    cmp.close_before(u64::MAX);
    if exit.is_none() {
        rt.finish_trace(replayed_s);
    }
    Ok(ReplayReport {
        scenario: rec.info.scenario.clone(),
        mode: rec.info.mode,
        tolerance: tol,
        controller_start_s: cmp.time(start_ns),
        replayed_s,
        inputs: next_input as u64,
        divergence: cmp.divergence,
        messages: cmp.messages,
        truncated: rec.truncated.clone(),
        skipped_frames: rec.skipped,
        controller_exit: exit,
        trace_error: rt.trace_error().map(str::to_owned),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn recording(mode: RecordMode, inputs: Vec<(u64, Input)>, commands: Vec<Command>) -> Recorded {
        Recorded {
            info: RunInfo {
                mode,
                scenario: "test".to_owned(),
                physics_hz: 200.0,
                epoch_unix_ns: 1_000,
                can_interface: "vcan0".to_owned(),
                gps_sentences: ReaderConfig::default().complete_when,
                gps_baud: DEFAULT_GPS_BAUD,
                controller_toml: String::new(),
            },
            config: ControllerConfig::default(),
            inputs,
            commands,
            truncated: None,
            skipped: 0,
            plans_taken_at: Vec::new(),
            ticks_skipped: Vec::new(),
            stop_requested: None,
        }
    }

    fn heartbeat(ns: u64) -> Command {
        Command {
            ns,
            id: 0x100,
            data: vec![0; 8],
        }
    }

    #[test]
    fn a_hil_controller_starts_at_its_first_frame_and_a_sil_one_at_the_epoch() {
        let commands = vec![heartbeat(5_000), heartbeat(6_000)];
        let hil = recording(RecordMode::Hil, Vec::new(), commands.clone());
        assert_eq!(controller_start(&hil), 5_000);
        let sil = recording(RecordMode::Sil, Vec::new(), commands);
        assert_eq!(controller_start(&sil), 1_000);
        // No command at all: the epoch.
        assert_eq!(
            controller_start(&recording(RecordMode::Hil, Vec::new(), Vec::new())),
            1_000
        );
    }

    #[test]
    fn a_late_controller_finds_the_newest_sentences_that_fit_the_line_the_newest_scan_and_the_last_frames()
     {
        let ms = 1_000_000;
        let sentence = |n: u8| Input::Gps(vec![n; 1500]);
        let frame = |n: u8| Input::Can {
            id: 0x200,
            data: vec![n],
        };
        let inputs = vec![
            (110 * ms, sentence(1)),
            (120 * ms, Input::Laser(Box::default())),
            (130 * ms, sentence(2)),
            (140 * ms, frame(1)),
            (150 * ms, sentence(3)),
            (160 * ms, Input::Laser(Box::default())),
            (170 * ms, sentence(4)),
            (195 * ms, frame(2)),
            (200 * ms, sentence(5)),
        ];
        let rec = recording(RecordMode::Hil, inputs, Vec::new());
        // As they arrived (here: at their log times).
        let arrived: Vec<(u64, &Input)> = rec.inputs.iter().map(|(ns, i)| (*ns, i)).collect();
        let (waiting, next) = waiting_at_start(&arrived, 200 * ms);
        // Sentence 5 is at the start itself: delivered at the first tick, not waiting.
        assert_eq!(next, 8);
        let kinds: Vec<String> = waiting
            .iter()
            .map(|i| match i {
                Input::Gps(b) => format!("gps{}", b[0]),
                Input::Laser(_) => "laser".to_owned(),
                Input::Can { data, .. } => format!("can{}", data[0]),
            })
            .collect();
        // 4096 bytes hold two 1500-byte sentences (the third would overflow): 3 and 4,
        // oldest first, with the newest scan between them; the frame sent within the
        // socket's 10 ms before the start, not the one before it was opened.
        assert_eq!(kinds, ["gps3", "laser", "gps4", "can2"]);
    }

    #[test]
    fn the_controllers_own_recording_replays_on_its_ticks_less_those_it_skipped() {
        let ms = 1_000_000;
        let inputs = vec![(1_000 + 30 * ms, Input::Gps(vec![b'$'; 1152]))];
        let mut rec = recording(RecordMode::Field, inputs, vec![heartbeat(1_000 + 200 * ms)]);
        rec.info.physics_hz = 100.0;
        rec.ticks_skipped = vec![(5, 10), (18, 1)];
        let at: Vec<u64> = ticks(&rec, controller_start(&rec), 1_000 + 200 * ms)
            .map(|(now, ns)| {
                assert_eq!(ns, 1_000 + (now * 1e9).round() as u64);
                (now * 100.0).round() as u64
            })
            .collect();
        let expected: Vec<u64> = (0..=20)
            .filter(|k| !(5..15).contains(k) && *k != 18)
            .collect();
        assert_eq!(at, expected);
        // Its inputs are fed at the tick that took them (the line's time is behind
        // them), and compared exactly.
        assert_eq!(arrivals(&rec)[0].0, 1_000 + 30 * ms);
        assert_eq!(Tolerance::for_mode(RecordMode::Field), Tolerance::EXACT);
    }

    #[test]
    fn in_hil_a_sentence_arrives_once_its_bytes_crossed_the_line() {
        let ms = 1_000_000;
        let inputs = vec![
            // 11.52 bytes a millisecond at 115200 baud: 1152 bytes take 100 ms.
            (0, Input::Gps(vec![b'$'; 1152])),
            // Queued while the first is on the line: it follows it.
            (5 * ms, Input::Gps(vec![b'$'; 576])),
            (
                6 * ms,
                Input::Can {
                    id: 1,
                    data: vec![],
                },
            ),
            (130 * ms, Input::Gps(vec![b'$'; 576])),
            // The line idle again: 50 ms after it was queued.
            (300 * ms, Input::Gps(vec![b'$'; 576])),
        ];
        let mut rec = recording(RecordMode::Hil, inputs, Vec::new());
        rec.info.gps_baud = 115_200;
        let at: Vec<u64> = arrivals(&rec).iter().map(|(ns, _)| *ns / ms).collect();
        assert_eq!(at, [6, 100, 150, 200, 350]);
        // SIL's memory ports deliver at once.
        rec.info.mode = RecordMode::Sil;
        let at: Vec<u64> = arrivals(&rec).iter().map(|(ns, _)| *ns / ms).collect();
        assert_eq!(at, [0, 5, 6, 130, 300]);
    }

    #[test]
    fn hil_tolerance_allows_steps_on_values_but_not_on_states() {
        let spec = NetworkSpec::from_dbc(golf_car_can::GOLF_CAR_DBC).unwrap();
        let steering = spec
            .messages
            .iter()
            .find(|m| m.name == "STEERING_CMD")
            .unwrap();
        let cmp = Comparer {
            spec: &spec,
            tol: Tolerance::HIL,
            recorded: Vec::new(),
            first_open: 0,
            messages: BTreeMap::new(),
            divergence: None,
            epoch_ns: 0,
            judged_from_ns: 0,
        };
        let frame = [1u8, 0, 0, 0, 0, 0, 0, 0];
        let allowed: BTreeMap<String, f64> = cmp
            .signals(u32::from(steering.id), &frame)
            .into_iter()
            .map(|(name, _, allowed)| (name, allowed))
            .collect();
        assert_eq!(allowed["Enable"], 0.0, "{allowed:?}");
        let angle = steering
            .signals
            .iter()
            .find(|s| s.name == "TargetAngle")
            .unwrap();
        assert!((allowed["TargetAngle"] - 10.0 * angle.factor.abs()).abs() < 1e-12);
        assert!(!allowed.contains_key("Counter") && !allowed.contains_key("Crc"));
    }
}
