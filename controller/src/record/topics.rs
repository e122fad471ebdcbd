//! The recording's MCAP topics (the same names on the live view and in the
//! controller's own recording).

/// `foxglove.LaserScan`, at the scanner's rate; the channel's metadata holds the
/// frame's constant fields (angle_min, angle_increment, time_increment, scan_time,
/// range_min, range_max) as exact f32 text.
pub const LASER: &str = "/laser/scan";
/// `foxglove.LocationFix`, one per GPS epoch.
pub const FIX: &str = "/gps/fix";
/// JSON `{"sentence": "$GPGGA,...*hh"}` (and `wall_unix_ns` in HIL), one per sentence
/// as sent (without its CR LF).
pub const NMEA: &str = "/gps/nmea";
/// `foxglove.FrameTransform` world -> base_link (the rear axle), 50 Hz.
pub const TF: &str = "/tf";
/// `foxglove.PoseInFrame` of the rear axle in the world frame, 50 Hz.
pub const POSE: &str = "/vehicle/pose";
/// `foxglove.SceneUpdate` of the scenario's obstacles where they are.
pub const OBSTACLES: &str = "/world/obstacles";
/// `foxglove.SceneUpdate` with each path the controller planned (SIL's in-process
/// controller, and the controller's own recording).
pub const PLANS: &str = "/controller/plans";
/// JSON `{"id", "extended", "data": hex, "direction": "rx"|"tx"}` (and
/// `wall_unix_ns`, the kernel's receive time, in HIL), one per frame on the bus. The
/// controller's own recording adds `"sent"`: `true` for a frame it sent (`rx`),
/// `false` for one it received (`tx`), a second sender's on its own IDs included.
pub const CAN_RAW: &str = "/can/raw";
/// JSON `{"id", "message", "signals": {name: value}}` per golf_car.dbc, one per frame
/// of a message the DBC defines.
pub const CAN_DECODED: &str = "/can/decoded";
/// JSON state of the controller (SIL's in-process one, and the controller's own
/// recording): mode, estimated pose, obstacles seen.
pub const CONTROLLER_STATE: &str = "/controller/state";
/// JSON `{"taken": n}`: the controller's loop took its n-th replanning from its
/// planning thread at this tick (the controller's own recording, `ugv-controller run
/// --record`), so that a replay takes each at the same tick.
pub const CONTROLLER_PLANNING: &str = "/controller/planning";
/// JSON `{"ticks": n}`: the controller's loop came late and skipped n ticks from this
/// one on (the controller's own recording).
pub const CONTROLLER_SKIPPED: &str = "/controller/skipped";
/// JSON `{"from": t, "entries": n}`: the recorder's queue was full and lost n entries,
/// the first at controller second t, the last at this message's time (the controller's
/// own recording): the recording is whole only before t, and a replay compares up to
/// there.
pub const CONTROLLER_DROPPED: &str = "/controller/dropped";
/// JSON `{"requested": true}`: the controller was asked to stop (a signal) at this
/// tick (the controller's own recording).
pub const CONTROLLER_STOP: &str = "/controller/stop";
