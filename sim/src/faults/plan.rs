//! The fault plan of a scenario, `[[faults]]` and `[expect]` (the format and every kind:
//! docs/faults.md): read flat from TOML ([`FaultSpec`], one table per fault, its
//! parameters beside `kind`) and turned into typed [`Fault`]s when the scenario is
//! validated, so an unknown key, a parameter of another kind or a value out of range is
//! refused with its file, line and field.

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

/// How a kind is built from its table: its parameters checked and typed.
type Build = fn(&KindArgs<'_>) -> Result<FaultKind, FieldError>;

/// Each kind: its name, the parameters it takes, whether it needs a duration
/// (`Some(true)`), refuses one (`Some(false)`) or takes either (`None`), and how it
/// is built.
const KINDS: &[(&str, &[&str], Option<bool>, Build)] = &[
    ("can_drop", &["node", "probability"], None, |a| {
        Ok(FaultKind::CanDrop {
            node: a.node()?,
            probability: a.probability()?,
        })
    }),
    ("can_silence", &["node"], None, |a| {
        Ok(FaultKind::CanSilence { node: a.node()? })
    }),
    ("can_delay", &["node", "delay_s"], None, can_delay),
    ("can_corrupt_crc", &["node"], None, |a| {
        Ok(FaultKind::CanCorruptCrc {
            node: a.ecu_node()?,
        })
    }),
    ("can_counter", &["node", "mode"], None, can_counter),
    ("can_dlc", &["node", "dlc"], None, can_dlc),
    ("can_babble", &["id", "rate_hz"], None, can_babble),
    ("can_bus_off", &[], None, |_| Ok(FaultKind::CanBusOff)),
    ("gps_outage", &[], None, |_| Ok(FaultKind::GpsOutage)),
    ("gps_quality", &["fix"], None, gps_quality),
    ("gps_jump", &["east_m", "north_m"], None, gps_jump),
    ("gps_heading_lost", &[], None, |_| {
        Ok(FaultKind::GpsHeadingLost)
    }),
    ("gps_bad_checksum", &["probability"], None, |a| {
        Ok(FaultKind::GpsBadChecksum {
            probability: a.probability()?,
        })
    }),
    ("gps_garbage", &["bytes"], None, gps_garbage),
    ("gps_stale", &[], None, |_| Ok(FaultKind::GpsStale)),
    ("gps_baud_mismatch", &[], None, |_| {
        Ok(FaultKind::GpsBaudMismatch)
    }),
    ("laser_blackout", &[], None, |_| {
        Ok(FaultKind::LaserBlackout)
    }),
    ("laser_frozen", &[], None, |_| Ok(FaultKind::LaserFrozen)),
    ("laser_nan_storm", &[], None, |_| {
        Ok(FaultKind::LaserNanStorm)
    }),
    ("laser_zero_storm", &[], None, |_| {
        Ok(FaultKind::LaserZeroStorm)
    }),
    (
        "laser_occluded",
        &["from_deg", "to_deg"],
        None,
        laser_occluded,
    ),
    (
        "laser_phantom",
        &["range_m", "bearing_deg", "radius_m"],
        None,
        laser_phantom,
    ),
    ("steering_stuck", &[], None, |_| {
        Ok(FaultKind::SteeringStuck)
    }),
    ("steering_rate_cut", &["factor"], None, |a| {
        Ok(FaultKind::SteeringRateCut {
            factor: a.factor()?,
        })
    }),
    ("steering_offset", &["deg"], None, steering_offset),
    ("throttle_stuck", &[], None, |_| {
        Ok(FaultKind::ThrottleStuck)
    }),
    ("brake_weak", &["factor"], None, |a| {
        Ok(FaultKind::BrakeWeak {
            factor: a.factor()?,
        })
    }),
    ("ecu_fault", &["ecu", "code"], None, ecu_fault),
    ("driver_override", &["deg"], None, driver_override),
    // A killed process does not come back.
    ("controller_kill", &[], Some(false), |_| {
        Ok(FaultKind::ControllerKill)
    }),
    // SIGSTOP for a while, then SIGCONT.
    ("controller_stop", &[], Some(true), |_| {
        Ok(FaultKind::ControllerStop)
    }),
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
        let Some(&(name, params, needs_duration, build)) = KINDS.iter().find(|k| k.0 == self.kind)
        else {
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
        let kind = build(&KindArgs {
            spec: self,
            name,
            path,
        })?;
        Ok(Fault {
            kind,
            start,
            duration_s: self.duration_s,
        })
    }
}

/// What a kind is built from: its table, its name and the table's path.
struct KindArgs<'a> {
    spec: &'a FaultSpec,
    name: &'a str,
    path: &'a FieldPath,
}

