//! Recordings in formats others read: one writer for the simulator's recording of
//! every run (`ugv-sim run`, which adds the world's topics to it) and the
//! controller's own (`ugv-controller run --record DIR`, on the car or on the bench).
//!
//! - `run.mcap` (the Foxglove SDK's built-in schemas, written by [`McapFile`]): the laser as
//!   `foxglove.LaserScan`, the GPS fix as `foxglove.LocationFix`, the car as
//!   `foxglove.FrameTransform` world -> base_link with the sensors' mounts base_link ->
//!   laser and base_link -> gps ([`Mounts`]), every CAN frame raw and decoded per
//!   golf_car.dbc (JSON), the NMEA sentences (JSON), the controller's state (JSON) and
//!   planned paths (`foxglove.SceneUpdate`), topics in [`topics`]. Every message's frame
//!   has a chain of transforms to `world`, so Foxglove's 3D and map panels show it all.
//! - `bus.log`: every CAN frame in `candump -l` form, for canplayer and `ugv-can decode`.
//! - `gps.nmea`: the NMEA byte stream exactly as it went over the line, for gpsfake.
//!
//! Written as the run goes with bounded buffering: MCAP chunks close when they reach
//! [`CHUNK_SIZE`] and at least every [`FLUSH_PERIOD`] of wall-clock time, when the two
//! text files reach the kernel too, so a process killed with SIGKILL leaves everything
//! up to its last second readable (an MCAP without its summary section is still read
//! by a streaming reader). A write error stops the recording, not the run.
//!
//! The controller's own recording ([`RecordMode::Field`]) is made at its loop's seam
//! (the runtime's `Runtime::with_recorder`): every input at the tick that took it,
//! every frame it sent, the ticks at which it took its replannings from the planning
//! thread, the ticks it skipped and the one it was asked to stop at, on its clock (log
//! time = the wall clock at its start + its time); besides, for the viewer, each fix it
//! read and its own estimate of the car's pose as world -> base_link. A replay feeds
//! the same inputs at the same ticks into the same code and gets the same frames, byte
//! for byte.

mod mcap_file;
pub mod topics;

pub use mcap_file::McapFile;

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime};

use firmware_bridge::can::TapFrame;
use firmware_bridge::clock::unix_ns;
use firmware_bridge::laser::LaserFrame;
use firmware_bridge::nmea::{Accuracy, GpsFix, GpsReading, is_terminator};
use foxglove::schemas::{
    Color, FrameTransform, LaserScan, LinePrimitive, LocationFix, Point3, Quaternion, SceneEntity,
    SceneUpdate, Timestamp, Vector3,
};
use foxglove::{Channel, Context, Encode, PartialMetadata, RawChannel, Sink};
use golf_car_can::candump::{Compact, push_decimal, push_hex_bytes};
use golf_car_can::spec::NetworkSpec;
use serde::{Deserialize, Serialize};
use serde_json::json;

use crate::control::{Controller, Mode};

/// The recording's file names in its directory.
pub const MCAP_FILE: &str = "run.mcap";
pub const BUS_LOG: &str = "bus.log";
pub const NMEA_FILE: &str = "gps.nmea";

/// Longest wall-clock time between two flushes to the kernel.
pub const FLUSH_PERIOD: Duration = Duration::from_secs(1);

/// An MCAP chunk is closed when it holds this many bytes (or at the next flush).
pub const CHUNK_SIZE: u64 = 1 << 20;

/// Seconds between two controller states when nothing changed.
const STATE_PERIOD: f64 = 0.1;

/// Seconds between two poses of the car (world -> base_link; the loop may run faster).
pub const POSE_PERIOD: f64 = 0.02;

/// Seconds between two copies of the sensors' mounts (static, but a live viewer may
/// connect late, and a player may start anywhere).
const MOUNTS_PERIOD: f64 = 1.0;

/// The longest NMEA line kept while waiting for its end: bytes that never end a line
/// (noise on the wire) are logged as one at this length.
const MAX_LINE: usize = 4096;

/// Why a recording could not be made.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    #[error("creating {path}: {source}")]
    Create {
        path: String,
        #[source]
        source: std::io::Error,
    },
    #[error("starting the MCAP file {path}: {source}")]
    Mcap {
        path: String,
        #[source]
        source: std::io::Error,
    },
    #[error("creating the channel {topic}: {source}")]
    Channel {
        topic: String,
        #[source]
        source: foxglove::FoxgloveError,
    },
    #[error("encoding golf_car.dbc's names for /can/decoded: {0}")]
    Json(#[source] serde_json::Error),
    #[error("the CAN tap on {iface}: {source}")]
    Tap {
        iface: String,
        #[source]
        source: std::io::Error,
    },
}

/// Which loop made a recording; written `"sil"`, `"hil"`, `"lockstep"`, `"field"`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RecordMode {
    /// The simulator's, of a SIL run (the controller in-process, in lockstep).
    Sil,
    /// The simulator's, of a HIL run (the controller binary in a process of its own).
    Hil,
    /// The simulator's, of a lockstep HIL run (the controller binary on the
    /// simulator's clock): every input at the tick that took it, as in SIL.
    Lockstep,
    /// The controller binary's own (`ugv-controller run --record`): on the car, on the
    /// bench, or beside a HIL run.
    Field,
}

/// What a replay needs to know about the run, kept in the MCAP metadata record
/// [`RUN_METADATA`] (one string per field) and the attachment [`CONFIG_ATTACHMENT`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunInfo {
    pub mode: RecordMode,
    /// The scenario's name (the simulator's recordings), or what the controller was
    /// started with (its own).
    pub scenario: String,
    /// Physics rate, Hz (SIL's controller ticks fall on its steps); the controller's
    /// tick rate in its own recordings.
    pub physics_hz: f64,
    /// UTC of t = 0, ns since 1970: log time = this + the run's time.
    pub epoch_unix_ns: u64,
    /// The CAN interface named in bus.log.
    pub can_interface: String,
    /// The GPS sentences that complete an epoch (the controller's reader setting).
    pub gps_sentences: firmware_bridge::nmea::SentenceSet,
    /// The GPS line's baud rate: in HIL a sentence reaches the controller once its
    /// last byte crossed the line.
    pub gps_baud: u32,
    /// The controller's configuration (TOML), for a replay into the same controller.
    #[serde(skip)]
    pub controller_toml: String,
}

/// Name of the MCAP metadata record with the [`RunInfo`].
pub const RUN_METADATA: &str = "ugv-hil run";
/// Name of the MCAP attachment with the controller's configuration.
pub const CONFIG_ATTACHMENT: &str = "controller.toml";

impl RunInfo {
    /// The controller's own recording's: `label` names the run (its configuration
    /// file), `epoch_unix_ns` is the wall clock at its loop's t = 0, the GPS line is read
    /// for `gps_sentences` at `gps_baud`, and `cfg` is attached.
    pub fn field(
        label: String,
        epoch_unix_ns: u64,
        can_interface: String,
        gps_sentences: firmware_bridge::nmea::SentenceSet,
        gps_baud: u32,
        cfg: &crate::config::ControllerConfig,
    ) -> Result<RunInfo, toml::ser::Error> {
        Ok(RunInfo {
            mode: RecordMode::Field,
            scenario: label,
            physics_hz: 1.0 / crate::control::COMMAND_PERIOD,
            epoch_unix_ns,
            can_interface,
            gps_sentences,
            gps_baud,
            controller_toml: toml::to_string_pretty(cfg)?,
        })
    }

