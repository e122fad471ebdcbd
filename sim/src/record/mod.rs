//! Every run recorded at the simulator's side of the wires, in formats others read:
//!
//! - `run.mcap` (Foxglove SDK, its built-in schemas): the laser as
//!   `foxglove.LaserScan`, the fix as `foxglove.LocationFix`, the car as
//!   `foxglove.FrameTransform` and `foxglove.PoseInFrame`, obstacles and the
//!   controller's planned paths as `foxglove.SceneUpdate`, every CAN frame raw and
//!   decoded per golf_car.dbc (JSON), the NMEA sentences as sent, the controller's
//!   state (JSON). Log time is simulated time on the scenario's UTC epoch; in HIL the
//!   wall clock goes alongside (`wall_unix_ns` in the JSON messages).
//! - `bus.log`: every CAN frame in `candump -l` form (kernel receive timestamps in
//!   HIL, simulated time in SIL), for canplayer and `ugv-can decode`.
//! - `gps.nmea`: the NMEA byte stream exactly as sent, for gpsfake.
//!
//! Written as the run goes with bounded buffering: MCAP chunks close when they reach
//! [`CHUNK_SIZE`] and at least every [`FLUSH_PERIOD`] of wall-clock time, when the two
//! text files reach the kernel too, so a simulator killed with SIGKILL leaves
//! everything up to its last second readable (an MCAP without its summary section is
//! still read by a streaming reader).
//!
//! One recorder for both modes: the runner hands it what the sensors produced
//! ([`Recorder::sensors`]) and, after each step, what crossed the bus
//! ([`Recording::after_step`], from a [`tap::BusTap`]: a memory-bus endpoint in SIL,
//! a CAN socket in HIL).
//!
//! The same channels feed the live view ([`live::LiveView`], `ugv-sim run --live`)
//! when one is given ([`Outputs`]): the recorder then logs through the live view's
//! context, so the files and the WebSocket clients get the same messages; without a
//! directory (`--no-record`) it writes no file and the channels serve the live view
//! alone.

pub mod live;
pub mod replay;
pub mod tap;
pub mod topics;

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime};

use firmware_bridge::clock::unix_ns;

use foxglove::schemas::{
    Color, CylinderPrimitive, FrameTransform, LaserScan, LinePrimitive, LocationFix, Point3, Pose,
    PoseInFrame, Quaternion, SceneEntity, SceneUpdate, Timestamp, Vector3,
};
use foxglove::{Channel, Context, McapWriteOptions, McapWriterHandle, PartialMetadata, RawChannel};
use golf_car_can::candump::Compact;
use golf_car_can::spec::NetworkSpec;
use serde::{Deserialize, Serialize};
use serde_json::json;

use crate::devices::gps::GpsEpoch;
use crate::run::{SensorOutput, Sim};
use crate::scenario::{Obstacle, Scenario};
use crate::vehicle::VehicleState;
use firmware_bridge::laser::LaserFrame;
use tap::{BusTap, TapFrame};
use ugv_controller::core::Controller;

/// The recording's file names in the run's results directory.
pub const MCAP_FILE: &str = "run.mcap";
pub const BUS_LOG: &str = "bus.log";
pub const NMEA_FILE: &str = "gps.nmea";

/// Longest wall-clock time between two flushes to the kernel.
pub const FLUSH_PERIOD: Duration = Duration::from_secs(1);

/// An MCAP chunk is closed when it holds this many bytes (or at the next flush).
pub const CHUNK_SIZE: u64 = 1 << 20;

/// Seconds between two vehicle poses (the physics may run faster).
const POSE_PERIOD: f64 = 0.02;
/// Seconds between two obstacle scenes when something moves (else one a second, for
/// live viewers who connect late).
const SCENE_PERIOD_MOVING: f64 = 0.1;
const SCENE_PERIOD_STATIC: f64 = 1.0;
/// Seconds between two controller states when nothing changed.
const STATE_PERIOD: f64 = 0.1;

