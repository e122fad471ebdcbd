//! The CAN network as data: messages, signals, value tables and timing, read from a
//! DBC file and checked against the golf car's contract (DESIGN.md).
//!
//! This file is shared with the build script (`#[path]`), which turns the checked
//! specification of `golf_car.dbc` into Rust; the library uses the same types for the
//! generated tables and for a DBC loaded at run time (`ugv-can --dbc`). `Cow` lets one
//! type serve both: borrowed `'static` data in the generated tables, owned data when
//! loaded.

use std::borrow::Cow;

/// Name of the E2E rolling-counter signal every message carries.
pub const COUNTER_SIGNAL: &str = "Counter";
/// Name of the E2E CRC signal every message carries.
pub const CRC_SIGNAL: &str = "Crc";
/// Start bit and size of the counter (byte 6, low nibble).
pub const COUNTER_LAYOUT: (u16, u8) = (48, 4);
/// Start bit and size of the CRC (byte 7).
pub const CRC_LAYOUT: (u16, u8) = (56, 8);
/// Every frame on the bus is eight bytes long.
pub const FRAME_LEN: usize = 8;

/// Bit numbering of a signal.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ByteOrder {
    /// Little endian (`@1` in DBC): the start bit is the least significant bit.
    Intel,
    /// Big endian (`@0` in DBC): the start bit is the most significant bit, in the
    /// DBC's sawtooth numbering.
    Motorola,
}

/// One value-table entry: raw value and its label.
#[derive(Clone, Debug, PartialEq)]
pub struct ValueLabel {
    pub raw: i64,
    pub label: Cow<'static, str>,
}

/// One signal of a message.
#[derive(Clone, Debug, PartialEq)]
pub struct SignalSpec {
    pub name: Cow<'static, str>,
    pub start_bit: u16,
    pub size: u8,
    pub byte_order: ByteOrder,
    pub signed: bool,
    pub factor: f64,
    pub offset: f64,
    pub min: f64,
    pub max: f64,
    pub unit: Cow<'static, str>,
    pub receivers: Cow<'static, [Cow<'static, str>]>,
    pub values: Cow<'static, [ValueLabel]>,
    pub comment: Cow<'static, str>,
}

/// One message of the network.
#[derive(Clone, Debug, PartialEq)]
pub struct MessageSpec {
    pub id: u16,
    pub name: Cow<'static, str>,
    /// Nodes that may send it (`BO_` transmitter plus `BO_TX_BU_`).
    pub senders: Cow<'static, [Cow<'static, str>]>,
    /// `GenMsgCycleTime`, in milliseconds.
    pub cycle_time_ms: Option<u32>,
    /// `GenMsgTimeoutTime`: how long a receiver waits before its safe state.
    pub timeout_ms: Option<u32>,
    pub signals: Cow<'static, [SignalSpec]>,
    pub comment: Cow<'static, str>,
}

/// The whole network.
#[derive(Clone, Debug, PartialEq)]
pub struct NetworkSpec {
    pub name: Cow<'static, str>,
    pub baudrate: u32,
    pub nodes: Cow<'static, [Cow<'static, str>]>,
    pub messages: Cow<'static, [MessageSpec]>,
}

