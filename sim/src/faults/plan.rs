//! The fault plan of a scenario: `[[faults]]`, each with a start (a time, or a distance
//! travelled), an optional duration and the parameters of its kind, and `[expect]`,
//! what must follow. Written flat in TOML (one table per fault, its parameters beside
//! `kind`) and turned into typed [`Fault`]s when the scenario is validated, so an
//! unknown key, a parameter of another kind or a value out of range is refused with its
//! file, line and field.

use serde::{Deserialize, Serialize};
use ugv_fields::{FieldError, FieldPath, parse_toml, positive_up_to, read_file, within};

use crate::devices::gps::FixKind;
use crate::scenario::fields::ScenarioError;

/// Most faults in one plan.
pub const MAX_FAULTS: usize = 1_000;

/// The longest a fault may last or be delayed into a run, seconds.
const MAX_TIME_S: f64 = 86_400.0;

/// One `[[faults]]` table as written: the start, the duration, the kind, and every
/// parameter any kind takes (each kind takes its own; others are refused).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FaultSpec {
    pub kind: String,
    /// Start at this simulated time, seconds.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub at_s: Option<f64>,
    /// Start once the car has travelled this far, metres.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub after_m: Option<f64>,
    /// How long it lasts, seconds (absent: to the end of the run).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub duration_s: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub node: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub probability: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub delay_s: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mode: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dlc: Option<u8>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub id: Option<u16>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rate_hz: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fix: Option<FixKind>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub east_m: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub north_m: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bytes: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub from_deg: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub to_deg: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub range_m: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bearing_deg: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radius_m: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub factor: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub deg: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ecu: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub code: Option<String>,
}

/// Where a CAN fault acts.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Node {
    /// What the steering ECU sends.
    Steering,
    /// What the throttle ECU sends.
    Throttle,
    /// Everything the controller sends, as the ECUs receive it.
    Controller,
    /// The controller's heartbeat only, as the ECUs receive it.
    Heartbeat,
}

impl Node {
    fn parse(path: &FieldPath, s: &str) -> Result<Node, FieldError> {
        Ok(match s {
            "steering" => Node::Steering,
            "throttle" => Node::Throttle,
            "controller" => Node::Controller,
            "heartbeat" => Node::Heartbeat,
            _ => {
                return Err(FieldError::new(
                    path.clone(),
                    format!("{s:?} is not a node: steering, throttle, controller or heartbeat"),
                ));
            }
        })
    }

    /// An ECU's own transmissions (the faults that rewrite frames need the sender).
    pub fn is_ecu(self) -> bool {
        matches!(self, Node::Steering | Node::Throttle)
    }
}

/// Which actuator ECU.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum EcuName {
    Steering,
    Throttle,
}

/// What an ECU's own fault is (the DBC's actuator codes).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum EcuFaultCode {
    Overcurrent,
    Sensor,
    Internal,
}

/// A counter fault.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum CounterMode {
    /// The previous frame again, counter and all.
    Repeat,
    /// One counter value left out before each frame.
    Skip,
}

/// A fault, typed.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum FaultKind {
    CanDrop {
        node: Node,
        probability: f64,
    },
    CanSilence {
        node: Node,
    },
    CanDelay {
        node: Node,
        delay_s: f64,
    },
    CanCorruptCrc {
        node: Node,
    },
    CanCounter {
        node: Node,
        mode: CounterMode,
    },
    CanDlc {
        node: Node,
        dlc: u8,
    },
    CanBabble {
        id: u16,
        rate_hz: f64,
    },
    CanBusOff,
    GpsOutage,
    GpsQuality {
        fix: FixKind,
    },
    GpsJump {
        east_m: f64,
        north_m: f64,
    },
    GpsHeadingLost,
    GpsBadChecksum {
        probability: f64,
    },
    GpsGarbage {
        bytes: usize,
    },
    GpsStale,
    GpsBaudMismatch,
    LaserBlackout,
    LaserFrozen,
    LaserNanStorm,
    LaserZeroStorm,
    LaserOccluded {
        from_deg: f64,
        to_deg: f64,
    },
    LaserPhantom {
        range_m: f64,
        bearing_deg: f64,
        radius_m: f64,
    },
    SteeringStuck,
    SteeringRateCut {
        factor: f64,
    },
    SteeringOffset {
        deg: f64,
    },
    ThrottleStuck,
    BrakeWeak {
        factor: f64,
    },
    EcuFault {
        ecu: EcuName,
        code: EcuFaultCode,
    },
    DriverOverride {
        deg: f64,
    },
    ControllerKill,
    ControllerStop,
}

