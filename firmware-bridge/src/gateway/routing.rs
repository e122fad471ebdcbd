//! The routing table: which frames cross the gateway, read from the DBC.
//!
//! Every node of the network lives on one side: the ones the user names are
//! physical, the others simulated. A frame read on one side crosses to the other iff
//! its sender lives on the side it was read from and at least one of its receivers
//! (the union of its signals' receivers) lives on the other side. A message with
//! several senders (FAULT_REPORT) names its sender in a `Source` signal whose value
//! table labels the nodes; the gateway decodes that signal and nothing else: E2E
//! (counter, CRC) is the endpoints' business, bytes cross verbatim.

use std::collections::BTreeSet;
use std::fmt;

use golf_car_can::spec::FRAME_LEN;
use golf_car_can::{NetworkSpec, Payload, SignalSpec};

use super::GatewayError;

/// Name of the signal that says which node sent a message with several senders.
pub const SOURCE_SIGNAL: &str = "Source";

/// Raw `can_id` flag of a 29-bit ID (linux/can.h).
pub const CAN_EFF_FLAG: u32 = 0x8000_0000;
/// Raw `can_id` flag of a remote transmission request.
pub const CAN_RTR_FLAG: u32 = 0x4000_0000;
/// Raw `can_id` flag of an error frame.
pub const CAN_ERR_FLAG: u32 = 0x2000_0000;
/// Mask of an 11-bit ID.
pub const CAN_SFF_MASK: u32 = 0x7FF;
/// Mask of a 29-bit ID.
pub const CAN_EFF_MASK: u32 = 0x1FFF_FFFF;

/// One of the gateway's two buses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Side {
    /// The simulator's bus (vcan0).
    Sim,
    /// The physical bus (can0, a USB adapter).
    Physical,
}

impl Side {
    /// The other bus.
    pub fn other(self) -> Side {
        match self {
            Side::Sim => Side::Physical,
            Side::Physical => Side::Sim,
        }
    }
}

impl fmt::Display for Side {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Side::Sim => "sim",
            Side::Physical => "physical",
        })
    }
}

/// Why a frame stays on the bus it was read from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum LocalReason {
    /// An ID the DBC does not define (29-bit IDs included).
    UnknownId,
    /// Its sender lives on the other side: an echo of a frame that came from there, or
    /// a node that is simulated although it is declared physical (or the reverse).
    SenderOnOtherSide,
    /// Sender and all receivers live on the side it was read from.
    NoReceiverAcross,
    /// Malformed: a data length other than 8 bytes.
    WrongDlc,
    /// Malformed: a remote transmission request (the golf car bus uses none).
    Remote,
    /// Malformed: an error frame (the bus's own state, never forwarded).
    ErrorFrame,
    /// Malformed: a message with several senders whose `Source` signal names none of them.
    UnknownSource,
}

impl LocalReason {
    /// Every reason, in the order the stats list them.
    pub const ALL: [LocalReason; 7] = [
        LocalReason::UnknownId,
        LocalReason::SenderOnOtherSide,
        LocalReason::NoReceiverAcross,
        LocalReason::WrongDlc,
        LocalReason::Remote,
        LocalReason::ErrorFrame,
        LocalReason::UnknownSource,
    ];
}

/// What the gateway does with a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    /// Send it, byte for byte, on the other side; `message` indexes
    /// [`RoutingTable::messages`].
    Forward { message: usize },
    /// Keep it where it is; `message` is the DBC message when the ID is known.
    Local {
        reason: LocalReason,
        message: Option<usize>,
    },
}

/// Who sends a message.
#[derive(Debug, Clone)]
enum Sender {
    /// One node.
    Fixed(Side),
    /// Several nodes, told apart by the `Source` signal: raw value -> side.
    BySource {
        signal: Box<SignalSpec>,
        sides: Vec<(i128, Side)>,
    },
    /// Several nodes and no `Source` signal: any sender on the read side counts.
    Any { sim: bool, physical: bool },
}

/// The route of one DBC message.
#[derive(Debug, Clone)]
pub struct MessageRoute {
    /// The 11-bit ID.
    pub id: u16,
    /// The DBC name.
    pub name: String,
    /// The sender nodes, as the DBC lists them.
    pub senders: Vec<String>,
    /// The union of the signals' receivers.
    pub receivers: Vec<String>,
    sender: Sender,
    receivers_sim: bool,
    receivers_physical: bool,
}