/// Why a DBC was refused.
#[derive(Debug, thiserror::Error)]
pub enum SpecError {
    #[error("DBC syntax error: {0}")]
    Syntax(String),
    #[error("message {message}: extended (29-bit) ID {id:#x}; the golf car bus uses 11-bit IDs")]
    ExtendedId { message: String, id: u32 },
    #[error(
        "message {message}: ID {id:#x} ({id}) does not fit 11 bits (at most 0x7ff); an extended ID has bit 31 set in a DBC"
    )]
    IdBeyond11Bits { message: String, id: u16 },
    #[error("message {message}: DLC {dlc}; every frame on the golf car bus has 8 bytes")]
    WrongSize { message: String, dlc: u64 },
    #[error("message ID {id:#x} is defined twice ({first} and {second})")]
    DuplicateId {
        id: u16,
        first: String,
        second: String,
    },
    #[error("message {message}: multiplexed signal {signal} is not supported")]
    Multiplexed { message: String, signal: String },
    #[error("message {message}, signal {signal}: {what}")]
    BadSignal {
        message: String,
        signal: String,
        what: String,
    },
    #[error(
        "message {message}: signals {first} and {second} overlap (both use bit {bit} of the frame)"
    )]
    Overlap {
        message: String,
        first: String,
        second: String,
        bit: usize,
    },
    #[error(
        "message {message}: E2E signal {signal} missing or misplaced; it must be unsigned little-endian at bit {start} with {size} bits"
    )]
    E2eLayout {
        message: String,
        signal: &'static str,
        start: u16,
        size: u8,
    },
    #[error("attribute {attribute} of message {id:#x}: {what}")]
    BadAttribute {
        attribute: String,
        id: u32,
        what: String,
    },
    #[error("{what} refers to message {id:#x}, which the DBC does not define")]
    UnknownMessage { what: &'static str, id: u32 },
}

impl SignalSpec {
    /// The bit positions (0..64, byte-major, LSB first within a byte) the signal occupies.
    pub fn bit_positions(&self) -> Vec<usize> {
        let start = usize::from(self.start_bit);
        let size = usize::from(self.size);
        match self.byte_order {
            ByteOrder::Intel => (start..start + size).collect(),
            ByteOrder::Motorola => {
                // Walk from the MSB downwards in sawtooth order.
                let mut bits = Vec::with_capacity(size);
                let mut bit = start;
                for _ in 0..size {
                    bits.push(bit);
                    if bit % 8 == 0 {
                        bit += 15;
                    } else {
                        bit -= 1;
                    }
                }
                bits
            }
        }
    }

    /// The label of a raw value, if the value table has one.
    pub fn label(&self, raw: i64) -> Option<&str> {
        self.values
            .iter()
            .find(|v| v.raw == raw)
            .map(|v| v.label.as_ref())
    }

    /// Whether this signal is one of the two E2E protection signals.
    pub fn is_e2e(&self) -> bool {
        self.name == COUNTER_SIGNAL || self.name == CRC_SIGNAL
    }
}

impl MessageSpec {
    /// A signal by name (exact).
    pub fn signal(&self, name: &str) -> Option<&SignalSpec> {
        self.signals.iter().find(|s| s.name == name)
    }
}

impl NetworkSpec {
    /// A message by CAN ID.
    pub fn message(&self, id: u16) -> Option<&MessageSpec> {
        self.messages.iter().find(|m| m.id == id)
    }

    /// The IDs of the messages `node` sends or receives (a receiver of any of their
    /// signals): what its acceptance filter lets through, its own IDs included so
    /// that a second sender on them is still heard.
    pub fn ids_of_node(&self, node: &str) -> Vec<u16> {
        self.messages
            .iter()
            .filter(|m| {
                m.senders.iter().any(|s| s == node)
                    || m.signals
                        .iter()
                        .any(|s| s.receivers.iter().any(|r| r == node))
            })
            .map(|m| m.id)
            .collect()
    }

    /// A message by name (case-insensitive) or by ID written as `0x100` or `256`.
    pub fn find_message(&self, key: &str) -> Option<&MessageSpec> {
        let by_id = key
            .strip_prefix("0x")
            .or_else(|| key.strip_prefix("0X"))
            .map(|hex| u16::from_str_radix(hex, 16))
            .unwrap_or_else(|| key.parse::<u16>());
        match by_id {
            Ok(id) => self.message(id),
            Err(_) => self
                .messages
                .iter()
                .find(|m| m.name.eq_ignore_ascii_case(key)),
        }
    }

    /// Parse DBC text and check it against the golf car's bus contract.
    pub fn from_dbc(text: &str) -> Result<NetworkSpec, SpecError> {
        let dbc = can_dbc::Dbc::try_from(text).map_err(|e| SpecError::Syntax(e.to_string()))?;
        convert(&dbc)
    }
}