    /// As the MCAP metadata record: each field as JSON text.
    fn metadata(&self) -> BTreeMap<String, String> {
        match serde_json::to_value(self) {
            Ok(serde_json::Value::Object(map)) => {
                map.into_iter().map(|(k, v)| (k, v.to_string())).collect()
            }
            _ => BTreeMap::new(),
        }
    }
}

/// What a recording holds, for the log and the tests.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct RecordSummary {
    pub dir: PathBuf,
    pub can_frames: u64,
    pub nmea_sentences: u64,
    pub laser_scans: u64,
    pub fixes: u64,
    /// CAN frames the recorder's tap lost: the kernel dropped them from its full
    /// receive queue (HIL; absent where it cannot happen or cannot be told).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub can_frames_lost: Option<u32>,
    /// The first error writing the recording (the run went on without it).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

/// A line for the log: what was recorded where.
pub fn describe(s: &RecordSummary) -> String {
    format!(
        "recorded {} CAN frames{}, {} NMEA sentences, {} laser scans in {}{}",
        s.can_frames,
        match s.can_frames_lost {
            Some(n) if n > 0 => format!(" ({n} more lost by the tap's full queue)"),
            _ => String::new(),
        },
        s.nmea_sentences,
        s.laser_scans,
        s.dir.display(),
        s.error
            .as_ref()
            .map(|e| format!(" (incomplete: {e})"))
            .unwrap_or_default()
    )
}

/// Where the car's sensors sit in its frame `base_link` (the rear axle's centre, x
/// forward, y left): the static transforms base_link -> laser and base_link -> gps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Mounts {
    /// The scanner: x, y (m) and yaw (rad, counter-clockwise).
    pub laser: [f64; 3],
    /// The GPS antenna: x, y and its height z (m).
    pub gps: [f64; 3],
}

impl Mounts {
    /// The mounts the controller's configuration states (the antenna's height is not
    /// in it: 0).
    pub fn of(v: &crate::config::Vehicle) -> Mounts {
        Mounts {
            laser: [v.laser_x, v.laser_y, v.laser_yaw_deg.to_radians()],
            gps: [v.antenna_x, v.antenna_y, 0.0],
        }
    }
}

/// A quaternion for a yaw about +z.
pub fn yaw(theta: f64) -> Quaternion {
    Quaternion {
        x: 0.0,
        y: 0.0,
        z: (theta / 2.0).sin(),
        w: (theta / 2.0).cos(),
    }
}

/// The transform `parent` -> `child` at `ns`: a translation and a yaw.
fn transform(ns: u64, parent: &str, child: &str, at: [f64; 3], theta: f64) -> FrameTransform {
    FrameTransform {
        timestamp: Some(timestamp(ns)),
        parent_frame_id: parent.to_owned(),
        child_frame_id: child.to_owned(),
        translation: Some(Vector3 {
            x: at[0],
            y: at[1],
            z: at[2],
        }),
        rotation: Some(yaw(theta)),
    }
}

/// A Foxglove timestamp of `ns` since 1970.
pub fn timestamp(ns: u64) -> Timestamp {
    Timestamp::new(
        u32::try_from(ns / 1_000_000_000).unwrap_or(u32::MAX),
        (ns % 1_000_000_000) as u32,
    )
}

/// Direction of a frame seen from the ECUs' side of the bus (the simulator's, in its
/// recordings): `rx` what the controller sends (towards the ECUs), `tx` what the ECUs
/// send (towards the controller). The controller's own recording goes by who sent
/// each frame instead ([`Writer::can`]: a frame on its IDs from a second sender is one
/// it received).
pub fn direction(spec: &NetworkSpec, id: u32) -> &'static str {
    let controller = u16::try_from(id)
        .ok()
        .and_then(|id| spec.message(id))
        .is_some_and(|m| m.senders.iter().any(|s| s == "CONTROLLER"));
    if controller { "rx" } else { "tx" }
}

/// A text file written through a buffer, its first error kept.
#[derive(Debug)]
struct TextOut {
    path: PathBuf,
    out: Option<BufWriter<File>>,
}

impl TextOut {
    fn create(path: PathBuf) -> Result<TextOut, RecordError> {
        let file = File::create(&path).map_err(|source| RecordError::Create {
            path: path.display().to_string(),
            source,
        })?;
        Ok(TextOut {
            path,
            out: Some(BufWriter::new(file)),
        })
    }

    /// No file (a live view without a recording).
    fn none() -> TextOut {
        TextOut {
            path: PathBuf::new(),
            out: None,
        }
    }

    fn write(&mut self, bytes: &[u8], error: &mut Option<String>) {
        if let Some(o) = &mut self.out
            && let Err(e) = o.write_all(bytes)
        {
            self.fail(e, error);
        }
    }

    fn flush(&mut self, error: &mut Option<String>) {
        if let Some(o) = &mut self.out
            && let Err(e) = o.flush()
        {
            self.fail(e, error);
        }
    }

    fn fail(&mut self, e: std::io::Error, error: &mut Option<String>) {
        error.get_or_insert_with(|| format!("writing {}: {e}", self.path.display()));
        self.out = None;
    }
}

fn json_channel(
    ctx: &Arc<Context>,
    topic: &str,
) -> Result<Arc<RawChannel>, foxglove::FoxgloveError> {
    ctx.channel_builder(topic)
        .message_encoding("json")
        .build_raw()
}

/// The `foxglove.LaserScan` channel of scans like `frame`: its metadata keeps the
/// frame's constant fields exactly (f32 text round-trips), for replay.
fn laser_channel(
    ctx: &Arc<Context>,
    frame: &LaserFrame,
) -> Result<Arc<RawChannel>, foxglove::FoxgloveError> {
    let meta = BTreeMap::from([
        ("angle_min".to_owned(), frame.angle_min.to_string()),
        (
            "angle_increment".to_owned(),
            frame.angle_increment.to_string(),
        ),
        (
            "time_increment".to_owned(),
            frame.time_increment.to_string(),
        ),
        ("scan_time".to_owned(), frame.scan_time.to_string()),
        ("range_min".to_owned(), frame.range_min.to_string()),
        ("range_max".to_owned(), frame.range_max.to_string()),
    ]);
    ctx.channel_builder(topics::LASER)
        .message_encoding(LaserScan::get_message_encoding())
        .schema(LaserScan::get_schema())
        .metadata(meta)
        .build_raw()
}

/// Append `frame` as a `foxglove.LaserScan` message (protobuf), the bytes the SDK's
/// own encoding gives: the head (stamp, frame `laser`, angles) by the SDK, then the
/// ranges and the intensities (fields 6 and 7, packed doubles) straight from the
/// frame's f32, without a `Vec<f64>` of each or the SDK's per-value buffer checks.
pub fn encode_scan(
    buf: &mut Vec<u8>,
    frame: &LaserFrame,
) -> Result<(), <LaserScan as Encode>::Error> {
    let head = LaserScan {
        timestamp: Some(timestamp(frame.stamp_ns)),
        frame_id: "laser".to_owned(),
        pose: None,
        start_angle: f64::from(frame.angle_min),
        end_angle: f64::from(frame.angle_max()),
        ranges: Vec::new(),
        intensities: Vec::new(),
    };
    Encode::encode(&head, buf)?;
    packed_doubles(buf, 6, frame.ranges());
    packed_doubles(buf, 7, frame.intensities());
    Ok(())
}