/// Why a recording could not be made.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    #[error("creating {path}: {source}")]
    Create {
        path: String,
        #[source]
        source: std::io::Error,
    },
    #[error("starting the MCAP writer on {path}: {source}")]
    Mcap {
        path: String,
        #[source]
        source: foxglove::FoxgloveError,
    },
    #[error("creating the channel {topic}: {source}")]
    Channel {
        topic: String,
        #[source]
        source: foxglove::FoxgloveError,
    },
    #[error("golf_car.dbc: {0}")]
    Dbc(#[from] golf_car_can::spec::SpecError),
    #[error("the CAN tap on {iface}: {source}")]
    Tap {
        iface: String,
        #[source]
        source: std::io::Error,
    },
}

/// Which loop made the recording: the run's [`Mode`](crate::Mode).
pub use crate::mode::Mode as RecordMode;

/// What a replay needs to know about the run, kept in the MCAP metadata record
/// [`RUN_METADATA`] (one string per field) and the attachment [`CONFIG_ATTACHMENT`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunInfo {
    pub mode: RecordMode,
    pub scenario: String,
    /// Physics rate, Hz (SIL's controller ticks fall on its steps).
    pub physics_hz: f64,
    /// UTC of simulated t = 0, ns since 1970: log time = this + simulated time.
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
    pub fn of(mode: RecordMode, sc: &Scenario, controller_toml: String) -> RunInfo {
        RunInfo {
            mode,
            scenario: sc.name.clone(),
            physics_hz: sc.sim.physics_hz,
            epoch_unix_ns: sc.sim.epoch.unix_ns(),
            can_interface: sc.can.interface.clone(),
            gps_sentences: sc.gps.sentence_set(),
            gps_baud: sc.gps.baud,
            controller_toml,
        }
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

fn timestamp(ns: u64) -> Timestamp {
    Timestamp::new(
        u32::try_from(ns / 1_000_000_000).unwrap_or(u32::MAX),
        (ns % 1_000_000_000) as u32,
    )
}

/// A quaternion for a yaw about +z.
fn yaw(theta: f64) -> Quaternion {
    Quaternion {
        x: 0.0,
        y: 0.0,
        z: (theta / 2.0).sin(),
        w: (theta / 2.0).cos(),
    }
}

fn pose(x: f64, y: f64, theta: f64) -> Pose {
    Pose {
        position: Some(Vector3 { x, y, z: 0.0 }),
        orientation: Some(yaw(theta)),
    }
}

/// Direction of a frame seen from the simulator: `rx` what the controller sends
/// (towards the ECUs), `tx` what the ECUs send (towards the controller).
pub fn direction(spec: &NetworkSpec, id: u32) -> &'static str {
    let controller = u16::try_from(id)
        .ok()
        .and_then(|id| spec.message(id))
        .is_some_and(|m| m.senders.iter().any(|s| s == "CONTROLLER"));
    if controller { "rx" } else { "tx" }
}

/// Where a run's topics go: files in a directory (run.mcap, bus.log, gps.nmea), a
/// live view, both, or neither (then no recorder is made at all).
#[derive(Clone, Copy, Debug, Default)]
pub struct Outputs<'a> {
    /// Record into this directory (which must exist).
    pub dir: Option<&'a Path>,
    /// Serve the channels on this live view too.
    pub live: Option<&'a live::LiveView>,
}

impl Outputs<'_> {
    /// Whether anything is to be recorded or served.
    pub fn any(&self) -> bool {
        self.dir.is_some() || self.live.is_some()
    }
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

/// The MCAP channels.
struct Channels {
    laser: Option<Channel<LaserScan>>,
    fix: Channel<LocationFix>,
    tf: Channel<FrameTransform>,
    pose: Channel<PoseInFrame>,
    obstacles: Channel<SceneUpdate>,
    plans: Channel<SceneUpdate>,
    can_raw: Arc<RawChannel>,
    can_decoded: Arc<RawChannel>,
    nmea: Arc<RawChannel>,
    state: Arc<RawChannel>,
}

fn json_channel(
    ctx: &Arc<Context>,
    topic: &str,
) -> Result<Arc<RawChannel>, foxglove::FoxgloveError> {
    ctx.channel_builder(topic)
        .message_encoding("json")
        .build_raw()
}