fn owned(s: &str) -> Cow<'static, str> {
    Cow::Owned(s.to_owned())
}

fn numeric(v: &can_dbc::NumericValue) -> f64 {
    match *v {
        can_dbc::NumericValue::Uint(u) => u as f64,
        can_dbc::NumericValue::Int(i) => i as f64,
        can_dbc::NumericValue::Double(d) => d,
    }
}

fn attribute_u32(
    value: &can_dbc::AttributeValue,
    attribute: &str,
    id: u32,
) -> Result<u32, SpecError> {
    let bad = |what: String| SpecError::BadAttribute {
        attribute: attribute.to_owned(),
        id,
        what,
    };
    match value {
        can_dbc::AttributeValue::Uint(u) => {
            u32::try_from(*u).map_err(|_| bad(format!("{u} does not fit 32 bits")))
        }
        can_dbc::AttributeValue::Int(i) => {
            u32::try_from(*i).map_err(|_| bad(format!("{i} is negative or too large")))
        }
        can_dbc::AttributeValue::Double(d)
            if d.fract() == 0.0 && *d >= 0.0 && *d <= f64::from(u32::MAX) =>
        {
            Ok(*d as u32)
        }
        other => Err(bad(format!(
            "expected a whole number of milliseconds, found {other:?}"
        ))),
    }
}

/// The network of a parsed DBC: its messages checked and converted, the message
/// attributes applied, the database's bit rate (500 kbit/s when not given) and name.
fn convert(dbc: &can_dbc::Dbc) -> Result<NetworkSpec, SpecError> {
    let mut messages: Vec<MessageSpec> = Vec::with_capacity(dbc.messages.len());
    for m in &dbc.messages {
        let message = convert_message(dbc, m, &messages)?;
        messages.push(message);
    }
    for tx in &dbc.message_transmitters {
        if !dbc.messages.iter().any(|m| m.id == tx.message_id) {
            return Err(SpecError::UnknownMessage {
                what: "BO_TX_BU_",
                id: tx.message_id.raw(),
            });
        }
    }
    apply_message_attributes(dbc, &mut messages)?;
    let baudrate = dbc
        .attribute_values_database
        .iter()
        .find(|a| a.name == "Baudrate")
        .map(|a| attribute_u32(&a.value, "Baudrate", 0))
        .transpose()?
        .unwrap_or(500_000);
    let name = dbc
        .attribute_values_database
        .iter()
        .find_map(|a| match (&a.name[..], &a.value) {
            ("DBName", can_dbc::AttributeValue::String(s)) => Some(owned(s)),
            _ => None,
        })
        .unwrap_or_default();
    Ok(NetworkSpec {
        name,
        baudrate,
        nodes: Cow::Owned(
            dbc.nodes
                .iter()
                .flat_map(|n| n.0.split_whitespace())
                .map(owned)
                .collect(),
        ),
        messages: Cow::Owned(messages),
    })
}

/// One message: an 11-bit ID that none of `earlier` has, eight bytes, its signals
/// laid out without overlap, its senders and comment (cycle time and timeout come
/// from the attributes later).
fn convert_message(
    dbc: &can_dbc::Dbc,
    m: &can_dbc::Message,
    earlier: &[MessageSpec],
) -> Result<MessageSpec, SpecError> {
    let id = standard_id(m)?;
    if let Some(first) = earlier.iter().find(|x| x.id == id) {
        return Err(SpecError::DuplicateId {
            id,
            first: first.name.to_string(),
            second: m.name.clone(),
        });
    }
    if m.size != FRAME_LEN as u64 {
        return Err(SpecError::WrongSize {
            message: m.name.clone(),
            dlc: m.size,
        });
    }
    let mut signals = Vec::with_capacity(m.signals.len());
    for s in &m.signals {
        signals.push(convert_signal(dbc, &m.name, m.id, s)?);
    }
    check_layout(&m.name, &signals)?;
    let comment = dbc
        .comments
        .iter()
        .find_map(|c| match c {
            can_dbc::Comment::Message { id: cid, comment } if *cid == m.id => Some(owned(comment)),
            _ => None,
        })
        .unwrap_or_default();
    Ok(MessageSpec {
        id,
        name: owned(&m.name),
        senders: Cow::Owned(senders(dbc, m)),
        cycle_time_ms: None,
        timeout_ms: None,
        signals: Cow::Owned(signals),
        comment,
    })
}