impl MessageRoute {
    /// Whether a receiver of this message lives on `side`.
    fn received_on(&self, side: Side) -> bool {
        match side {
            Side::Sim => self.receivers_sim,
            Side::Physical => self.receivers_physical,
        }
    }
}

/// The routing table of a network for one assignment of nodes to sides.
#[derive(Debug, Clone)]
pub struct RoutingTable {
    messages: Vec<MessageRoute>,
    /// 11-bit ID -> index into `messages`.
    by_id: Vec<Option<usize>>,
    physical_nodes: Vec<String>,
    sim_nodes: Vec<String>,
}

impl RoutingTable {
    /// Build the table of `network` with `physical_nodes` on the physical side and every
    /// other node on the simulated one. Node names are matched case-insensitively and
    /// must be nodes of the network; none at all is refused (nothing would cross).
    pub fn new(network: &NetworkSpec, physical_nodes: &[String]) -> Result<Self, GatewayError> {
        if physical_nodes.is_empty() {
            return Err(GatewayError::NoPhysicalNode {
                valid: valid_nodes(network),
            });
        }
        let mut physical = BTreeSet::new();
        for node in physical_nodes {
            let known = network
                .nodes
                .iter()
                .find(|n| n.eq_ignore_ascii_case(node.trim()))
                .ok_or_else(|| GatewayError::UnknownNode {
                    node: node.clone(),
                    valid: valid_nodes(network),
                })?;
            physical.insert(known.to_string());
        }
        let side_of = |node: &str| {
            if physical.contains(node) {
                Side::Physical
            } else {
                Side::Sim
            }
        };
        let mut messages = Vec::with_capacity(network.messages.len());
        let mut by_id = vec![None; (CAN_SFF_MASK + 1) as usize];
        for m in network.messages.iter() {
            let senders: Vec<String> = m.senders.iter().map(|s| s.to_string()).collect();
            let mut receivers: Vec<String> = Vec::new();
            for s in m.signals.iter() {
                for r in s.receivers.iter() {
                    if !receivers.iter().any(|x| x == r.as_ref()) {
                        receivers.push(r.to_string());
                    }
                }
            }
            let sender = match senders.as_slice() {
                [] => Sender::Any {
                    sim: false,
                    physical: false,
                },
                [one] => Sender::Fixed(side_of(one)),
                several => match m.signal(SOURCE_SIGNAL) {
                    Some(signal) => Sender::BySource {
                        sides: signal
                            .values
                            .iter()
                            .filter_map(|v| {
                                several
                                    .iter()
                                    .find(|n| n.eq_ignore_ascii_case(&v.label))
                                    .map(|n| (i128::from(v.raw), side_of(n)))
                            })
                            .collect(),
                        signal: Box::new(signal.clone()),
                    },
                    None => Sender::Any {
                        sim: several.iter().any(|n| side_of(n) == Side::Sim),
                        physical: several.iter().any(|n| side_of(n) == Side::Physical),
                    },
                },
            };
            let route = MessageRoute {
                id: m.id,
                name: m.name.to_string(),
                receivers_sim: receivers.iter().any(|r| side_of(r) == Side::Sim),
                receivers_physical: receivers.iter().any(|r| side_of(r) == Side::Physical),
                senders,
                receivers,
                sender,
            };
            if let Some(slot) = by_id.get_mut(usize::from(m.id)) {
                *slot = Some(messages.len());
            }
            messages.push(route);
        }
        let sim_nodes = network
            .nodes
            .iter()
            .filter(|n| !physical.contains(n.as_ref()))
            .map(|n| n.to_string())
            .collect();
        Ok(RoutingTable {
            messages,
            by_id,
            physical_nodes: physical.into_iter().collect(),
            sim_nodes,
        })
    }

    /// The messages of the network, in DBC order (indexed by [`Verdict`]).
    pub fn messages(&self) -> &[MessageRoute] {
        &self.messages
    }

    /// The nodes on the physical side (DBC spelling).
    pub fn physical_nodes(&self) -> &[String] {
        &self.physical_nodes
    }

    /// The nodes on the simulated side (DBC spelling).
    pub fn sim_nodes(&self) -> &[String] {
        &self.sim_nodes
    }