/// Append the protobuf field `field` of `values` as packed doubles (nothing when
/// empty, as proto3 has it).
fn packed_doubles(buf: &mut Vec<u8>, field: u64, values: &[f32]) {
    if values.is_empty() {
        return;
    }
    push_varint(buf, field << 3 | 2);
    push_varint(buf, 8 * values.len() as u64);
    buf.reserve(8 * values.len());
    // A block at a time through a buffer on the stack: converted in a loop the
    // compiler vectorises, appended with one short copy, never zeroed first.
    const BLOCK: usize = 64;
    let mut block = [0u8; 8 * BLOCK];
    for chunk in values.chunks(BLOCK) {
        for (out, v) in block.chunks_exact_mut(8).zip(chunk) {
            out.copy_from_slice(&f64::from(*v).to_le_bytes());
        }
        buf.extend_from_slice(&block[..8 * chunk.len()]);
    }
}

/// Append `n` as a protobuf varint.
fn push_varint(buf: &mut Vec<u8>, mut n: u64) {
    while n >= 0x80 {
        buf.push((n & 0x7F) as u8 | 0x80);
        n >>= 7;
    }
    buf.push(n as u8);
}

/// Append `v` as serde_json writes an f64: an integral value below a billion (most
/// signals' are) by hand, `-0.0` and `3.0` alike, the rest through serde_json.
fn push_number(buf: &mut Vec<u8>, v: f64) -> Result<(), serde_json::Error> {
    if v.fract() == 0.0 && v.abs() < 1e9 {
        if v.is_sign_negative() {
            buf.push(b'-');
        }
        push_decimal(buf, v.abs() as u64, 1);
        buf.extend_from_slice(b".0");
        return Ok(());
    }
    serde_json::to_writer(buf, &v)
}

/// `/can/raw` and `/can/decoded` written by hand into a reused buffer: the keys are
/// known, so no map, no `serde_json::Value`, no escaping per frame; each message's
/// JSON up to its first signal's value is made once. The bytes are those serde_json
/// gave the maps before (keys in name order, numbers as serde_json writes them).
#[derive(Debug)]
struct CanJson {
    /// golf_car.dbc, each message's signals sorted by name (the order of the keys of
    /// `/can/decoded`'s `signals`).
    spec: NetworkSpec,
    /// For each of `spec`'s messages, in its order.
    messages: Vec<MessageJson>,
}

/// One message's JSON made once: `{"id":ID,"message":"NAME","signals":{`, each
/// signal's `"NAME":` (after a comma but the first), its [`direction`].
#[derive(Debug)]
struct MessageJson {
    head: Vec<u8>,
    keys: Vec<Vec<u8>>,
    direction: &'static str,
}

impl CanJson {
    fn new(mut spec: NetworkSpec) -> Result<CanJson, serde_json::Error> {
        let directions: Vec<_> = spec
            .messages
            .iter()
            .map(|m| direction(&spec, u32::from(m.id)))
            .collect();
        let mut messages = Vec::with_capacity(spec.messages.len());
        for (m, direction) in spec.messages.to_mut().iter_mut().zip(directions) {
            m.signals.to_mut().sort_by(|a, b| a.name.cmp(&b.name));
            let head = format!(
                r#"{{"id":{},"message":{},"signals":{{"#,
                m.id,
                serde_json::to_string(&m.name)?
            );
            let mut keys = Vec::with_capacity(m.signals.len());
            for (i, s) in m.signals.iter().enumerate() {
                let comma = if i == 0 { "" } else { "," };
                keys.push(format!("{comma}{}:", serde_json::to_string(&s.name)?).into_bytes());
            }
            messages.push(MessageJson {
                head: head.into_bytes(),
                keys,
                direction,
            });
        }
        Ok(CanJson { spec, messages })
    }

    /// Where the message of ID `id` is in the spec, if it has one.
    fn position(&self, id: u32) -> Option<usize> {
        let id = u16::try_from(id).ok()?;
        self.spec.messages.iter().position(|m| m.id == id)
    }