/// A message's ID, which must be a standard (11-bit) one.
fn standard_id(m: &can_dbc::Message) -> Result<u16, SpecError> {
    match m.id {
        can_dbc::MessageId::Standard(id) if id > 0x7FF => Err(SpecError::IdBeyond11Bits {
            message: m.name.clone(),
            id,
        }),
        can_dbc::MessageId::Standard(id) => Ok(id),
        can_dbc::MessageId::Extended(id) => Err(SpecError::ExtendedId {
            message: m.name.clone(),
            id,
        }),
    }
}

/// A message's senders: its transmitter (unless `Vector__XXX`), then those of its
/// `BO_TX_BU_` lines, each once.
fn senders(dbc: &can_dbc::Dbc, m: &can_dbc::Message) -> Vec<Cow<'static, str>> {
    let mut senders: Vec<Cow<'static, str>> = m
        .transmitter
        .iter()
        .filter(|t| t.as_str() != "Vector__XXX")
        .map(|t| owned(t))
        .collect();
    for tx in dbc
        .message_transmitters
        .iter()
        .filter(|t| t.message_id == m.id)
    {
        for t in &tx.transmitter {
            if !senders.iter().any(|s| s == t) {
                senders.push(owned(t));
            }
        }
    }
    senders
}

/// The messages' cycle times and timeouts (`GenMsgCycleTime`, `GenMsgTimeoutTime`;
/// 0 is none), each of a message the DBC defines.
fn apply_message_attributes(
    dbc: &can_dbc::Dbc,
    messages: &mut [MessageSpec],
) -> Result<(), SpecError> {
    for attr in &dbc.attribute_values_message {
        let slot = match attr.name.as_str() {
            "GenMsgCycleTime" => 0,
            "GenMsgTimeoutTime" => 1,
            _ => continue,
        };
        let raw_id = attr.message_id.raw();
        let value = attribute_u32(&attr.value, &attr.name, raw_id)?;
        let message = messages
            .iter_mut()
            .find(|m| {
                u32::from(m.id) == raw_id
                    && matches!(attr.message_id, can_dbc::MessageId::Standard(_))
            })
            .ok_or(SpecError::UnknownMessage {
                what: "a BA_ attribute",
                id: raw_id,
            })?;
        let ms = (value > 0).then_some(value);
        if slot == 0 {
            message.cycle_time_ms = ms;
        } else {
            message.timeout_ms = ms;
        }
    }
    Ok(())
}

/// One signal of `message`: plain (not multiplexed), its bits within the frame, a
/// finite non-zero factor, a finite offset and range, with its value table and
/// comment.
fn convert_signal(
    dbc: &can_dbc::Dbc,
    message: &str,
    message_id: can_dbc::MessageId,
    s: &can_dbc::Signal,
) -> Result<SignalSpec, SpecError> {
    let bad = |what: String| SpecError::BadSignal {
        message: message.to_owned(),
        signal: s.name.clone(),
        what,
    };
    let (min, max) = check_signal(message, s)?;
    let spec = SignalSpec {
        name: owned(&s.name),
        start_bit: s.start_bit as u16,
        size: s.size as u8,
        byte_order: match s.byte_order {
            can_dbc::ByteOrder::LittleEndian => ByteOrder::Intel,
            can_dbc::ByteOrder::BigEndian => ByteOrder::Motorola,
        },
        signed: matches!(s.value_type, can_dbc::ValueType::Signed),
        factor: s.factor,
        offset: s.offset,
        min,
        max,
        unit: owned(&s.unit),
        receivers: Cow::Owned(
            s.receivers
                .iter()
                .filter(|r| r.as_str() != "Vector__XXX")
                .map(|r| owned(r))
                .collect(),
        ),
        values: Cow::Owned(value_table(dbc, message_id, &s.name)),
        comment: signal_comment(dbc, message_id, &s.name),
    };
    if spec.bit_positions().iter().any(|&b| b >= 64) {
        return Err(bad(format!(
            "bits {}|{} run outside the 8-byte frame",
            s.start_bit, s.size
        )));
    }
    Ok(spec)
}

