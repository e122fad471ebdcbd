//! Every run recorded at the simulator's side of the wires, in formats others read:
//!
//! - `run.mcap` (the Foxglove SDK's built-in schemas, written by the controller
//!   library's `McapFile`): the laser as
//!   `foxglove.LaserScan`, the fix as `foxglove.LocationFix`, the car as
//!   `foxglove.FrameTransform` (world -> base_link, with the scenario's sensor mounts
//!   base_link -> laser and base_link -> gps) and `foxglove.PoseInFrame`, obstacles and the
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
//! The topics every recording has are the controller library's
//! ([`ugv_controller::record::Writer`], which the controller's own recording,
//! `ugv-controller run --record`, uses too); this adds the world's (the fix, the car,
//! the obstacles).
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

use std::path::Path;
use std::sync::Arc;

use foxglove::Channel;
use foxglove::Context;
use foxglove::schemas::{
    Color, CylinderPrimitive, LinePrimitive, Point3, Pose, PoseInFrame, SceneEntity, SceneUpdate,
    Vector3,
};

use crate::devices::gps::GpsEpoch;
use crate::run::{SensorOutput, Sim};
use crate::scenario::{Obstacle, Scenario};
use crate::vehicle::VehicleState;
use tap::{BusTap, TapFrame};
use ugv_controller::control::Controller;
pub use ugv_controller::record::{
    BUS_LOG, CHUNK_SIZE, CONFIG_ATTACHMENT, FLUSH_PERIOD, MCAP_FILE, NMEA_FILE, RUN_METADATA,
    RecordError, RecordMode, RecordSummary, RunInfo, describe, direction, timestamp, topics,
};
use ugv_controller::record::{Mounts, POSE_PERIOD, Writer, yaw};

/// The directory under a HIL run's results where the controller `ugv-sim run
/// --controller-log` starts records its own ports (`ugv-controller run --record`).
pub const CONTROLLER_LOG_DIR: &str = "controller";

/// Seconds between two obstacle scenes when something moves (else one a second, for
/// live viewers who connect late).
const SCENE_PERIOD_MOVING: f64 = 0.1;
const SCENE_PERIOD_STATIC: f64 = 1.0;

/// The [`RunInfo`] of a run of `sc` in `mode`.
pub fn run_info(mode: RecordMode, sc: &Scenario, controller_toml: String) -> RunInfo {
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

fn pose(x: f64, y: f64, theta: f64) -> Pose {
    Pose {
        position: Some(Vector3 { x, y, z: 0.0 }),
        orientation: Some(yaw(theta)),
    }
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

/// The world's MCAP channels (the rest are the [`Writer`]'s).
struct WorldChannels {
    pose: Channel<PoseInFrame>,
    obstacles: Channel<SceneUpdate>,
}

/// Writes one run's recording: the [`Writer`]'s topics and the world's.
pub struct Recorder {
    w: Writer,
    ch: WorldChannels,
    obstacles: Vec<Obstacle>,
    moving: bool,
    next_pose: f64,
    next_scene: f64,
}

impl std::fmt::Debug for Recorder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Recorder")
            .field("writer", &self.w)
            .finish_non_exhaustive()
    }
}

impl Recorder {
    /// Start the recording of a run of `sc` into `out`: the files in `out.dir` (which
    /// must exist), the channels on `out.live`'s context when given.
    pub fn create(out: Outputs<'_>, sc: &Scenario, info: RunInfo) -> Result<Recorder, RecordError> {
        let ctx = match out.live {
            Some(live) => Arc::clone(live.context()),
            None => Context::new(),
        };
        let ch = WorldChannels {
            pose: ctx.channel_builder(topics::POSE).build(),
            obstacles: ctx.channel_builder(topics::OBSTACLES).build(),
        };
        let mounts = Mounts {
            laser: [
                sc.laser.mount_x,
                sc.laser.mount_y,
                sc.laser.mount_yaw_deg.to_radians(),
            ],
            gps: [sc.gps.antenna_x, sc.gps.antenna_y, sc.gps.antenna_z],
        };
        let w = Writer::create(out.dir, ctx, info)?.with_mounts(mounts);
        let obstacles = sc.obstacles.clone();
        let moving = obstacles.iter().any(Obstacle::moves);
        Ok(Recorder {
            w,
            ch,
            obstacles,
            moving,
            next_pose: 0.0,
            next_scene: 0.0,
        })
    }

    /// What the sensors produced at simulated time `t`, as it goes on the wires.
    pub fn sensors(&mut self, t: f64, out: &SensorOutput) {
        if let Some(epoch) = &out.gps {
            self.gps(t, epoch);
        }
        if let Some(frame) = &out.laser {
            self.w.laser(t, frame);
        }
    }

    fn gps(&mut self, t: f64, epoch: &GpsEpoch) {
        self.w.nmea(t, epoch.text.as_bytes());
        self.w.fix(t, &epoch.fix);
    }

    /// One CAN frame seen on the bus at simulated time `t`.
    fn can(&mut self, t: f64, f: &TapFrame) {
        self.w.can(t, f);
    }

    /// The car, the obstacles, and the controller (when in-process) at time `t`.
    fn world(&mut self, t: f64, v: &VehicleState) {
        if t + 1e-9 >= self.next_pose {
            self.next_pose = t + POSE_PERIOD;
            let ns = self.w.ns(t);
            self.w.base_link(t, v.x, v.y, v.theta);
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
        let ns = self.w.ns(t);
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

    /// Close the files (the MCAP with its summary section); what they hold, when files
    /// were written.
    pub fn finish(self) -> Option<RecordSummary> {
        self.w.finish()
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
            self.recorder.w.note_error(format!("the CAN tap: {e}"));
        }
        for f in self.frames.drain(..) {
            self.recorder.can(t, &f);
        }
        self.recorder.world(t, &sim.vehicle);
        if let Some(c) = controller {
            self.recorder.w.controller(t, c);
        }
        self.recorder.w.maybe_flush_at(t);
    }

    /// See [`Recorder::finish`]; the summary also says how many frames the tap lost.
    pub fn finish(mut self) -> Option<RecordSummary> {
        self.recorder.w.summary_mut().can_frames_lost = self.tap.queue_drops();
        self.recorder.finish()
    }
}