impl KindArgs<'_> {
    /// A parameter the kind cannot do without.
    fn required(&self, v: Option<f64>, key: &'static str) -> Result<f64, FieldError> {
        v.ok_or_else(|| {
            FieldError::new(
                self.path.key(key),
                format!("missing: {} needs {key}", self.name),
            )
        })
    }

    /// The node the kind acts on.
    fn node(&self) -> Result<Node, FieldError> {
        let s = self.spec.node.as_deref().ok_or_else(|| {
            FieldError::new(
                self.path.key("node"),
                format!("missing: {} needs node", self.name),
            )
        })?;
        Node::parse(&self.path.key("node"), s)
    }

    /// The node, which must be an ECU (the kind rewrites the frames it sends).
    fn ecu_node(&self) -> Result<Node, FieldError> {
        let n = self.node()?;
        if n.is_ecu() {
            Ok(n)
        } else {
            Err(FieldError::new(
                self.path.key("node"),
                format!(
                    "{} rewrites the frames an ECU sends: node must be steering or throttle \
                     (the controller's frames reach the ECUs unaltered; drop, delay or silence them instead)",
                    self.name
                ),
            ))
        }
    }

    /// `probability`, 1 when not given.
    fn probability(&self) -> Result<f64, FieldError> {
        let p = self.spec.probability.unwrap_or(1.0);
        within(&self.path.key("probability"), p, 0.0, 1.0, "")?;
        Ok(p)
    }

    /// `factor`, required, 0 to 1.
    fn factor(&self) -> Result<f64, FieldError> {
        let f = self.required(self.spec.factor, "factor")?;
        within(&self.path.key("factor"), f, 0.0, 1.0, "")?;
        Ok(f)
    }
}

fn can_delay(a: &KindArgs<'_>) -> Result<FaultKind, FieldError> {
    let d = a.required(a.spec.delay_s, "delay_s")?;
    positive_up_to(&a.path.key("delay_s"), d, 10.0, "s")?;
    Ok(FaultKind::CanDelay {
        node: a.node()?,
        delay_s: d,
    })
}

fn can_counter(a: &KindArgs<'_>) -> Result<FaultKind, FieldError> {
    let node = a.ecu_node()?;
    let mode = match a.spec.mode.as_deref() {
        Some("repeat") => CounterMode::Repeat,
        Some("skip") => CounterMode::Skip,
        Some(m) => {
            return Err(FieldError::new(
                a.path.key("mode"),
                format!("{m:?} is not a counter fault: repeat or skip"),
            ));
        }
        None => {
            return Err(FieldError::new(
                a.path.key("mode"),
                "missing: can_counter needs mode (repeat or skip)",
            ));
        }
    };
    Ok(FaultKind::CanCounter { node, mode })
}

fn can_dlc(a: &KindArgs<'_>) -> Result<FaultKind, FieldError> {
    let dlc = a
        .spec
        .dlc
        .ok_or_else(|| FieldError::new(a.path.key("dlc"), "missing: can_dlc needs dlc (0 to 7)"))?;
    if dlc > 7 {
        return Err(FieldError::new(
            a.path.key("dlc"),
            format!("{dlc}: every golf_car.dbc frame is 8 bytes, so a wrong DLC is 0 to 7"),
        ));
    }
    Ok(FaultKind::CanDlc {
        node: a.ecu_node()?,
        dlc,
    })
}

fn can_babble(a: &KindArgs<'_>) -> Result<FaultKind, FieldError> {
    let id = a.spec.id.unwrap_or(0);
    if id > 0x7ff {
        return Err(FieldError::new(
            a.path.key("id"),
            format!("{id:#x} is not an 11-bit CAN ID"),
        ));
    }
    let rate = a.spec.rate_hz.unwrap_or(2_000.0);
    positive_up_to(&a.path.key("rate_hz"), rate, 20_000.0, "Hz")?;
    Ok(FaultKind::CanBabble { id, rate_hz: rate })
}