/// A signal's checks before it is converted; returns its range (min, max).
fn check_signal(message: &str, s: &can_dbc::Signal) -> Result<(f64, f64), SpecError> {
    let bad = |what: String| SpecError::BadSignal {
        message: message.to_owned(),
        signal: s.name.clone(),
        what,
    };
    if !matches!(s.multiplexer_indicator, can_dbc::MultiplexIndicator::Plain) {
        return Err(SpecError::Multiplexed {
            message: message.to_owned(),
            signal: s.name.clone(),
        });
    }
    if s.size == 0 || s.size > 64 {
        return Err(bad(format!("size {} bits is outside 1..=64", s.size)));
    }
    if s.start_bit >= 64 {
        return Err(bad(format!(
            "start bit {} is outside the 8-byte frame",
            s.start_bit
        )));
    }
    if !(s.factor.is_finite() && s.factor != 0.0 && s.offset.is_finite()) {
        return Err(bad(format!(
            "factor {} and offset {} must be finite, factor non-zero",
            s.factor, s.offset
        )));
    }
    let (min, max) = (numeric(&s.min), numeric(&s.max));
    if !(min.is_finite() && max.is_finite() && min <= max) {
        return Err(bad(format!("range [{min}|{max}] is not a finite interval")));
    }
    Ok((min, max))
}

/// The value table (`VAL_`) of signal `name` of message `message_id`; empty when none.
fn value_table(dbc: &can_dbc::Dbc, message_id: can_dbc::MessageId, name: &str) -> Vec<ValueLabel> {
    dbc.value_descriptions
        .iter()
        .find_map(|v| match v {
            can_dbc::ValueDescription::Signal {
                message_id: id,
                name: signal,
                value_descriptions,
            } if *id == message_id && signal == name => Some(value_descriptions),
            _ => None,
        })
        .map(|list| {
            list.iter()
                .map(|v| ValueLabel {
                    raw: v.id,
                    label: owned(&v.description),
                })
                .collect::<Vec<_>>()
        })
        .unwrap_or_default()
}

/// The comment (`CM_ SG_`) of signal `name` of message `message_id`; empty when none.
fn signal_comment(
    dbc: &can_dbc::Dbc,
    message_id: can_dbc::MessageId,
    name: &str,
) -> Cow<'static, str> {
    dbc.comments
        .iter()
        .find_map(|c| match c {
            can_dbc::Comment::Signal {
                message_id: id,
                name: signal,
                comment,
            } if *id == message_id && signal == name => Some(owned(comment)),
            _ => None,
        })
        .unwrap_or_default()
}

fn check_layout(message: &str, signals: &[SignalSpec]) -> Result<(), SpecError> {
    let mut owner: [Option<&str>; 64] = [None; 64];
    for s in signals {
        for bit in s.bit_positions() {
            if let Some(first) = owner[bit] {
                return Err(SpecError::Overlap {
                    message: message.to_owned(),
                    first: first.to_owned(),
                    second: s.name.to_string(),
                    bit,
                });
            }
            owner[bit] = Some(&s.name);
        }
    }
    for (name, (start, size)) in [(COUNTER_SIGNAL, COUNTER_LAYOUT), (CRC_SIGNAL, CRC_LAYOUT)] {
        let ok = signals.iter().any(|s| {
            s.name == name
                && s.start_bit == start
                && s.size == size
                && s.byte_order == ByteOrder::Intel
                && !s.signed
                && s.factor == 1.0
                && s.offset == 0.0
        });
        if !ok {
            return Err(SpecError::E2eLayout {
                message: message.to_owned(),
                signal: name,
                start,
                size,
            });
        }
    }
    Ok(())
}