/// When a fault starts.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub enum Start {
    /// At a simulated time, seconds.
    #[serde(rename = "at_s")]
    At(f64),
    /// Once the car's odometer reaches this, metres.
    #[serde(rename = "after_m")]
    After(f64),
}

/// A validated fault of the plan.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Fault {
    #[serde(flatten)]
    pub kind: FaultKind,
    pub start: Start,
    pub duration_s: Option<f64>,
}

impl FaultKind {
    /// The kind's name as written in `kind`.
    pub fn name(&self) -> &'static str {
        match self {
            FaultKind::CanDrop { .. } => "can_drop",
            FaultKind::CanSilence { .. } => "can_silence",
            FaultKind::CanDelay { .. } => "can_delay",
            FaultKind::CanCorruptCrc { .. } => "can_corrupt_crc",
            FaultKind::CanCounter { .. } => "can_counter",
            FaultKind::CanDlc { .. } => "can_dlc",
            FaultKind::CanBabble { .. } => "can_babble",
            FaultKind::CanBusOff => "can_bus_off",
            FaultKind::GpsOutage => "gps_outage",
            FaultKind::GpsQuality { .. } => "gps_quality",
            FaultKind::GpsJump { .. } => "gps_jump",
            FaultKind::GpsHeadingLost => "gps_heading_lost",
            FaultKind::GpsBadChecksum { .. } => "gps_bad_checksum",
            FaultKind::GpsGarbage { .. } => "gps_garbage",
            FaultKind::GpsStale => "gps_stale",
            FaultKind::GpsBaudMismatch => "gps_baud_mismatch",
            FaultKind::LaserBlackout => "laser_blackout",
            FaultKind::LaserFrozen => "laser_frozen",
            FaultKind::LaserNanStorm => "laser_nan_storm",
            FaultKind::LaserZeroStorm => "laser_zero_storm",
            FaultKind::LaserOccluded { .. } => "laser_occluded",
            FaultKind::LaserPhantom { .. } => "laser_phantom",
            FaultKind::SteeringStuck => "steering_stuck",
            FaultKind::SteeringRateCut { .. } => "steering_rate_cut",
            FaultKind::SteeringOffset { .. } => "steering_offset",
            FaultKind::ThrottleStuck => "throttle_stuck",
            FaultKind::BrakeWeak { .. } => "brake_weak",
            FaultKind::EcuFault { .. } => "ecu_fault",
            FaultKind::DriverOverride { .. } => "driver_override",
            FaultKind::ControllerKill => "controller_kill",
            FaultKind::ControllerStop => "controller_stop",
        }
    }
}

/// Each kind: its name, the parameters it takes, and whether it needs a duration
/// (`Some(true)`), refuses one (`Some(false)`) or takes either (`None`).
const KINDS: &[(&str, &[&str], Option<bool>)] = &[
    ("can_drop", &["node", "probability"], None),
    ("can_silence", &["node"], None),
    ("can_delay", &["node", "delay_s"], None),
    ("can_corrupt_crc", &["node"], None),
    ("can_counter", &["node", "mode"], None),
    ("can_dlc", &["node", "dlc"], None),
    ("can_babble", &["id", "rate_hz"], None),
    ("can_bus_off", &[], None),
    ("gps_outage", &[], None),
    ("gps_quality", &["fix"], None),
    ("gps_jump", &["east_m", "north_m"], None),
    ("gps_heading_lost", &[], None),
    ("gps_bad_checksum", &["probability"], None),
    ("gps_garbage", &["bytes"], None),
    ("gps_stale", &[], None),
    ("gps_baud_mismatch", &[], None),
    ("laser_blackout", &[], None),
    ("laser_frozen", &[], None),
    ("laser_nan_storm", &[], None),
    ("laser_zero_storm", &[], None),
    ("laser_occluded", &["from_deg", "to_deg"], None),
    (
        "laser_phantom",
        &["range_m", "bearing_deg", "radius_m"],
        None,
    ),
    ("steering_stuck", &[], None),
    ("steering_rate_cut", &["factor"], None),
    ("steering_offset", &["deg"], None),
    ("throttle_stuck", &[], None),
    ("brake_weak", &["factor"], None),
    ("ecu_fault", &["ecu", "code"], None),
    ("driver_override", &["deg"], None),
    // A killed process does not come back.
    ("controller_kill", &[], Some(false)),
    // SIGSTOP for a while, then SIGCONT.
    ("controller_stop", &[], Some(true)),
];