/// Writes one run's recording.
pub struct Recorder {
    ctx: Arc<Context>,
    mcap: Option<McapWriterHandle<BufWriter<File>>>,
    ch: Channels,
    bus_log: TextOut,
    nmea: TextOut,
    spec: NetworkSpec,
    info: RunInfo,
    obstacles: Vec<Obstacle>,
    moving: bool,
    last_flush: Instant,
    next_pose: f64,
    next_scene: f64,
    next_state: f64,
    last_mode: Option<String>,
    plans_seen: usize,
    /// Whether files are written (else the channels serve a live view only).
    files: bool,
    summary: RecordSummary,
}

impl std::fmt::Debug for Recorder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Recorder")
            .field("summary", &self.summary)
            .finish_non_exhaustive()
    }
}

impl Recorder {
    /// Start the recording of a run of `sc` into `out`: the files in `out.dir` (which
    /// must exist), the channels on `out.live`'s context when given.
    pub fn create(out: Outputs<'_>, sc: &Scenario, info: RunInfo) -> Result<Recorder, RecordError> {
        let dir = out.dir.unwrap_or(Path::new(""));
        let mcap_path = dir.join(MCAP_FILE);
        let mcap_err = |source| RecordError::Mcap {
            path: mcap_path.display().to_string(),
            source,
        };
        let ctx = match out.live {
            Some(live) => Arc::clone(live.context()),
            None => Context::new(),
        };
        let mcap = match out.dir {
            Some(_) => {
                let file = File::create(&mcap_path).map_err(|source| RecordError::Create {
                    path: mcap_path.display().to_string(),
                    source,
                })?;
                let options = McapWriteOptions::new()
                    .compression(None)
                    .chunk_size(Some(CHUNK_SIZE));
                let mcap = ctx
                    .mcap_writer_with_options(options)
                    .create(BufWriter::new(file))
                    .map_err(mcap_err)?;
                mcap.write_metadata(RUN_METADATA, info.metadata())
                    .map_err(mcap_err)?;
                mcap.attach(&foxglove::McapAttachment {
                    log_time: info.epoch_unix_ns,
                    create_time: info.epoch_unix_ns,
                    name: CONFIG_ATTACHMENT.to_owned(),
                    media_type: "application/toml".to_owned(),
                    data: std::borrow::Cow::Borrowed(info.controller_toml.as_bytes()),
                })
                .map_err(mcap_err)?;
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
        let ch = Channels {
            laser: None,
            fix: ctx.channel_builder(topics::FIX).build(),
            tf: ctx.channel_builder(topics::TF).build(),
            pose: ctx.channel_builder(topics::POSE).build(),
            obstacles: ctx.channel_builder(topics::OBSTACLES).build(),
            plans: ctx.channel_builder(topics::PLANS).build(),
            can_raw: json(topics::CAN_RAW)?,
            can_decoded: json(topics::CAN_DECODED)?,
            nmea: json(topics::NMEA)?,
            state: json(topics::CONTROLLER_STATE)?,
        };
        let spec = NetworkSpec::from_dbc(golf_car_can::GOLF_CAR_DBC)?;
        let obstacles = sc.obstacles.clone();
        let moving = obstacles.iter().any(|o| {
            matches!(
                o,
                Obstacle::Circle {
                    motion: Some(_),
                    ..
                } | Obstacle::Box {
                    motion: Some(_),
                    ..
                }
            )
        });
        let text = |name| match out.dir {
            Some(dir) => TextOut::create(dir.join(name)),
            None => Ok(TextOut::none()),
        };
        Ok(Recorder {
            ch,
            mcap,
            bus_log: text(BUS_LOG)?,
            nmea: text(NMEA_FILE)?,
            spec,
            info,
            obstacles,
            moving,
            last_flush: Instant::now(),
            next_pose: 0.0,
            next_scene: 0.0,
            next_state: 0.0,
            last_mode: None,
            plans_seen: 0,
            files: out.dir.is_some(),
            summary: RecordSummary {
                dir: dir.to_path_buf(),
                ..RecordSummary::default()
            },
            ctx,
        })
    }

    /// Log time of simulated time `t`, ns since 1970.
    fn ns(&self, t: f64) -> u64 {
        self.info.epoch_unix_ns + (t.max(0.0) * 1e9).round() as u64
    }

    fn log_json(&self, channel: &RawChannel, t: f64, value: &serde_json::Value) {
        let bytes = value.to_string();
        channel.log_with_meta(bytes.as_bytes(), PartialMetadata::with_log_time(self.ns(t)));
    }

    /// The wall clock alongside simulated time (HIL only).
    fn wall(&self) -> Option<u64> {
        (self.info.mode == RecordMode::Hil).then(|| unix_ns(SystemTime::now()))
    }

    /// What the sensors produced at simulated time `t`, as it goes on the wires.
    pub fn sensors(&mut self, t: f64, out: &SensorOutput) {
        if let Some(epoch) = &out.gps {
            self.gps(t, epoch);
        }
        if let Some(frame) = &out.laser {
            self.laser(t, frame);
        }
    }

    fn gps(&mut self, t: f64, epoch: &GpsEpoch) {
        let mut error = self.summary.error.take();
        self.nmea.write(epoch.text.as_bytes(), &mut error);
        self.summary.error = error;
        let wall = self.wall();
        for sentence in epoch.text.split_terminator("\r\n") {
            let mut m = json!({ "sentence": sentence });
            if let Some(w) = wall {
                m["wall_unix_ns"] = w.into();
            }
            self.log_json(&self.ch.nmea, t, &m);
            self.summary.nmea_sentences += 1;
        }
        let f = &epoch.fix;
        let sigma = f
            .accuracy
            .map(|a| [a.lat_sigma_m, a.lon_sigma_m, a.alt_sigma_m]);
        self.ch.fix.log_with_time(
            &LocationFix {
                timestamp: Some(timestamp(self.ns(t))),
                frame_id: "gps".to_owned(),
                latitude: f.lat_deg,
                longitude: f.lon_deg,
                altitude: f.ellipsoid_height_m,
                // Diagonal covariance from GST (type 2, diagonal known), else unknown.
                position_covariance: sigma.map_or_else(Vec::new, |[n, e, u]| {
                    vec![e * e, 0.0, 0.0, 0.0, n * n, 0.0, 0.0, 0.0, u * u]
                }),
                position_covariance_type: if sigma.is_some() { 2 } else { 0 },
                heading: f.heading_deg,
                ..LocationFix::default()
            },
            self.ns(t),
        );
        self.summary.fixes += 1;
    }

    fn laser(&mut self, t: f64, frame: &LaserFrame) {
        if self.ch.laser.is_none() {
            // The frame's constant fields, exactly (f32 text round-trips), for replay.
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
            self.ch.laser = Some(
                self.ctx
                    .channel_builder(topics::LASER)
                    .metadata(meta)
                    .build(),
            );
        }
        let Some(channel) = &self.ch.laser else {
            return;
        };
        channel.log_with_time(
            &LaserScan {
                timestamp: Some(timestamp(frame.stamp_ns)),
                frame_id: "laser".to_owned(),
                pose: None,
                start_angle: f64::from(frame.angle_min),
                end_angle: f64::from(frame.angle_max()),
                ranges: frame.ranges().iter().map(|r| f64::from(*r)).collect(),
                intensities: frame.intensities().iter().map(|r| f64::from(*r)).collect(),
            },
            self.ns(t),
        );
        self.summary.laser_scans += 1;
    }

    /// One CAN frame seen on the bus at simulated time `t`.
    fn can(&mut self, t: f64, f: &TapFrame) {
        let ns = self.ns(t);
        // candump -l: kernel receive time in HIL, simulated time in SIL.
        let stamp = f.kernel.map_or(ns, unix_ns);
        let compact = Compact {
            id: f.id,
            extended: f.extended,
            data: &f.data,
        };
        let line = format!(
            "({}.{:06}) {} {compact}\n",
            stamp / 1_000_000_000,
            (stamp % 1_000_000_000) / 1000,
            self.info.can_interface
        );
        let mut error = self.summary.error.take();
        self.bus_log.write(line.as_bytes(), &mut error);
        self.summary.error = error;
        let hex: String = f.data.iter().map(|b| format!("{b:02X}")).collect();
        let mut raw = json!({
            "id": f.id,
            "extended": f.extended,
            "data": hex,
            "direction": direction(&self.spec, f.id),
        });
        if let Some(k) = f.kernel {
            raw["wall_unix_ns"] = unix_ns(k).into();
        }
        self.log_json(&self.ch.can_raw, t, &raw);
        let message = (!f.extended)
            .then(|| u16::try_from(f.id).ok())
            .flatten()
            .and_then(|id| self.spec.message(id));
        if let (Some(m), Ok(p)) = (message, golf_car_can::codec::payload("", &f.data)) {
            let signals: serde_json::Map<String, serde_json::Value> = m
                .decode_all(&p)
                .into_iter()
                .map(|v| (v.name.to_owned(), v.value.into()))
                .collect();
            let decoded = json!({ "id": f.id, "message": m.name, "signals": signals });
            self.log_json(&self.ch.can_decoded, t, &decoded);
        }
        self.summary.can_frames += 1;
    }

    /// The car, the obstacles, and the controller (when in-process) at time `t`.
    fn world(&mut self, t: f64, v: &VehicleState) {
        if t + 1e-9 >= self.next_pose {
            self.next_pose = t + POSE_PERIOD;
            let ns = self.ns(t);
            self.ch.tf.log_with_time(
                &FrameTransform {
                    timestamp: Some(timestamp(ns)),
                    parent_frame_id: "world".to_owned(),
                    child_frame_id: "base_link".to_owned(),
                    translation: Some(Vector3 {
                        x: v.x,
                        y: v.y,
                        z: 0.0,
                    }),
                    rotation: Some(yaw(v.theta)),
                },
                ns,
            );
            self.ch.pose.log_with_time(
                &PoseInFrame {
                    timestamp: Some(timestamp(ns)),
                    frame_id: "world".to_owned(),
                    pose: Some(pose(v.x, v.y, v.theta)),
                },
                ns,
            );
        }
        if t + 1e-9 >= self.next_scene {
            self.next_scene = t + if self.moving {
                SCENE_PERIOD_MOVING
            } else {
                SCENE_PERIOD_STATIC
            };
            self.scene(t);
        }
    }

    fn scene(&mut self, t: f64) {
        let ns = self.ns(t);
        let grey = Color {
            r: 0.55,
            g: 0.55,
            b: 0.6,
            a: 1.0,
        };
        let entities = self
            .obstacles
            .iter()
            .enumerate()
            .map(|(i, o)| {
                let mut e = SceneEntity {
                    timestamp: Some(timestamp(ns)),
                    frame_id: "world".to_owned(),
                    id: format!("obstacle-{i}"),
                    ..SceneEntity::default()
                };
                match o {
                    Obstacle::Circle {
                        x,
                        y,
                        radius,
                        motion,
                    } => {
                        let (x, y) = crate::world::position_at(*x, *y, motion, t);
                        e.cylinders.push(CylinderPrimitive {
                            pose: Some(pose(x, y, 0.0)),
                            size: Some(Vector3 {
                                x: 2.0 * radius,
                                y: 2.0 * radius,
                                z: 1.0,
                            }),
                            bottom_scale: 1.0,
                            top_scale: 1.0,
                            color: Some(grey),
                        });
                    }
                    Obstacle::Box {
                        x,
                        y,
                        length,
                        width,
                        heading_deg,
                        motion,
                    } => {
                        let (x, y) = crate::world::position_at(*x, *y, motion, t);
                        e.cubes.push(foxglove::schemas::CubePrimitive {
                            pose: Some(pose(x, y, heading_deg.to_radians())),
                            size: Some(Vector3 {
                                x: *length,
                                y: *width,
                                z: 1.0,
                            }),
                            color: Some(grey),
                        });
                    }
                    Obstacle::Wall { points, thickness } => {
                        e.lines.push(LinePrimitive {
                            r#type: foxglove::schemas::line_primitive::Type::LineStrip as i32,
                            thickness: *thickness,
                            points: points
                                .iter()
                                .map(|p| Point3 {
                                    x: p[0],
                                    y: p[1],
                                    z: 0.0,
                                })
                                .collect(),
                            color: Some(grey),
                            ..LinePrimitive::default()
                        });
                    }
                }
                e
            })
            .collect();
        self.ch.obstacles.log_with_time(
            &SceneUpdate {
                deletions: Vec::new(),
                entities,
            },
            ns,
        );
    }

    /// The in-process controller's state (on change of mode and every
    /// [`STATE_PERIOD`]) and its new planned paths.
    fn controller(&mut self, t: f64, ctl: &Controller) {
        let mode = serde_json::to_value(ctl.mode()).unwrap_or_default();
        let mode_text = mode.to_string();
        let changed = self.last_mode.as_deref() != Some(mode_text.as_str());
        if changed || t + 1e-9 >= self.next_state {
            self.next_state = t + STATE_PERIOD;
            let pose = ctl.pose(t).and_then(|p| serde_json::to_value(p).ok());
            let state = json!({
                "mode": mode,
                "changed": changed,
                "pose": pose,
                "obstacles": ctl.obstacles(),
                "stop_reason": ctl.stop_reason(),
            });
            self.log_json(&self.ch.state, t, &state);
            self.last_mode = Some(mode_text);
        }
        let plans = &ctl.nav.plans;
        if plans.len() > self.plans_seen {
            let ns = self.ns(t);
            let green = Color {
                r: 0.1,
                g: 0.8,
                b: 0.3,
                a: 1.0,
            };
            for p in &plans[self.plans_seen..] {
                let entity = SceneEntity {
                    timestamp: Some(timestamp(ns)),
                    frame_id: "world".to_owned(),
                    id: "plan".to_owned(),
                    lines: vec![LinePrimitive {
                        r#type: foxglove::schemas::line_primitive::Type::LineStrip as i32,
                        thickness: 0.1,
                        points: p
                            .path
                            .iter()
                            .map(|q| Point3 {
                                x: q[0],
                                y: q[1],
                                z: 0.05,
                            })
                            .collect(),
                        color: Some(green),
                        ..LinePrimitive::default()
                    }],
                    ..SceneEntity::default()
                };
                self.ch.plans.log_with_time(
                    &SceneUpdate {
                        deletions: Vec::new(),
                        entities: vec![entity],
                    },
                    ns,
                );
            }
            self.plans_seen = plans.len();
        }
    }

    /// Hand what was written to the kernel when [`FLUSH_PERIOD`] has passed.
    fn maybe_flush(&mut self) {
        if self.last_flush.elapsed() >= FLUSH_PERIOD {
            self.flush();
        }
    }

    fn flush(&mut self) {
        self.last_flush = Instant::now();
        let mut error = self.summary.error.take();
        self.bus_log.flush(&mut error);
        self.nmea.flush(&mut error);
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
            && let Err(e) = m.close()
        {
            self.summary
                .error
                .get_or_insert_with(|| format!("closing {MCAP_FILE}: {e}"));
        }
        self.files.then(|| self.summary.clone())
    }
}

/// A recorder with its tap on the bus: the one thing a runner calls.
#[derive(Debug)]
pub struct Recording<T> {
    pub recorder: Recorder,
    tap: T,
    frames: Vec<TapFrame>,
}

impl<T: BusTap> Recording<T> {
    pub fn new(recorder: Recorder, tap: T) -> Recording<T> {
        Recording {
            recorder,
            tap,
            frames: Vec::new(),
        }
    }

    /// What the sensors produced at `t` (call before the outputs go on the wires).
    pub fn sensors(&mut self, t: f64, out: &SensorOutput) {
        self.recorder.sensors(t, out);
    }

    /// After the step at `t` (and the in-process controller's tick, if any): the
    /// frames on the bus, the car and the world, the controller's state.
    pub fn after_step<B: embedded_can::nb::Can>(
        &mut self,
        t: f64,
        sim: &Sim<B>,
        controller: Option<&Controller>,
    ) {
        if let Err(e) = self.tap.drain(&mut self.frames) {
            self.recorder
                .summary
                .error
                .get_or_insert_with(|| format!("the CAN tap: {e}"));
        }
        for f in std::mem::take(&mut self.frames) {
            self.recorder.can(t, &f);
        }
        self.recorder.world(t, &sim.vehicle);
        if let Some(c) = controller {
            self.recorder.controller(t, c);
        }
        self.recorder.maybe_flush();
    }

    /// See [`Recorder::finish`]; the summary also says how many frames the tap lost.
    pub fn finish(mut self) -> Option<RecordSummary> {
        self.recorder.summary.can_frames_lost = self.tap.queue_drops();
        self.recorder.finish()
    }
}