    /// [`direction`] of a frame of ID `id`, the message at `at` ([`CanJson::position`]).
    fn direction(&self, at: Option<usize>) -> &'static str {
        at.and_then(|i| self.messages.get(i))
            .map_or("tx", |m| m.direction)
    }

    /// `/can/raw`'s message of `f` into `buf`; `direction` as seen by the recorder.
    fn raw(buf: &mut Vec<u8>, f: &TapFrame, direction: &str) {
        buf.extend_from_slice(br#"{"data":""#);
        push_hex_bytes(buf, &f.data);
        buf.extend_from_slice(br#"","direction":""#);
        buf.extend_from_slice(direction.as_bytes());
        buf.extend_from_slice(br#"","extended":"#);
        buf.extend_from_slice(if f.extended { b"true" } else { b"false" });
        buf.extend_from_slice(br#","id":"#);
        push_decimal(buf, u64::from(f.id), 1);
        if let Some(sent) = f.sent {
            buf.extend_from_slice(br#","sent":"#);
            buf.extend_from_slice(if sent { b"true" } else { b"false" });
        }
        if let Some(k) = f.kernel {
            buf.extend_from_slice(br#","wall_unix_ns":"#);
            push_decimal(buf, unix_ns(k), 1);
        }
        buf.push(b'}');
    }

    /// `/can/decoded`'s message of a standard frame with `data` of the message at
    /// `at` ([`CanJson::position`]) into `buf`; false (and nothing written) when the
    /// data is not eight bytes.
    fn decoded(
        &self,
        buf: &mut Vec<u8>,
        at: usize,
        data: &[u8],
    ) -> Result<bool, serde_json::Error> {
        let (Some(m), Some(json), Ok(p)) = (
            self.spec.messages.get(at),
            self.messages.get(at),
            golf_car_can::codec::payload("", data),
        ) else {
            return Ok(false);
        };
        buf.extend_from_slice(&json.head);
        for (s, key) in m.signals.iter().zip(&json.keys) {
            buf.extend_from_slice(key);
            push_number(buf, s.get(&p))?;
        }
        buf.extend_from_slice(b"}}");
        Ok(true)
    }
}

/// Writes one recording: the topics every recording has, on a [`Context`] the
/// simulator adds its world's channels to.
pub struct Writer {
    ctx: Arc<Context>,
    mcap: Option<Arc<McapFile<BufWriter<File>>>>,
    /// `foxglove.LaserScan`, encoded by [`encode_scan`].
    laser: Option<Arc<RawChannel>>,
    fix: Channel<LocationFix>,
    tf: Channel<FrameTransform>,
    /// The sensors' mounts, logged with the car's pose ([`Writer::with_mounts`]).
    mounts: Option<Mounts>,
    next_mounts: f64,
    plans: Channel<SceneUpdate>,
    can_raw: Arc<RawChannel>,
    can_decoded: Arc<RawChannel>,
    nmea: Arc<RawChannel>,
    state: Arc<RawChannel>,
    /// JSON channels made when first logged to (the controller's own topics).
    other: BTreeMap<&'static str, Arc<RawChannel>>,
    bus_log: TextOut,
    nmea_file: TextOut,
    /// The start of an NMEA line whose end has not come yet.
    nmea_line: Vec<u8>,
    /// A buffer reused for each message's encoding (a frame's bus.log line, its JSON,
    /// a scan).
    scratch: Vec<u8>,
    can_json: CanJson,
    info: RunInfo,
    last_flush: Instant,
    /// The log time of the last flush by log time ([`Writer::maybe_flush_at`]).
    last_flush_t: f64,
    cadence: StateCadence,
    /// Whether files are written (else the channels serve a live view only).
    files: bool,
    summary: RecordSummary,
}

impl std::fmt::Debug for Writer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Writer")
            .field("summary", &self.summary)
            .finish_non_exhaustive()
    }
}

impl Writer {
    /// Start a recording: the files in `dir` (which must exist) when given, the
    /// channels on `ctx` (a live view's, or a new one).
    pub fn create(
        dir: Option<&Path>,
        ctx: Arc<Context>,
        info: RunInfo,
    ) -> Result<Writer, RecordError> {
        let base = dir.unwrap_or(Path::new(""));
        let mcap_path = base.join(MCAP_FILE);
        let mcap_err = |source| RecordError::Mcap {
            path: mcap_path.display().to_string(),
            source,
        };
        let mcap = match dir {
            Some(_) => {
                let file = File::create(&mcap_path).map_err(|source| RecordError::Create {
                    path: mcap_path.display().to_string(),
                    source,
                })?;
                let mcap = McapFile::create(BufWriter::new(file), CHUNK_SIZE as usize)
                    .map_err(mcap_err)?;
                mcap.metadata(RUN_METADATA, &info.metadata())
                    .map_err(mcap_err)?;
                let toml = info.controller_toml.as_bytes();
                mcap.attach(
                    CONFIG_ATTACHMENT,
                    "application/toml",
                    info.epoch_unix_ns,
                    toml,
                )
                .map_err(mcap_err)?;
                let mcap = Arc::new(mcap);
                ctx.add_sink(Arc::clone(&mcap) as Arc<dyn Sink>);
                Some(mcap)
            }
            None => None,
        };
        let json = |topic: &str| {
            json_channel(&ctx, topic).map_err(|source| RecordError::Channel {
                topic: topic.to_owned(),
                source,
            })
        };
        let text = |name| match dir {
            Some(dir) => TextOut::create(dir.join(name)),
            None => Ok(TextOut::none()),
        };
        Ok(Writer {
            laser: None,
            fix: ctx.channel_builder(topics::FIX).build(),
            tf: ctx.channel_builder(topics::TF).build(),
            mounts: None,
            next_mounts: 0.0,
            plans: ctx.channel_builder(topics::PLANS).build(),
            can_raw: json(topics::CAN_RAW)?,
            can_decoded: json(topics::CAN_DECODED)?,
            nmea: json(topics::NMEA)?,
            state: json(topics::CONTROLLER_STATE)?,
            other: BTreeMap::new(),
            mcap,
            bus_log: text(BUS_LOG)?,
            nmea_file: text(NMEA_FILE)?,
            nmea_line: Vec::new(),
            scratch: Vec::new(),
            can_json: CanJson::new(golf_car_can::NETWORK.clone()).map_err(RecordError::Json)?,
            info,
            last_flush: Instant::now(),
            last_flush_t: 0.0,
            cadence: StateCadence::default(),
            files: dir.is_some(),
            summary: RecordSummary {
                dir: base.to_path_buf(),
                ..RecordSummary::default()
            },
            ctx,
        })
    }

    /// Log the sensors' `mounts` with the car's pose ([`Writer::base_link`]).
    pub fn with_mounts(mut self, mounts: Mounts) -> Writer {
        self.mounts = Some(mounts);
        self
    }

    /// The count of what was logged, to add to.
    pub fn summary_mut(&mut self) -> &mut RecordSummary {
        &mut self.summary
    }

    /// Keep the first error (the recording goes on as far as it can).
    pub fn note_error(&mut self, error: String) {
        self.summary.error.get_or_insert(error);
    }

    /// Log time of the run's time `t`, ns since 1970 ([`log_ns`]).
    pub fn ns(&self, t: f64) -> u64 {
        log_ns(self.info.epoch_unix_ns, t)
    }

    /// The wall clock alongside the run's time (HIL only: SIL has none, and the
    /// controller's own log time is its wall clock).
    fn wall(&self) -> Option<u64> {
        (self.info.mode == RecordMode::Hil).then(|| unix_ns(SystemTime::now()))
    }

    fn log_json(&self, channel: &RawChannel, t: f64, value: &serde_json::Value) {
        let bytes = value.to_string();
        channel.log_with_meta(bytes.as_bytes(), PartialMetadata::with_log_time(self.ns(t)));
    }

    /// `value` on the JSON topic `topic`, created when first logged to.
    pub fn log_other(&mut self, topic: &'static str, t: f64, value: &serde_json::Value) {
        if !self.other.contains_key(topic) {
            match json_channel(&self.ctx, topic) {
                Ok(c) => {
                    self.other.insert(topic, c);
                }
                Err(e) => {
                    self.note_error(format!("creating the channel {topic}: {e}"));
                    return;
                }
            }
        }
        if let Some(c) = self.other.get(topic) {
            self.log_json(c, t, value);
        }
    }

    /// NMEA bytes that went over the line at `t`: into gps.nmea as they are, and each
    /// line they end onto `/gps/nmea` (without its CR LF; a line's start waits for its
    /// end, bytes that are not UTF-8 are replaced).
    pub fn nmea(&mut self, t: f64, bytes: &[u8]) {
        if bytes.is_empty() {
            return;
        }
        let mut error = self.summary.error.take();
        self.nmea_file.write(bytes, &mut error);
        self.summary.error = error;
        let wall = self.wall();
        let ns = self.ns(t);
        for &b in bytes {
            self.nmea_line.push(b);
            // A line ends where the reader ends it (a read that stops between its CR
            // and LF, in a backlog, gave the reader the line a tick before its LF).
            if !is_terminator(b) && self.nmea_line.len() < MAX_LINE {
                continue;
            }
            let line = std::mem::take(&mut self.nmea_line);
            let text = String::from_utf8_lossy(&line);
            let sentence = text.trim_end_matches(['\r', '\n']);
            if sentence.is_empty() {
                continue;
            }
            // {"sentence":...,"wall_unix_ns":...} by hand, as for the CAN frames.
            let buf = &mut self.scratch;
            buf.clear();
            buf.extend_from_slice(br#"{"sentence":"#);
            if let Err(e) = serde_json::to_writer(&mut *buf, sentence) {
                self.note_error(format!("encoding {}: {e}", topics::NMEA));
                continue;
            }
            if let Some(w) = wall {
                buf.extend_from_slice(br#","wall_unix_ns":"#);
                push_decimal(buf, w, 1);
            }
            buf.push(b'}');
            self.nmea
                .log_with_meta(buf, PartialMetadata::with_log_time(ns));
            self.summary.nmea_sentences += 1;
        }
    }

    /// A GPS epoch's fix at `t`, as the receiver sent it.
    pub fn fix(&mut self, t: f64, f: &GpsFix) {
        let at = [f.lat_deg, f.lon_deg, f.ellipsoid_height_m];
        self.location_fix(t, at, f.accuracy.as_ref(), f.heading_deg);
    }

    /// A GPS epoch at `t` as the controller read it; none without a position.
    pub fn reading(&mut self, t: f64, r: &GpsReading) {
        if let (Some(lat), Some(lon)) = (r.lat_deg, r.lon_deg) {
            // GGA's altitude is above mean sea level: the ellipsoid is the geoid's
            // separation below.
            let alt = r.altitude_msl_m.unwrap_or(0.0) + r.geoid_separation_m.unwrap_or(0.0);
            self.location_fix(t, [lat, lon, alt], r.accuracy.as_ref(), r.heading_deg);
        }
    }

    /// `foxglove.LocationFix` in frame `gps` (the antenna) at `t`: latitude, longitude
    /// (degrees) and height above the ellipsoid (m) `at`, the GST's sigmas as a diagonal
    /// covariance when known, the true heading.
    fn location_fix(
        &mut self,
        t: f64,
        at: [f64; 3],
        accuracy: Option<&Accuracy>,
        heading_deg: Option<f64>,
    ) {
        let sigma = accuracy.map(|a| [a.lat_sigma_m, a.lon_sigma_m, a.alt_sigma_m]);
        let ns = self.ns(t);
        self.fix.log_with_time(
            &LocationFix {
                timestamp: Some(timestamp(ns)),
                frame_id: "gps".to_owned(),
                latitude: at[0],
                longitude: at[1],
                altitude: at[2],
                // Diagonal covariance from GST (type 2, diagonal known), else unknown.
                position_covariance: sigma.map_or_else(Vec::new, |[n, e, u]| {
                    vec![e * e, 0.0, 0.0, 0.0, n * n, 0.0, 0.0, 0.0, u * u]
                }),
                position_covariance_type: if sigma.is_some() { 2 } else { 0 },
                heading: heading_deg,
                ..LocationFix::default()
            },
            ns,
        );
        self.summary.fixes += 1;
    }

    /// The car at `t` as world -> base_link (the rear axle at x, y, heading `theta`),
    /// and the sensors' mounts with it when they are due.
    pub fn base_link(&mut self, t: f64, x: f64, y: f64, theta: f64) {
        let ns = self.ns(t);
        self.tf
            .log_with_time(&transform(ns, "world", "base_link", [x, y, 0.0], theta), ns);
        if let Some(m) = self.mounts
            && t + 1e-9 >= self.next_mounts
        {
            self.next_mounts = t + MOUNTS_PERIOD;
            let [lx, ly, lyaw] = m.laser;
            let laser = transform(ns, "base_link", "laser", [lx, ly, 0.0], lyaw);
            self.tf.log_with_time(&laser, ns);
            self.tf
                .log_with_time(&transform(ns, "base_link", "gps", m.gps, 0.0), ns);
        }
    }

    /// A laser frame at `t` as `foxglove.LaserScan` (the channel's metadata keeps the
    /// frame's constant fields exactly, for replay), encoded by [`encode_scan`].
    pub fn laser(&mut self, t: f64, frame: &LaserFrame) {
        if self.laser.is_none() {
            match laser_channel(&self.ctx, frame) {
                Ok(c) => self.laser = Some(c),
                Err(e) => {
                    self.note_error(format!("creating the channel {}: {e}", topics::LASER));
                    return;
                }
            }
        }
        let ns = self.ns(t);
        let Some(channel) = &self.laser else {
            return;
        };
        self.scratch.clear();
        if let Err(e) = encode_scan(&mut self.scratch, frame) {
            self.note_error(format!("encoding a scan: {e}"));
            return;
        }
        channel.log_with_meta(&self.scratch, PartialMetadata::with_log_time(ns));
        self.summary.laser_scans += 1;
    }

    /// One CAN frame on the bus at `t`, with the kernel's receive time when known
    /// (bus.log then carries it, and `/can/raw` as `wall_unix_ns`). A frame a port
    /// kept (the controller's own recording) says whether the port sent it: a frame
    /// it received goes on `/can/raw` as received (`"sent": false`, direction `tx`)
    /// whatever its ID, so a second sender on the controller's IDs is not taken for
    /// the controller.
    pub fn can(&mut self, t: f64, f: &TapFrame) {
        let ns = self.ns(t);
        let meta = PartialMetadata::with_log_time(ns);
        let compact = Compact {
            id: f.id,
            extended: f.extended,
            data: &f.data,
        };
        let buf = &mut self.scratch;
        buf.clear();
        compact.push_log_line(buf, f.kernel.map_or(ns, unix_ns), &self.info.can_interface);
        let mut error = self.summary.error.take();
        self.bus_log.write(buf, &mut error);
        self.summary.error = error;
        let at = self.can_json.position(f.id);
        let direction = match f.sent {
            Some(false) => "tx",
            Some(true) | None => self.can_json.direction(at),
        };
        buf.clear();
        CanJson::raw(buf, f, direction);
        self.can_raw.log_with_meta(buf, meta);
        if let Some(at) = at.filter(|_| !f.extended) {
            buf.clear();
            match self.can_json.decoded(buf, at, &f.data) {
                Ok(true) => self.can_decoded.log_with_meta(buf, meta),
                Ok(false) => {}
                Err(e) => self.note_error(format!("encoding {}: {e}", topics::CAN_DECODED)),
            }
        }
        self.summary.can_frames += 1;
    }

    /// The controller's state (on change of mode and every [`STATE_PERIOD`]) and its
    /// new planned paths, at `t`.
    pub fn controller(&mut self, t: f64, ctl: &Controller) {
        let (state, plans) = self.cadence.take(t, ctl);
        if let Some(state) = state {
            self.log_json(&self.state, t, &state);
        }
        for planned in plans {
            self.plan(t, &planned);
        }
    }

    /// A planned path at `t` in the world frame: the polynomial's as a green line; a
    /// manoeuvre's forward segments orange, its backward ones magenta, and a sphere at
    /// each cusp (entity id `plan` either way, so each replaces the last).
    fn plan(&self, t: f64, planned: &Planned) {
        let ns = self.ns(t);
        let colour = |r, g, b| Color { r, g, b, a: 1.0 };
        let line = |points: &[[f64; 2]], color: Color| LinePrimitive {
            r#type: foxglove::schemas::line_primitive::Type::LineStrip as i32,
            thickness: 0.1,
            points: points
                .iter()
                .map(|q| Point3 {
                    x: q[0],
                    y: q[1],
                    z: 0.05,
                })
                .collect(),
            color: Some(color),
            ..LinePrimitive::default()
        };
        let (lines, spheres) = match &planned.manoeuvre {
            None => (vec![line(&planned.path, colour(0.1, 0.8, 0.3))], Vec::new()),
            Some(m) => (
                manoeuvre_spans(planned.path.len(), &m.reverse)
                    .into_iter()
                    .map(|(lo, hi, forward)| {
                        let end = (hi + 1).min(planned.path.len());
                        match forward {
                            true => line(&planned.path[lo..end], colour(0.9, 0.47, 0.08)),
                            false => line(&planned.path[lo..end], colour(0.78, 0.12, 0.63)),
                        }
                    })
                    .collect(),
                m.cusps
                    .iter()
                    .map(|c| foxglove::schemas::SpherePrimitive {
                        pose: Some(foxglove::schemas::Pose {
                            position: Some(foxglove::schemas::Vector3 {
                                x: c[0],
                                y: c[1],
                                z: 0.1,
                            }),
                            orientation: None,
                        }),
                        size: Some(foxglove::schemas::Vector3 {
                            x: 0.3,
                            y: 0.3,
                            z: 0.3,
                        }),
                        color: Some(colour(0.78, 0.12, 0.63)),
                    })
                    .collect(),
            ),
        };
        let entity = SceneEntity {
            timestamp: Some(timestamp(ns)),
            frame_id: "world".to_owned(),
            id: "plan".to_owned(),
            lines,
            spheres,
            ..SceneEntity::default()
        };
        self.plans.log_with_time(
            &SceneUpdate {
                deletions: Vec::new(),
                entities: vec![entity],
            },
            ns,
        );
    }

    /// Hand what was written to the kernel when [`FLUSH_PERIOD`] has passed.
    pub fn maybe_flush(&mut self) {
        if self.last_flush.elapsed() >= FLUSH_PERIOD {
            self.flush();
        }
    }

    /// [`Writer::maybe_flush`] for a recording written at log time `t`: a lockstep
    /// run's flushes go by its own time, so that its chunks, and the file, are the same
    /// in every run of it.
    pub fn maybe_flush_at(&mut self, t: f64) {
        if self.info.mode != RecordMode::Lockstep {
            return self.maybe_flush();
        }
        if t >= self.last_flush_t + FLUSH_PERIOD.as_secs_f64() {
            self.last_flush_t = t;
            self.flush();
        }
    }

    fn flush(&mut self) {
        self.last_flush = Instant::now();
        let mut error = self.summary.error.take();
        self.bus_log.flush(&mut error);
        self.nmea_file.flush(&mut error);
        if let Some(m) = &self.mcap
            && let Err(e) = m.flush()
        {
            error.get_or_insert_with(|| format!("writing {MCAP_FILE}: {e}"));
            self.mcap = None;
        }
        self.summary.error = error;
    }

    /// Close the files (the MCAP with its summary section); what they hold, when files
    /// were written.
    pub fn finish(mut self) -> Option<RecordSummary> {
        self.flush();
        if let Some(m) = self.mcap.take()
            && let Err(e) = {
                self.ctx.remove_sink(Sink::id(&*m));
                m.close()
            }
        {
            self.summary
                .error
                .get_or_insert_with(|| format!("closing {MCAP_FILE}: {e}"));
        }
        self.files.then(|| self.summary.clone())
    }
}

/// A replanning's path as the recording shows it: the planner that made it is the
/// manoeuvre planner when `manoeuvre` is set.
#[derive(Clone, Debug)]
pub struct Planned {
    pub path: Vec<[f64; 2]>,
    pub manoeuvre: Option<crate::guidance::ManoeuvreRecord>,
}

/// The spans of a manoeuvre's path of `n` points (first index, one past the last,
/// forward), the backward ones `reverse` (in order, apart) and the forward ones between.
pub fn manoeuvre_spans(n: usize, reverse: &[[usize; 2]]) -> Vec<(usize, usize, bool)> {
    let mut all = Vec::new();
    let mut at = 0;
    for r in reverse {
        let (lo, hi) = (r[0].clamp(at, n), r[1].clamp(at, n));
        if lo > at {
            all.push((at, lo, true));
        }
        all.push((lo, hi, false));
        at = hi;
    }
    if at < n {
        all.push((at, n, true));
    }
    all
}

/// When the controller's state is logged (on a change of mode, else every
/// [`STATE_PERIOD`]) and which of its paths are new.
#[derive(Debug, Default)]
struct StateCadence {
    next_state: f64,
    last_mode: Option<Mode>,
    plans_seen: usize,
}

impl StateCadence {
    /// The state to log at `t`, if due, and the paths planned since the last call.
    fn take(&mut self, t: f64, ctl: &Controller) -> (Option<serde_json::Value>, Vec<Planned>) {
        let changed = self.last_mode.as_ref() != Some(ctl.mode());
        let state = (changed || t + 1e-9 >= self.next_state).then(|| {
            self.next_state = t + STATE_PERIOD;
            self.last_mode = Some(ctl.mode().clone());
            json!({
                "mode": ctl.mode(),
                "changed": changed,
                "pose": ctl.pose(t),
                "obstacles": ctl.obstacles(),
                "stop_reason": ctl.stop_reason(),
            })
        });
        let plans = &ctl.nav.plans;
        let new = plans
            .get(self.plans_seen..)
            .unwrap_or_default()
            .iter()
            .map(|p| Planned {
                path: p.path.clone(),
                manoeuvre: p.manoeuvre.clone().filter(|m| !m.failed),
            })
            .collect();
        self.plans_seen = plans.len();
        (state, new)
    }
}

/// Log time, ns since 1970, of the run's time `t` (seconds) for a run that began at
/// `epoch_unix_ns`: what every message of a recording is logged at.
pub fn log_ns(epoch_unix_ns: u64, t: f64) -> u64 {
    epoch_unix_ns + (t.max(0.0) * 1e9).round() as u64
}

/// What the controller's loop hands its [`BackgroundWriter`].
enum Entry {
    Nmea(f64, Vec<u8>),
    Laser(f64, Box<LaserFrame>),
    Can(f64, TapFrame),
    Json(&'static str, f64, serde_json::Value),
    State(f64, serde_json::Value),
    Plan(f64, Planned),
    Fix(f64, Box<GpsReading>),
    Pose(f64, [f64; 3]),
}

impl Entry {
    /// Its time, controller seconds.
    fn time(&self) -> f64 {
        match self {
            Entry::Nmea(t, _)
            | Entry::Laser(t, _)
            | Entry::Can(t, _)
            | Entry::Json(_, t, _)
            | Entry::State(t, _)
            | Entry::Plan(t, _)
            | Entry::Fix(t, _)
            | Entry::Pose(t, _) => *t,
        }
    }
}

/// Entries the loop's queue lost in a row: the first's and the last's times, and how
/// many; marked in the file ([`topics::CONTROLLER_DROPPED`]) once the queue takes an
/// entry again, so a replay knows where the recording stops being whole.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Gap {
    from: f64,
    to: f64,
    entries: u64,
}

impl Gap {
    fn mark(self) -> Entry {
        Entry::Json(
            topics::CONTROLLER_DROPPED,
            self.to,
            json!({ "from": self.from, "entries": self.entries }),
        )
    }
}

/// Entries queued for the [`BackgroundWriter`]'s thread before the loop drops them
/// (some seconds of a run: a tick hands over a handful).
const QUEUE: usize = 8192;

/// A [`Writer`] on a thread of its own, for the controller's loop: the loop hands it
/// owned copies of what crossed its ports and never waits (a full queue drops the
/// entry, counts it and marks the gap in the file: [`Gap`]), and the thread encodes
/// and writes them. Dropped, it finishes the recording.
#[derive(Debug)]
pub struct BackgroundWriter {
    queue: Option<std::sync::mpsc::SyncSender<Entry>>,
    thread: Option<std::thread::JoinHandle<Option<RecordSummary>>>,
    cadence: StateCadence,
    /// When the controller's pose estimate is next due ([`POSE_PERIOD`]).
    next_pose: f64,
    dropped: u64,
    /// Entries lost since the queue last took one.
    gap: Option<Gap>,
}

impl BackgroundWriter {
    /// Start the thread that writes into `writer`.
    pub fn spawn(mut writer: Writer) -> std::io::Result<BackgroundWriter> {
        let (queue, entries) = std::sync::mpsc::sync_channel::<Entry>(QUEUE);
        let thread = std::thread::Builder::new()
            .name("recorder".to_owned())
            .spawn(move || {
                loop {
                    match entries.recv_timeout(FLUSH_PERIOD) {
                        Ok(entry) => writer.write(entry),
                        Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {}
                        Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => break,
                    }
                    writer.maybe_flush();
                }
                writer.finish()
            })?;
        Ok(BackgroundWriter {
            queue: Some(queue),
            thread: Some(thread),
            cadence: StateCadence::default(),
            next_pose: 0.0,
            dropped: 0,
            gap: None,
        })
    }

    /// `entry` onto the queue, after the mark of the gap before it if there is one; a
    /// full queue loses it (and the mark, which waits for the next).
    fn send(&mut self, entry: Entry) {
        let Some(q) = &self.queue else {
            return;
        };
        let t = entry.time();
        let marked = self.gap.is_none_or(|gap| q.try_send(gap.mark()).is_ok());
        if marked {
            self.gap = None;
            if q.try_send(entry).is_ok() {
                return;
            }
        }
        self.dropped += 1;
        let gap = self.gap.get_or_insert(Gap {
            from: t,
            to: t,
            entries: 0,
        });
        gap.to = t;
        gap.entries += 1;
    }

    /// See [`Writer::nmea`].
    pub fn nmea(&mut self, t: f64, bytes: &[u8]) {
        if !bytes.is_empty() {
            self.send(Entry::Nmea(t, bytes.to_vec()));
        }
    }

    /// See [`Writer::laser`].
    pub fn laser(&mut self, t: f64, frame: &LaserFrame) {
        self.send(Entry::Laser(t, Box::new(*frame)));
    }

    /// A frame the controller's port handed out or sent at `t`.
    pub fn can(&mut self, t: f64, frame: TapFrame) {
        self.send(Entry::Can(t, frame));
    }

    /// See [`Writer::log_other`].
    pub fn log_other(&mut self, topic: &'static str, t: f64, value: serde_json::Value) {
        self.send(Entry::Json(topic, t, value));
    }

    /// A GPS epoch the controller read at `t` ([`Writer::reading`]).
    pub fn reading(&mut self, t: f64, r: &GpsReading) {
        self.send(Entry::Fix(t, Box::new(r.clone())));
    }

    /// See [`Writer::controller`]; and the controller's estimate of the car's pose as
    /// world -> base_link every [`POSE_PERIOD`] (in the controller's own recording
    /// only: the simulator's has the true pose there).
    pub fn controller(&mut self, t: f64, ctl: &Controller) {
        let (state, plans) = self.cadence.take(t, ctl);
        if let Some(state) = state {
            self.send(Entry::State(t, state));
        }
        for planned in plans {
            self.send(Entry::Plan(t, planned));
        }
        if t + 1e-9 >= self.next_pose
            && let Some(p) = ctl.pose(t)
        {
            self.next_pose = t + POSE_PERIOD;
            self.send(Entry::Pose(t, [p.x, p.y, p.theta]));
        }
    }

    /// Let the thread write what is queued and close the recording; what it holds.
    pub fn finish(mut self) -> Option<RecordSummary> {
        self.close()
    }

    fn close(&mut self) -> Option<RecordSummary> {
        // A gap at the end is marked too: the thread writes what is queued, then it.
        let queue = self.queue.take();
        if let (Some(q), Some(gap)) = (&queue, self.gap.take()) {
            let _ = q.send(gap.mark());
        }
        drop(queue);
        let mut summary = self.thread.take()?.join().ok().flatten()?;
        if self.dropped > 0 {
            summary.error.get_or_insert(format!(
                "{} entries dropped: the recorder's queue was full",
                self.dropped
            ));
        }
        Some(summary)
    }
}

impl Drop for BackgroundWriter {
    fn drop(&mut self) {
        self.close();
    }
}

impl Writer {
    fn write(&mut self, entry: Entry) {
        match entry {
            Entry::Nmea(t, bytes) => self.nmea(t, &bytes),
            Entry::Laser(t, frame) => self.laser(t, &frame),
            Entry::Can(t, f) => self.can(t, &f),
            Entry::Json(topic, t, value) => self.log_other(topic, t, &value),
            Entry::State(t, value) => self.log_json(&self.state, t, &value),
            Entry::Plan(t, planned) => self.plan(t, &planned),
            Entry::Fix(t, reading) => self.reading(t, &reading),
            Entry::Pose(t, [x, y, theta]) => self.base_link(t, x, y, theta),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_are_written_as_serde_json_writes_them() {
        let values = [
            0.0,
            -0.0,
            3.0,
            -12.0,
            0.5,
            -1.25,
            1e9,
            999_999_999.0,
            1e-7,
            2.5e20,
            1.0 / 3.0,
        ];
        for v in values
            .into_iter()
            .chain((0..2000).map(|k| f64::from(k) * 0.25 - 250.0))
        {
            let mut ours = Vec::new();
            push_number(&mut ours, v).unwrap();
            let theirs = serde_json::to_string(&v).unwrap();
            assert_eq!(String::from_utf8(ours).unwrap(), theirs, "{v}");
        }
    }

    #[test]
    fn an_nmea_line_is_logged_at_the_tick_that_read_its_first_terminator_as_the_reader_ends_it() {
        let dir = tempfile::tempdir().unwrap();
        let info = RunInfo::field(
            "lines".to_owned(),
            1_000_000_000,
            "mem".to_owned(),
            firmware_bridge::nmea::ReaderConfig::default().complete_when,
            115_200,
            &crate::config::ControllerConfig::default(),
        )
        .unwrap();
        let mut w = Writer::create(Some(dir.path()), foxglove::Context::new(), info).unwrap();
        // Reads that end between a CR and its LF, in a line, and after an LF.
        let reads: [&[u8]; 4] = [
            b"$GPZDA,1*00\r",
            b"\n$GPZDA,2",
            b"*00\r\n$GPZDA,3*00\r\n",
            b"$X",
        ];
        for (k, bytes) in reads.iter().enumerate() {
            w.nmea(k as f64 * 0.01, bytes);
        }
        w.finish();
        let bytes = std::fs::read(dir.path().join(MCAP_FILE)).unwrap();
        let lines: Vec<(u64, String)> = mcap::MessageStream::new(&bytes)
            .unwrap()
            .map(|m| m.unwrap())
            .filter(|m| m.channel.topic == topics::NMEA)
            .map(|m| {
                let v: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
                (
                    m.log_time - 1_000_000_000,
                    v["sentence"].as_str().unwrap().to_owned(),
                )
            })
            .collect();
        let line = |ms: u64, s: &str| (ms * 1_000_000, s.to_owned());
        assert_eq!(
            lines,
            [
                line(0, "$GPZDA,1*00"),
                line(20, "$GPZDA,2*00"),
                line(20, "$GPZDA,3*00")
            ]
        );
    }

    /// A writer whose queue holds `n` entries, and the queue's other end (no thread).
    fn held_queue(n: usize) -> (BackgroundWriter, std::sync::mpsc::Receiver<Entry>) {
        let (queue, entries) = std::sync::mpsc::sync_channel(n);
        let w = BackgroundWriter {
            queue: Some(queue),
            thread: None,
            cadence: StateCadence::default(),
            next_pose: 0.0,
            dropped: 0,
            gap: None,
        };
        (w, entries)
    }

    /// The times of the entries queued, and the gaps marked among them.
    fn drained(entries: &std::sync::mpsc::Receiver<Entry>) -> (Vec<f64>, Vec<serde_json::Value>) {
        let (mut times, mut marks) = (Vec::new(), Vec::new());
        for e in entries.try_iter() {
            match e {
                Entry::Json(topics::CONTROLLER_DROPPED, t, v) => marks.push(json!([t, v])),
                e => times.push(e.time()),
            }
        }
        (times, marks)
    }

    #[test]
    fn a_full_queue_loses_entries_and_the_file_marks_the_gap_before_the_next() {
        let (mut w, entries) = held_queue(3);
        let log = |w: &mut BackgroundWriter, t: f64| {
            w.log_other(topics::CONTROLLER_STOP, t, json!({}));
        };
        // 0-2 s taken, 3-6 s lost.
        (0..7).for_each(|k| log(&mut w, f64::from(k)));
        assert_eq!(drained(&entries), (vec![0.0, 1.0, 2.0], vec![]));
        // The queue has room: the gap's mark, then the entry.
        log(&mut w, 7.0);
        let gap = json!([6.0, { "from": 3.0, "entries": 4 }]);
        assert_eq!(drained(&entries), (vec![7.0], vec![gap]));
        // 8-10 s taken, 11 s lost; the queue still full, the mark does not fit before
        // 11.5 s: it is lost too, and the gap grows.
        (8..12).for_each(|k| log(&mut w, f64::from(k)));
        log(&mut w, 11.5);
        assert_eq!(drained(&entries), (vec![8.0, 9.0, 10.0], vec![]));
        log(&mut w, 12.0);
        let gap = json!([11.5, { "from": 11.0, "entries": 2 }]);
        assert_eq!(drained(&entries), (vec![12.0], vec![gap]));
        assert_eq!(w.dropped, 6);
        // A gap at the end is marked when the writer closes.
        (13..17).for_each(|k| log(&mut w, f64::from(k)));
        assert_eq!(drained(&entries).0, [13.0, 14.0, 15.0]);
        assert!(w.close().is_none(), "no thread, no summary");
        let gap = json!([16.0, { "from": 16.0, "entries": 1 }]);
        assert_eq!(drained(&entries), (vec![], vec![gap]));
    }

    /// A scan of `n` beams with ranges, a dropout and no return among them.
    fn scan(n: u32) -> LaserFrame {
        let mut f = LaserFrame {
            count: n,
            stamp_ns: 1_700_000_000_123_456_789,
            angle_min: -2.35,
            angle_increment: 0.0087,
            range_max: 20.0,
            ..LaserFrame::default()
        };
        for i in 0..n as usize {
            f.ranges[i] = 0.5 + i as f32 * 0.37;
            f.intensities[i] = i as f32;
        }
        if n > 2 {
            f.ranges[1] = f32::NAN;
            f.ranges[2] = f32::INFINITY;
        }
        f
    }

    #[test]
    fn scans_are_encoded_as_the_sdk_encodes_a_laser_scan() {
        for n in [0, 1, 3, 541] {
            let frame = scan(n);
            let sdk = LaserScan {
                timestamp: Some(timestamp(frame.stamp_ns)),
                frame_id: "laser".to_owned(),
                pose: None,
                start_angle: f64::from(frame.angle_min),
                end_angle: f64::from(frame.angle_max()),
                ranges: frame.ranges().iter().map(|r| f64::from(*r)).collect(),
                intensities: frame.intensities().iter().map(|r| f64::from(*r)).collect(),
            };
            let mut expected = Vec::new();
            Encode::encode(&sdk, &mut expected).unwrap();
            let mut ours = vec![0xAA];
            encode_scan(&mut ours, &frame).unwrap();
            assert_eq!(ours[1..], expected[..], "{n} beams");
        }
    }

    /// What the recorder wrote per frame before (serde_json maps).
    fn as_maps(spec: &NetworkSpec, f: &TapFrame) -> (String, Option<String>) {
        let hex: String = f.data.iter().map(|b| format!("{b:02X}")).collect();
        let mut raw = json!({
            "id": f.id,
            "extended": f.extended,
            "data": hex,
            "direction": match f.sent {
                Some(false) => "tx",
                Some(true) | None => direction(spec, f.id),
            },
        });
        if let Some(sent) = f.sent {
            raw["sent"] = sent.into();
        }
        if let Some(k) = f.kernel {
            raw["wall_unix_ns"] = unix_ns(k).into();
        }
        let message = (!f.extended)
            .then(|| u16::try_from(f.id).ok())
            .flatten()
            .and_then(|id| spec.message(id));
        let decoded = match (message, golf_car_can::codec::payload("", &f.data)) {
            (Some(m), Ok(p)) => {
                let signals: serde_json::Map<String, serde_json::Value> = m
                    .decode_all(&p)
                    .into_iter()
                    .map(|v| (v.name.to_owned(), v.value.into()))
                    .collect();
                Some(json!({ "id": f.id, "message": m.name, "signals": signals }).to_string())
            }
            _ => None,
        };
        (raw.to_string(), decoded)
    }

    #[test]
    fn can_json_is_what_the_maps_gave_for_every_message_and_odd_frames() {
        let spec = NetworkSpec::from_dbc(golf_car_can::GOLF_CAR_DBC).unwrap();
        // The recorder's is the one built in; the maps' the DBC read at run time.
        let can = CanJson::new(golf_car_can::NETWORK.clone()).unwrap();
        let kernel = Some(SystemTime::UNIX_EPOCH + Duration::from_nanos(1_700_000_000_987_654_321));
        let mut frames: Vec<TapFrame> = spec
            .messages
            .iter()
            .enumerate()
            .map(|(i, m)| TapFrame {
                id: u32::from(m.id),
                extended: false,
                data: (0..8).map(|b| (b * 37 + i * 101) as u8).collect(),
                kernel: if i % 2 == 0 { kernel } else { None },
                sent: [None, Some(true), Some(false)][i % 3],
            })
            .collect();
        assert!(frames.len() > 3, "golf_car.dbc has its messages");
        for (id, extended, len) in [(0x7FF, false, 8), (0x123, true, 8), (0x1FFF_FFFF, true, 0)] {
            frames.push(TapFrame {
                id,
                extended,
                data: vec![0xFF; len],
                kernel: None,
                sent: None,
            });
        }
        // A known message with a short payload: raw only.
        frames.push(TapFrame {
            data: vec![1, 2],
            ..frames[0].clone()
        });
        for f in &frames {
            let (raw, decoded) = as_maps(&spec, f);
            let at = can.position(f.id);
            let direction = match f.sent {
                Some(false) => "tx",
                _ => can.direction(at),
            };
            let mut buf = Vec::new();
            CanJson::raw(&mut buf, f, direction);
            assert_eq!(String::from_utf8(buf).unwrap(), raw);
            let mut buf = Vec::new();
            let written = match at.filter(|_| !f.extended) {
                Some(at) => can.decoded(&mut buf, at, &f.data).unwrap(),
                None => false,
            };
            assert_eq!(
                written.then(|| String::from_utf8(buf).unwrap()),
                decoded,
                "{f:?}"
            );
        }
    }
}