/// The kinds' names, for messages and documentation.
pub fn kind_names() -> Vec<&'static str> {
    KINDS.iter().map(|k| k.0).collect()
}

impl FaultSpec {
    /// The parameters given, by name.
    fn given(&self) -> Vec<&'static str> {
        let s = self;
        [
            ("node", s.node.is_some()),
            ("probability", s.probability.is_some()),
            ("delay_s", s.delay_s.is_some()),
            ("mode", s.mode.is_some()),
            ("dlc", s.dlc.is_some()),
            ("id", s.id.is_some()),
            ("rate_hz", s.rate_hz.is_some()),
            ("fix", s.fix.is_some()),
            ("east_m", s.east_m.is_some()),
            ("north_m", s.north_m.is_some()),
            ("bytes", s.bytes.is_some()),
            ("from_deg", s.from_deg.is_some()),
            ("to_deg", s.to_deg.is_some()),
            ("range_m", s.range_m.is_some()),
            ("bearing_deg", s.bearing_deg.is_some()),
            ("radius_m", s.radius_m.is_some()),
            ("factor", s.factor.is_some()),
            ("deg", s.deg.is_some()),
            ("ecu", s.ecu.is_some()),
            ("code", s.code.is_some()),
        ]
        .into_iter()
        .filter_map(|(k, set)| set.then_some(k))
        .collect()
    }

    /// The typed fault; `path` is this table's (`faults[i]`).
    pub fn typed(&self, path: &FieldPath) -> Result<Fault, FieldError> {
        let Some(&(name, params, needs_duration)) = KINDS.iter().find(|k| k.0 == self.kind) else {
            return Err(FieldError::new(
                path.key("kind"),
                format!(
                    "{:?} is not a fault kind; the kinds are: {}",
                    self.kind,
                    kind_names().join(", ")
                ),
            ));
        };
        for p in self.given() {
            if !params.contains(&p) {
                return Err(FieldError::new(
                    path.key(p),
                    format!(
                        "{name} takes no {p}{}",
                        if params.is_empty() {
                            " (it takes no parameters)".to_owned()
                        } else {
                            format!(" (its parameters: {})", params.join(", "))
                        }
                    ),
                ));
            }
        }
        let start = match (self.at_s, self.after_m) {
            (Some(t), None) => {
                within(&path.key("at_s"), t, 0.0, MAX_TIME_S, "s")?;
                Start::At(t)
            }
            (None, Some(d)) => {
                within(&path.key("after_m"), d, 0.0, 1_000_000.0, "m")?;
                Start::After(d)
            }
            (Some(_), Some(_)) => {
                return Err(FieldError::new(
                    path.key("after_m"),
                    "give at_s or after_m, not both",
                ));
            }
            (None, None) => {
                return Err(FieldError::new(
                    path.key("at_s"),
                    "missing: a fault starts at a time (at_s) or a distance (after_m)",
                ));
            }
        };
        if let Some(d) = self.duration_s {
            positive_up_to(&path.key("duration_s"), d, MAX_TIME_S, "s")?;
        }
        match (needs_duration, self.duration_s) {
            (Some(true), None) => {
                return Err(FieldError::new(
                    path.key("duration_s"),
                    format!("missing: {name} needs a duration"),
                ));
            }
            (Some(false), Some(_)) => {
                return Err(FieldError::new(
                    path.key("duration_s"),
                    format!("{name} lasts to the end of the run: it takes no duration"),
                ));
            }
            _ => {}
        }
        let kind = self.kind_of(name, path)?;
        Ok(Fault {
            kind,
            start,
            duration_s: self.duration_s,
        })
    }

    fn kind_of(&self, name: &str, path: &FieldPath) -> Result<FaultKind, FieldError> {
        let required = |v: Option<f64>, key: &'static str| {
            v.ok_or_else(|| FieldError::new(path.key(key), format!("missing: {name} needs {key}")))
        };
        let node = || -> Result<Node, FieldError> {
            let s = self.node.as_deref().ok_or_else(|| {
                FieldError::new(path.key("node"), format!("missing: {name} needs node"))
            })?;
            Node::parse(&path.key("node"), s)
        };
        let ecu_node = || -> Result<Node, FieldError> {
            let n = node()?;
            if n.is_ecu() {
                Ok(n)
            } else {
                Err(FieldError::new(
                    path.key("node"),
                    format!(
                        "{name} rewrites the frames an ECU sends: node must be steering or throttle \
                         (the controller's frames reach the ECUs unaltered; drop, delay or silence them instead)"
                    ),
                ))
            }
        };
        let probability = |key: &'static str| -> Result<f64, FieldError> {
            let p = self.probability.unwrap_or(1.0);
            within(&path.key(key), p, 0.0, 1.0, "")?;
            Ok(p)
        };
        let factor = || -> Result<f64, FieldError> {
            let f = required(self.factor, "factor")?;
            within(&path.key("factor"), f, 0.0, 1.0, "")?;
            Ok(f)
        };
        Ok(match name {
            "can_drop" => FaultKind::CanDrop {
                node: node()?,
                probability: probability("probability")?,
            },
            "can_silence" => FaultKind::CanSilence { node: node()? },
            "can_delay" => {
                let d = required(self.delay_s, "delay_s")?;
                positive_up_to(&path.key("delay_s"), d, 10.0, "s")?;
                FaultKind::CanDelay {
                    node: node()?,
                    delay_s: d,
                }
            }
            "can_corrupt_crc" => FaultKind::CanCorruptCrc { node: ecu_node()? },
            "can_counter" => FaultKind::CanCounter {
                node: ecu_node()?,
                mode: match self.mode.as_deref() {
                    Some("repeat") => CounterMode::Repeat,
                    Some("skip") => CounterMode::Skip,
                    Some(m) => {
                        return Err(FieldError::new(
                            path.key("mode"),
                            format!("{m:?} is not a counter fault: repeat or skip"),
                        ));
                    }
                    None => {
                        return Err(FieldError::new(
                            path.key("mode"),
                            "missing: can_counter needs mode (repeat or skip)",
                        ));
                    }
                },
            },
            "can_dlc" => {
                let dlc = self.dlc.ok_or_else(|| {
                    FieldError::new(path.key("dlc"), "missing: can_dlc needs dlc (0 to 7)")
                })?;
                if dlc > 7 {
                    return Err(FieldError::new(
                        path.key("dlc"),
                        format!(
                            "{dlc}: every golf_car.dbc frame is 8 bytes, so a wrong DLC is 0 to 7"
                        ),
                    ));
                }
                FaultKind::CanDlc {
                    node: ecu_node()?,
                    dlc,
                }
            }
            "can_babble" => {
                let id = self.id.unwrap_or(0);
                if id > 0x7ff {
                    return Err(FieldError::new(
                        path.key("id"),
                        format!("{id:#x} is not an 11-bit CAN ID"),
                    ));
                }
                let rate = self.rate_hz.unwrap_or(2_000.0);
                positive_up_to(&path.key("rate_hz"), rate, 20_000.0, "Hz")?;
                FaultKind::CanBabble { id, rate_hz: rate }
            }
            "can_bus_off" => FaultKind::CanBusOff,
            "gps_outage" => FaultKind::GpsOutage,
            "gps_quality" => FaultKind::GpsQuality {
                fix: self.fix.ok_or_else(|| {
                    FieldError::new(
                        path.key("fix"),
                        "missing: gps_quality needs fix (rtk, float, single or none)",
                    )
                })?,
            },
            "gps_jump" => {
                let (e, n) = (
                    required(self.east_m, "east_m")?,
                    required(self.north_m, "north_m")?,
                );
                within(&path.key("east_m"), e, -1_000.0, 1_000.0, "m")?;
                within(&path.key("north_m"), n, -1_000.0, 1_000.0, "m")?;
                FaultKind::GpsJump {
                    east_m: e,
                    north_m: n,
                }
            }
            "gps_heading_lost" => FaultKind::GpsHeadingLost,
            "gps_bad_checksum" => FaultKind::GpsBadChecksum {
                probability: probability("probability")?,
            },
            "gps_garbage" => {
                let bytes = self.bytes.unwrap_or(64);
                if !(1..=4096).contains(&bytes) {
                    return Err(FieldError::new(
                        path.key("bytes"),
                        format!("{bytes}: 1 to 4096 bytes of garbage per epoch"),
                    ));
                }
                FaultKind::GpsGarbage { bytes }
            }
            "gps_stale" => FaultKind::GpsStale,
            "gps_baud_mismatch" => FaultKind::GpsBaudMismatch,
            "laser_blackout" => FaultKind::LaserBlackout,
            "laser_frozen" => FaultKind::LaserFrozen,
            "laser_nan_storm" => FaultKind::LaserNanStorm,
            "laser_zero_storm" => FaultKind::LaserZeroStorm,
            "laser_occluded" => {
                let (a, b) = (
                    required(self.from_deg, "from_deg")?,
                    required(self.to_deg, "to_deg")?,
                );
                within(&path.key("from_deg"), a, -180.0, 180.0, "degrees")?;
                within(&path.key("to_deg"), b, -180.0, 180.0, "degrees")?;
                if b <= a {
                    return Err(FieldError::new(
                        path.key("to_deg"),
                        format!("{b} must be beyond from_deg {a} (counter-clockwise)"),
                    ));
                }
                FaultKind::LaserOccluded {
                    from_deg: a,
                    to_deg: b,
                }
            }
            "laser_phantom" => {
                let r = required(self.range_m, "range_m")?;
                positive_up_to(&path.key("range_m"), r, 200.0, "m")?;
                let b = required(self.bearing_deg, "bearing_deg")?;
                within(&path.key("bearing_deg"), b, -180.0, 180.0, "degrees")?;
                let radius = self.radius_m.unwrap_or(0.5);
                positive_up_to(&path.key("radius_m"), radius, 50.0, "m")?;
                if radius >= r {
                    return Err(FieldError::new(
                        path.key("radius_m"),
                        format!(
                            "{radius} m: the phantom must lie outside the scanner (range_m {r} m)"
                        ),
                    ));
                }
                FaultKind::LaserPhantom {
                    range_m: r,
                    bearing_deg: b,
                    radius_m: radius,
                }
            }
            "steering_stuck" => FaultKind::SteeringStuck,
            "steering_rate_cut" => FaultKind::SteeringRateCut { factor: factor()? },
            "steering_offset" => {
                let d = required(self.deg, "deg")?;
                within(&path.key("deg"), d, -20.0, 20.0, "degrees")?;
                FaultKind::SteeringOffset { deg: d }
            }
            "throttle_stuck" => FaultKind::ThrottleStuck,
            "brake_weak" => FaultKind::BrakeWeak { factor: factor()? },
            "ecu_fault" => FaultKind::EcuFault {
                ecu: match self.ecu.as_deref() {
                    Some("steering") => EcuName::Steering,
                    Some("throttle") => EcuName::Throttle,
                    other => {
                        return Err(FieldError::new(
                            path.key("ecu"),
                            format!("{other:?}: ecu_fault needs ecu, steering or throttle"),
                        ));
                    }
                },
                code: match self.code.as_deref() {
                    Some("overcurrent") => EcuFaultCode::Overcurrent,
                    Some("sensor") => EcuFaultCode::Sensor,
                    Some("internal") => EcuFaultCode::Internal,
                    other => {
                        return Err(FieldError::new(
                            path.key("code"),
                            format!(
                                "{other:?}: ecu_fault needs code, overcurrent, sensor or internal"
                            ),
                        ));
                    }
                },
            },
            "driver_override" => {
                let d = self.deg.unwrap_or(0.0);
                within(&path.key("deg"), d, -45.0, 45.0, "degrees")?;
                FaultKind::DriverOverride { deg: d }
            }
            "controller_kill" => FaultKind::ControllerKill,
            "controller_stop" => FaultKind::ControllerStop,
            // KINDS and this match list the same names (the plan tests build each).
            other => {
                return Err(FieldError::new(
                    path.key("kind"),
                    format!("{other} is listed but has no constructor"),
                ));
            }
        })
    }
}