    /// What to do with a frame read on `from`: `can_id` is the kernel's raw `can_id`
    /// (with the EFF/RTR/ERR flags), `data` the frame's data bytes (its length is the DLC).
    pub fn route(&self, from: Side, can_id: u32, data: &[u8]) -> Verdict {
        let local = |reason, message| Verdict::Local { reason, message };
        if can_id & CAN_ERR_FLAG != 0 {
            return local(LocalReason::ErrorFrame, None);
        }
        let message = if can_id & CAN_EFF_FLAG != 0 {
            None
        } else {
            self.by_id
                .get((can_id & CAN_SFF_MASK) as usize)
                .copied()
                .flatten()
        };
        if can_id & CAN_RTR_FLAG != 0 {
            return local(LocalReason::Remote, message);
        }
        let Some(index) = message else {
            return local(LocalReason::UnknownId, None);
        };
        let Some(route) = self.messages.get(index) else {
            return local(LocalReason::UnknownId, None);
        };
        let Ok(payload) = Payload::try_from(data) else {
            return local(LocalReason::WrongDlc, message);
        };
        debug_assert_eq!(payload.len(), FRAME_LEN);
        let sent_from_here = match &route.sender {
            Sender::Fixed(side) => *side == from,
            Sender::BySource { signal, sides } => {
                let raw = signal.get_raw(&payload);
                match sides.iter().find(|(r, _)| *r == raw) {
                    Some((_, side)) => *side == from,
                    None => return local(LocalReason::UnknownSource, message),
                }
            }
            Sender::Any { sim, physical } => match from {
                Side::Sim => *sim,
                Side::Physical => *physical,
            },
        };
        if !sent_from_here {
            return local(LocalReason::SenderOnOtherSide, message);
        }
        if !route.received_on(from.other()) {
            return local(LocalReason::NoReceiverAcross, message);
        }
        Verdict::Forward { message: index }
    }

    /// One line per message saying where it goes, for people: `STEERING_CMD 0x100:
    /// sim -> physical`.
    pub fn describe(&self) -> Vec<String> {
        self.messages
            .iter()
            .map(|m| {
                let across = |from: Side| -> Option<&'static str> {
                    let sent = match &m.sender {
                        Sender::Fixed(side) => *side == from,
                        Sender::BySource { sides, .. } => sides.iter().any(|(_, s)| *s == from),
                        Sender::Any { sim, physical } => match from {
                            Side::Sim => *sim,
                            Side::Physical => *physical,
                        },
                    };
                    (sent && m.received_on(from.other())).then_some(match from {
                        Side::Sim => "sim -> physical",
                        Side::Physical => "physical -> sim",
                    })
                };
                let dirs: Vec<&str> = [Side::Sim, Side::Physical]
                    .into_iter()
                    .filter_map(across)
                    .collect();
                let by_source = if matches!(m.sender, Sender::BySource { .. }) {
                    format!(" (by its {SOURCE_SIGNAL} signal)")
                } else {
                    String::new()
                };
                format!(
                    "{} {:#05x}: {}{}",
                    m.name,
                    m.id,
                    if dirs.is_empty() {
                        "local".to_owned()
                    } else {
                        dirs.join(", ")
                    },
                    if dirs.is_empty() { "" } else { &by_source }
                )
            })
            .collect()
    }
}