fn gps_quality(a: &KindArgs<'_>) -> Result<FaultKind, FieldError> {
    let fix = a.spec.fix.ok_or_else(|| {
        FieldError::new(
            a.path.key("fix"),
            "missing: gps_quality needs fix (rtk, float, single or none)",
        )
    })?;
    Ok(FaultKind::GpsQuality { fix })
}

fn gps_jump(a: &KindArgs<'_>) -> Result<FaultKind, FieldError> {
    let (e, n) = (
        a.required(a.spec.east_m, "east_m")?,
        a.required(a.spec.north_m, "north_m")?,
    );
    within(&a.path.key("east_m"), e, -1_000.0, 1_000.0, "m")?;
    within(&a.path.key("north_m"), n, -1_000.0, 1_000.0, "m")?;
    Ok(FaultKind::GpsJump {
        east_m: e,
        north_m: n,
    })
}

fn gps_garbage(a: &KindArgs<'_>) -> Result<FaultKind, FieldError> {
    let bytes = a.spec.bytes.unwrap_or(64);
    if !(1..=4096).contains(&bytes) {
        return Err(FieldError::new(
            a.path.key("bytes"),
            format!("{bytes}: 1 to 4096 bytes of garbage per epoch"),
        ));
    }
    Ok(FaultKind::GpsGarbage { bytes })
}

fn laser_occluded(a: &KindArgs<'_>) -> Result<FaultKind, FieldError> {
    let (from, to) = (
        a.required(a.spec.from_deg, "from_deg")?,
        a.required(a.spec.to_deg, "to_deg")?,
    );
    within(&a.path.key("from_deg"), from, -180.0, 180.0, "degrees")?;
    within(&a.path.key("to_deg"), to, -180.0, 180.0, "degrees")?;
    if to <= from {
        return Err(FieldError::new(
            a.path.key("to_deg"),
            format!("{to} must be beyond from_deg {from} (counter-clockwise)"),
        ));
    }
    Ok(FaultKind::LaserOccluded {
        from_deg: from,
        to_deg: to,
    })
}

fn laser_phantom(a: &KindArgs<'_>) -> Result<FaultKind, FieldError> {
    let r = a.required(a.spec.range_m, "range_m")?;
    positive_up_to(&a.path.key("range_m"), r, 200.0, "m")?;
    let b = a.required(a.spec.bearing_deg, "bearing_deg")?;
    within(&a.path.key("bearing_deg"), b, -180.0, 180.0, "degrees")?;
    let radius = a.spec.radius_m.unwrap_or(0.5);
    positive_up_to(&a.path.key("radius_m"), radius, 50.0, "m")?;
    if radius >= r {
        return Err(FieldError::new(
            a.path.key("radius_m"),
            format!("{radius} m: the phantom must lie outside the scanner (range_m {r} m)"),
        ));
    }
    Ok(FaultKind::LaserPhantom {
        range_m: r,
        bearing_deg: b,
        radius_m: radius,
    })
}

fn steering_offset(a: &KindArgs<'_>) -> Result<FaultKind, FieldError> {
    let d = a.required(a.spec.deg, "deg")?;
    within(&a.path.key("deg"), d, -20.0, 20.0, "degrees")?;
    Ok(FaultKind::SteeringOffset { deg: d })
}

fn ecu_fault(a: &KindArgs<'_>) -> Result<FaultKind, FieldError> {
    let ecu = match a.spec.ecu.as_deref() {
        Some("steering") => EcuName::Steering,
        Some("throttle") => EcuName::Throttle,
        other => {
            return Err(FieldError::new(
                a.path.key("ecu"),
                format!("{other:?}: ecu_fault needs ecu, steering or throttle"),
            ));
        }
    };
    let code = match a.spec.code.as_deref() {
        Some("overcurrent") => EcuFaultCode::Overcurrent,
        Some("sensor") => EcuFaultCode::Sensor,
        Some("internal") => EcuFaultCode::Internal,
        other => {
            return Err(FieldError::new(
                a.path.key("code"),
                format!("{other:?}: ecu_fault needs code, overcurrent, sensor or internal"),
            ));
        }
    };
    Ok(FaultKind::EcuFault { ecu, code })
}

fn driver_override(a: &KindArgs<'_>) -> Result<FaultKind, FieldError> {
    let d = a.spec.deg.unwrap_or(0.0);
    within(&a.path.key("deg"), d, -45.0, 45.0, "degrees")?;
    Ok(FaultKind::DriverOverride { deg: d })
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