/// What must follow the faults (`[expect]`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Expectations {
    /// Something (the controller's FAULT_REPORT or estop, an ECU's safe state) reacts
    /// to each fault within this time of its start, seconds.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub detected_within_s: Option<f64>,
    /// Some reaction after each fault's start names exactly this code: a FAULT_REPORT
    /// code of the DBC (`gps_lost`, `estop`, ...; the controller's estop is `estop`)
    /// or the fault an ECU entered its safe state for (`command_timeout`,
    /// `actuator_fault`, ...): one of [`super::inject::reaction_codes`], checked at load.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub detected_by: Option<String>,
    /// Both ECUs report their safe state within this time of each fault's start, s.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub safe_within_s: Option<f64>,
    /// The faults are to be ridden out: neither ECU may enter its safe state.
    pub ecus_stay_enabled: bool,
    /// The schedule overloads the bus: its peak load must exceed the DBC's bit rate
    /// (without this, an overloaded bus fails the run).
    pub bus_overloaded: bool,
}

impl Expectations {
    /// The first expectation about the faults that is set (`bus_overloaded`, about the
    /// schedule, is judged with or without faults), by key.
    fn first_about_faults(&self) -> Option<&'static str> {
        [
            ("detected_within_s", self.detected_within_s.is_some()),
            ("detected_by", self.detected_by.is_some()),
            ("safe_within_s", self.safe_within_s.is_some()),
            ("ecus_stay_enabled", self.ecus_stay_enabled),
        ]
        .into_iter()
        .find_map(|(key, set)| set.then_some(key))
    }

    pub fn validate(&self, path: &FieldPath) -> Result<(), FieldError> {
        if let Some(code) = &self.detected_by {
            let codes = super::inject::reaction_codes();
            if !codes.contains(code.as_str()) {
                return Err(FieldError::new(
                    path.key("detected_by"),
                    format!(
                        "{code:?} is not a reaction code (matched exactly); the codes: {}",
                        codes.into_iter().collect::<Vec<_>>().join(", ")
                    ),
                ));
            }
        }
        if let Some(t) = self.detected_within_s {
            positive_up_to(&path.key("detected_within_s"), t, 600.0, "s")?;
        }
        if let Some(t) = self.safe_within_s {
            positive_up_to(&path.key("safe_within_s"), t, 600.0, "s")?;
        }
        if self.ecus_stay_enabled && self.safe_within_s.is_some() {
            return Err(FieldError::new(
                path.key("ecus_stay_enabled"),
                "contradicts safe_within_s: either the ECUs stay enabled or they go safe",
            ));
        }
        Ok(())
    }
}