fn valid_nodes(network: &NetworkSpec) -> String {
    network
        .nodes
        .iter()
        .map(|n| n.as_ref())
        .collect::<Vec<_>>()
        .join(", ")
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

    use super::*;
    use golf_car_can::NETWORK;

    const NODES: [&str; 3] = ["CONTROLLER", "STEERING_ECU", "THROTTLE_ECU"];

    /// The contract written out by hand (DESIGN.md's table), independent of the DBC
    /// parser: ID, name, senders, receivers.
    const CONTRACT: [(u16, &str, &[&str], &[&str]); 6] = [
        (
            0x080,
            "CONTROLLER_HEARTBEAT",
            &["CONTROLLER"],
            &["STEERING_ECU", "THROTTLE_ECU"],
        ),
        (0x100, "STEERING_CMD", &["CONTROLLER"], &["STEERING_ECU"]),
        (0x101, "STEERING_REPORT", &["STEERING_ECU"], &["CONTROLLER"]),
        (0x110, "THROTTLE_CMD", &["CONTROLLER"], &["THROTTLE_ECU"]),
        (0x111, "THROTTLE_REPORT", &["THROTTLE_ECU"], &["CONTROLLER"]),
        (0x0F0, "FAULT_REPORT", &NODES, &NODES),
    ];

    /// FAULT_REPORT's Source values (VAL_ 240 Source).
    const SOURCES: [(u8, &str); 3] = [(1, "CONTROLLER"), (2, "STEERING_ECU"), (3, "THROTTLE_ECU")];

    fn table(physical: &[&str]) -> RoutingTable {
        let nodes: Vec<String> = physical.iter().map(|s| (*s).to_owned()).collect();
        RoutingTable::new(&NETWORK, &nodes).unwrap()
    }

    /// Every non-empty subset of the nodes.
    fn assignments() -> Vec<Vec<&'static str>> {
        (1u8..8)
            .map(|mask| {
                NODES
                    .iter()
                    .enumerate()
                    .filter(|(i, _)| mask >> i & 1 == 1)
                    .map(|(_, n)| *n)
                    .collect()
            })
            .collect()
    }

    fn expected(
        physical: &[&str],
        from: Side,
        sender: &str,
        receivers: &[&str],
    ) -> Option<LocalReason> {
        let side = |n: &str| {
            if physical.contains(&n) {
                Side::Physical
            } else {
                Side::Sim
            }
        };
        if side(sender) != from {
            Some(LocalReason::SenderOnOtherSide)
        } else if !receivers.iter().any(|r| side(r) == from.other()) {
            Some(LocalReason::NoReceiverAcross)
        } else {
            None
        }
    }

    fn check(
        t: &RoutingTable,
        from: Side,
        id: u16,
        data: &[u8],
        want: Option<LocalReason>,
        what: &str,
    ) {
        let got = t.route(from, u32::from(id), data);
        match (got, want) {
            (Verdict::Forward { message }, None) => {
                assert_eq!(t.messages()[message].id, id, "{what}")
            }
            (Verdict::Local { reason, message }, Some(w)) => {
                assert_eq!(reason, w, "{what}");
                assert_eq!(message.map(|m| t.messages()[m].id), Some(id), "{what}");
            }
            (got, want) => panic!("{what}: got {got:?}, expected {want:?}"),
        }
    }

    #[test]
    fn the_dbc_matches_the_contract_written_by_hand() {
        let t = table(&["STEERING_ECU"]);
        assert_eq!(t.messages().len(), CONTRACT.len());
        for (id, name, senders, receivers) in CONTRACT {
            let m = t.messages().iter().find(|m| m.id == id).unwrap();
            assert_eq!(m.name, name);
            assert_eq!(m.senders, senders, "{name}");
            let mut got = m.receivers.clone();
            got.sort();
            assert_eq!(got, receivers, "{name}");
        }
    }

    #[test]
    fn every_message_every_assignment_both_sides() {
        for physical in assignments() {
            let t = table(&physical);
            for from in [Side::Sim, Side::Physical] {
                for (id, name, senders, receivers) in CONTRACT {
                    if senders.len() == 1 {
                        let data = [0x5A; 8];
                        let want = expected(&physical, from, senders[0], receivers);
                        check(
                            &t,
                            from,
                            id,
                            &data,
                            want,
                            &format!("{name} from {from} with {physical:?} physical"),
                        );
                    } else {
                        for (raw, sender) in SOURCES {
                            // Everything but the Source nibble is noise: only Source counts.
                            let data = [0xF0 | raw, 0xAA, 0x55, 0xFF, 0x00, 0x12, 0x0F, 0xEE];
                            let want = expected(&physical, from, sender, receivers);
                            check(
                                &t,
                                from,
                                id,
                                &data,
                                want,
                                &format!(
                                    "{name} Source={sender} from {from} with {physical:?} physical"
                                ),
                            );
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn steering_ecu_physical_spelled_out() {
        let t = table(&["steering_ecu"]);
        assert_eq!(t.physical_nodes(), ["STEERING_ECU"]);
        assert_eq!(t.sim_nodes(), ["CONTROLLER", "THROTTLE_ECU"]);
        let d = [0u8; 8];
        let fwd = |from, id| matches!(t.route(from, id, &d), Verdict::Forward { .. });
        assert!(fwd(Side::Sim, 0x100)); // STEERING_CMD out
        assert!(fwd(Side::Sim, 0x080)); // heartbeat out
        assert!(fwd(Side::Physical, 0x101)); // STEERING_REPORT in
        assert!(!fwd(Side::Sim, 0x101)); // a report on the sim side: not out
        assert!(!fwd(Side::Sim, 0x110) && !fwd(Side::Sim, 0x111)); // throttle stays
        assert!(!fwd(Side::Physical, 0x100)); // a command back from outside: no
        let fault = |src: u8| [src, 1, 0, 0, 0, 0, 0, 0];
        assert!(matches!(
            t.route(Side::Physical, 0xF0, &fault(2)),
            Verdict::Forward { .. }
        ));
        assert!(matches!(
            t.route(Side::Sim, 0xF0, &fault(1)),
            Verdict::Forward { .. }
        ));
        assert!(matches!(
            t.route(Side::Sim, 0xF0, &fault(3)),
            Verdict::Forward { .. }
        ));
        assert!(matches!(
            t.route(Side::Sim, 0xF0, &fault(2)),
            Verdict::Local {
                reason: LocalReason::SenderOnOtherSide,
                ..
            }
        ));
    }

    #[test]
    fn controller_physical_spelled_out() {
        let t = table(&["CONTROLLER"]);
        let d = [0u8; 8];
        let fwd = |from, id| matches!(t.route(from, id, &d), Verdict::Forward { .. });
        for id in [0x080, 0x100, 0x110] {
            assert!(fwd(Side::Physical, id) && !fwd(Side::Sim, id), "{id:#x}");
        }
        for id in [0x101, 0x111] {
            assert!(fwd(Side::Sim, id) && !fwd(Side::Physical, id), "{id:#x}");
        }
    }

    #[test]
    fn all_nodes_physical_nothing_crosses() {
        let t = table(&NODES);
        for m in t.messages() {
            for from in [Side::Sim, Side::Physical] {
                for src in 1..=3u8 {
                    let v = t.route(from, u32::from(m.id), &[src, 0, 0, 0, 0, 0, 0, 0]);
                    assert!(
                        matches!(v, Verdict::Local { .. }),
                        "{} from {from}: {v:?}",
                        m.name
                    );
                }
            }
        }
        assert!(t.describe().iter().all(|l| l.ends_with("local")));
    }

    #[test]
    fn malformed_and_unknown_frames_stay_local() {
        let t = table(&["STEERING_ECU"]);
        let reason = |from, id, data: &[u8]| match t.route(from, id, data) {
            Verdict::Local { reason, .. } => reason,
            v => panic!("{id:#x}: {v:?}"),
        };
        let d = [0u8; 8];
        assert_eq!(reason(Side::Sim, 0x555, &d), LocalReason::UnknownId);
        assert_eq!(
            reason(Side::Sim, 0x100 | CAN_EFF_FLAG, &d),
            LocalReason::UnknownId
        );
        assert_eq!(reason(Side::Sim, 0x100, &d[..4]), LocalReason::WrongDlc);
        assert_eq!(reason(Side::Sim, 0x100, &[]), LocalReason::WrongDlc);
        assert_eq!(
            reason(Side::Sim, 0x100 | CAN_RTR_FLAG, &[]),
            LocalReason::Remote
        );
        assert_eq!(
            reason(Side::Physical, CAN_ERR_FLAG | 0x40, &d),
            LocalReason::ErrorFrame
        );
        // Source 0 and 4..15 name no node.
        for src in [0u8, 4, 15] {
            assert_eq!(
                reason(Side::Sim, 0xF0, &[src, 0, 0, 0, 0, 0, 0, 0]),
                LocalReason::UnknownSource
            );
        }
        // E2E is not checked: a frame with a wrong CRC and counter still crosses.
        assert!(matches!(
            t.route(Side::Sim, 0x100, &[0xFF; 8]),
            Verdict::Forward { .. }
        ));
    }

    #[test]
    fn node_names_are_checked() {
        let err = RoutingTable::new(&NETWORK, &["BRAKE_ECU".to_owned()]).unwrap_err();
        let text = err.to_string();
        assert!(
            text.contains("BRAKE_ECU") && text.contains("CONTROLLER, STEERING_ECU, THROTTLE_ECU"),
            "{text}"
        );
        let err = RoutingTable::new(&NETWORK, &[]).unwrap_err();
        assert!(matches!(err, GatewayError::NoPhysicalNode { .. }), "{err}");
    }

    #[test]
    fn describe_names_each_direction() {
        let lines = table(&["STEERING_ECU"]).describe();
        assert!(
            lines.contains(&"STEERING_CMD 0x100: sim -> physical".to_owned()),
            "{lines:?}"
        );
        assert!(
            lines.contains(&"STEERING_REPORT 0x101: physical -> sim".to_owned()),
            "{lines:?}"
        );
        assert!(
            lines.contains(&"THROTTLE_CMD 0x110: local".to_owned()),
            "{lines:?}"
        );
        assert!(
            lines.contains(
                &"FAULT_REPORT 0x0f0: sim -> physical, physical -> sim (by its Source signal)"
                    .to_owned()
            ),
            "{lines:?}"
        );
    }
}