/// Validate a scenario's plan: [`validate_parts`], and, when an expectation is about
/// the faults, faults for it to judge (without any it would pass whatever happened).
pub fn validate_plan(faults: &[FaultSpec], expect: &Expectations) -> Result<(), FieldError> {
    validate_parts(faults, expect)?;
    match expect.first_about_faults() {
        Some(key) if faults.is_empty() => Err(FieldError::new(
            FieldPath::of(&["expect"]).key(key),
            "an expectation about faults, and no [[faults]] to judge it by (it could not fail)",
        )),
        _ => Ok(()),
    }
}

/// Every fault typed, at most [`MAX_FAULTS`], the expectations valid.
fn validate_parts(faults: &[FaultSpec], expect: &Expectations) -> Result<(), FieldError> {
    let root = FieldPath::of(&["faults"]);
    if faults.len() > MAX_FAULTS {
        return Err(FieldError::new(
            root,
            format!("{} faults, at most {MAX_FAULTS}", faults.len()),
        ));
    }
    for (i, f) in faults.iter().enumerate() {
        f.typed(&root.index(i))?;
    }
    expect.validate(&FieldPath::of(&["expect"]))
}

/// The typed plan (of a validated scenario: nothing is refused any more).
pub fn typed_plan(faults: &[FaultSpec]) -> Result<Vec<Fault>, FieldError> {
    let root = FieldPath::of(&["faults"]);
    faults
        .iter()
        .enumerate()
        .map(|(i, f)| f.typed(&root.index(i)))
        .collect()
}

/// A fault plan file (`ugv-sim run --faults FILE`): `[[faults]]` and `[expect]`, as in
/// a scenario, added to the scenario's own.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PlanFile {
    pub faults: Vec<FaultSpec>,
    /// Replaces the scenario's `[expect]` when given.
    pub expect: Option<Expectations>,
}

/// Fault plan files load like scenarios (their errors are scenario errors).
impl PlanFile {
    /// Parse and validate TOML text; `file` names it in errors.
    pub fn from_toml(text: &str, file: &str) -> Result<PlanFile, ScenarioError> {
        let plan: PlanFile = parse_toml(text, file)?;
        // Its [expect] may be about the scenario's faults alone: the scenario with the
        // plan is validated as a whole (`Scenario::with_overrides`), which refuses an
        // expectation with no fault at all.
        validate_parts(&plan.faults, &plan.expect.clone().unwrap_or_default())
            .map_err(|e| e.located(text, file))?;
        Ok(plan)
    }

    /// Read a fault plan file (`ugv-sim run --faults FILE`).
    pub fn load(path: &std::path::Path) -> Result<PlanFile, ScenarioError> {
        let text = read_file(path)?;
        PlanFile::from_toml(&text, &path.display().to_string())
    }
}
