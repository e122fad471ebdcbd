//! Generates the Rust codecs of golf_car.dbc: the network tables and one typed
//! struct per message (enums for value tables), so the DBC stays the single source
//! of truth. The DBC is parsed and checked with the same code the library uses for
//! a DBC loaded at run time (src/spec.rs).

#[path = "src/spec.rs"]
#[allow(dead_code)]
mod spec;

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::{Context, Result};
use spec::{MessageSpec, NetworkSpec, SignalSpec};

fn main() -> Result<()> {
    let manifest = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR")?);
    let dbc_path = manifest.join("golf_car.dbc");
    println!("cargo::rerun-if-changed={}", dbc_path.display());
    println!("cargo::rerun-if-changed=src/spec.rs");
    let text = std::fs::read_to_string(&dbc_path)
        .with_context(|| format!("reading {}", dbc_path.display()))?;
    let network =
        NetworkSpec::from_dbc(&text).with_context(|| format!("in {}", dbc_path.display()))?;
    let code = generate(&network)?;
    let out = PathBuf::from(std::env::var("OUT_DIR")?).join("golf_car.rs");
    std::fs::write(&out, code).with_context(|| format!("writing {}", out.display()))?;
    Ok(())
}

/// `STEERING_CMD` -> `SteeringCmd`, `command_timeout` -> `CommandTimeout`.
fn camel(name: &str) -> String {
    name.split(['_', ' ', '-'])
        .filter(|w| !w.is_empty())
        .map(|w| {
            let lower = w.to_ascii_lowercase();
            let mut chars = lower.chars();
            chars
                .next()
                .map(|c| c.to_ascii_uppercase().to_string() + chars.as_str())
                .unwrap_or_default()
        })
        .collect()
}

/// `TargetAngle` -> `target_angle`.
fn snake(name: &str) -> String {
    let mut out = String::new();
    let chars: Vec<char> = name.chars().collect();
    for (i, &c) in chars.iter().enumerate() {
        if c.is_ascii_uppercase() {
            let prev_lower = i > 0 && chars[i - 1].is_ascii_lowercase();
            let next_lower = chars.get(i + 1).is_some_and(|n| n.is_ascii_lowercase());
            let prev_upper = i > 0 && chars[i - 1].is_ascii_uppercase();
            if i > 0 && (prev_lower || (prev_upper && next_lower)) && !out.ends_with('_') {
                out.push('_');
            }
            out.push(c.to_ascii_lowercase());
        } else {
            out.push(c);
        }
    }
    const KEYWORDS: &[&str] = &[
        "abstract", "as", "async", "await", "become", "box", "break", "const", "continue", "do",
        "dyn", "else", "enum", "extern", "false", "final", "fn", "for", "gen", "if", "impl", "in",
        "let", "loop", "macro", "match", "mod", "move", "mut", "override", "priv", "pub", "ref",
        "return", "static", "struct", "trait", "true", "try", "type", "typeof", "unsafe",
        "unsized", "use", "virtual", "where", "while", "yield",
    ];
    if KEYWORDS.contains(&out.as_str()) {
        format!("r#{out}")
    } else {
        out
    }
}

/// How a signal appears in its message's typed struct.
enum FieldKind {
    Bool,
    Enum(String),
    Int(&'static str),
    Float,
}

fn field_kind(message: &MessageSpec, s: &SignalSpec) -> FieldKind {
    if s.size == 1 && !s.signed && s.factor == 1.0 && s.offset == 0.0 {
        FieldKind::Bool
    } else if !s.values.is_empty() {
        FieldKind::Enum(format!("{}{}", camel(&message.name), s.name))
    } else if s.factor == 1.0 && s.offset == 0.0 {
        let bits = [8u8, 16, 32, 64]
            .into_iter()
            .find(|b| *b >= s.size)
            .unwrap_or(64);
        FieldKind::Int(match (s.signed, bits) {
            (false, 8) => "u8",
            (false, 16) => "u16",
            (false, 32) => "u32",
            (false, _) => "u64",
            (true, 8) => "i8",
            (true, 16) => "i16",
            (true, 32) => "i32",
            (true, _) => "i64",
        })
    } else {
        FieldKind::Float
    }
}

fn strs(list: &[std::borrow::Cow<'static, str>]) -> String {
    let items: Vec<String> = list
        .iter()
        .map(|s| format!("Cow::Borrowed({s:?})"))
        .collect();
    format!("[{}]", items.join(", "))
}

/// The generated module: the network tables, each message's value-table enums and
/// typed struct, and one enum over all messages.
fn generate(net: &NetworkSpec) -> Result<String> {
    let mut o = String::new();
    write_prelude(&mut o)?;
    for m in net.messages.iter() {
        write_message_tables(&mut o, m)?;
    }
    write_network_tables(&mut o, net)?;
    for (mi, m) in net.messages.iter().enumerate() {
        for s in m.signals.iter().filter(|s| !s.is_e2e()) {
            if let FieldKind::Enum(ename) = field_kind(m, s) {
                write_value_enum(&mut o, m, s, &ename)?;
            }
        }
        write_message_struct(&mut o, m)?;
        write_can_message_impl(&mut o, m, mi)?;
    }
    write_any_message(&mut o, net)?;
    Ok(o)
}

/// The generated file's header and imports.
fn write_prelude(o: &mut String) -> Result<()> {
    writeln!(
        o,
        "// @generated by can-dbc/build.rs from golf_car.dbc. Do not edit."
    )?;
    writeln!(o, "use std::borrow::Cow;")?;
    writeln!(
        o,
        "use crate::spec::{{ByteOrder, MessageSpec, NetworkSpec, SignalSpec, ValueLabel}};"
    )?;
    writeln!(o, "use crate::codec::{{payload, Payload}};")?;
    writeln!(o, "use crate::{{CanMessage, CodecError}};\n")?;
    Ok(())
}

/// A message's static tables: its senders, each signal's receivers and value table,
/// and its signals.
fn write_message_tables(o: &mut String, m: &MessageSpec) -> Result<()> {
    let key = m.name.to_uppercase();
    writeln!(
        o,
        "static SENDERS_{key}: [Cow<'static, str>; {}] = {};",
        m.senders.len(),
        strs(&m.senders)
    )?;
    for s in m.signals.iter() {
        let skey = format!("{key}_{}", s.name.to_uppercase());
        writeln!(
            o,
            "static RECEIVERS_{skey}: [Cow<'static, str>; {}] = {};",
            s.receivers.len(),
            strs(&s.receivers)
        )?;
        let values: Vec<String> = s
            .values
            .iter()
            .map(|v| {
                format!(
                    "ValueLabel {{ raw: {}, label: Cow::Borrowed({:?}) }}",
                    v.raw, v.label
                )
            })
            .collect();
        writeln!(
            o,
            "static VALUES_{skey}: [ValueLabel; {}] = [{}];",
            values.len(),
            values.join(", ")
        )?;
    }
    writeln!(
        o,
        "static SIGNALS_{key}: [SignalSpec; {}] = [",
        m.signals.len()
    )?;
    for s in m.signals.iter() {
        let skey = format!("{key}_{}", s.name.to_uppercase());
        writeln!(
            o,
            "    SignalSpec {{ name: Cow::Borrowed({:?}), start_bit: {}, size: {}, byte_order: ByteOrder::{:?}, signed: {}, factor: {:?}, offset: {:?}, min: {:?}, max: {:?}, unit: Cow::Borrowed({:?}), receivers: Cow::Borrowed(&RECEIVERS_{skey}), values: Cow::Borrowed(&VALUES_{skey}), comment: Cow::Borrowed({:?}) }},",
            s.name,
            s.start_bit,
            s.size,
            s.byte_order,
            s.signed,
            s.factor,
            s.offset,
            s.min,
            s.max,
            s.unit,
            s.comment
        )?;
    }
    writeln!(o, "];")?;
    Ok(())
}

/// The network's tables: all messages, the nodes, and `NETWORK` itself.
fn write_network_tables(o: &mut String, net: &NetworkSpec) -> Result<()> {
    writeln!(
        o,
        "static MESSAGES: [MessageSpec; {}] = [",
        net.messages.len()
    )?;
    for m in net.messages.iter() {
        let key = m.name.to_uppercase();
        writeln!(
            o,
            "    MessageSpec {{ id: {:#x}, name: Cow::Borrowed({:?}), senders: Cow::Borrowed(&SENDERS_{key}), cycle_time_ms: {:?}, timeout_ms: {:?}, signals: Cow::Borrowed(&SIGNALS_{key}), comment: Cow::Borrowed({:?}) }},",
            m.id, m.name, m.cycle_time_ms, m.timeout_ms, m.comment
        )?;
    }
    writeln!(o, "];")?;
    writeln!(
        o,
        "static NODES: [Cow<'static, str>; {}] = {};",
        net.nodes.len(),
        strs(&net.nodes)
    )?;
    writeln!(
        o,
        "/// The golf car network, generated from golf_car.dbc.\npub static NETWORK: NetworkSpec = NetworkSpec {{ name: Cow::Borrowed({:?}), baudrate: {}, nodes: Cow::Borrowed(&NODES), messages: Cow::Borrowed(&MESSAGES) }};\n",
        net.name, net.baudrate
    )?;
    Ok(())
}

/// The enum `ename` of a signal's value table: its values in raw order, and their
/// raw values and labels.
fn write_value_enum(o: &mut String, m: &MessageSpec, s: &SignalSpec, ename: &str) -> Result<()> {
    let mut values: Vec<_> = s.values.iter().collect();
    values.sort_by_key(|v| v.raw);
    writeln!(
        o,
        "/// Values of {}.{} (value table of the DBC).",
        m.name, s.name
    )?;
    writeln!(
        o,
        "#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]\npub enum {ename} {{"
    )?;
    for (i, v) in values.iter().enumerate() {
        let default = if i == 0 { "#[default] " } else { "" };
        writeln!(o, "    {default}{} = {},", camel(&v.label), v.raw)?;
    }
    writeln!(o, "}}")?;
    writeln!(o, "impl {ename} {{")?;
    writeln!(o, "    /// All values, in raw order.")?;
    let all: Vec<String> = values
        .iter()
        .map(|v| format!("Self::{}", camel(&v.label)))
        .collect();
    writeln!(
        o,
        "    pub const ALL: [Self; {}] = [{}];",
        all.len(),
        all.join(", ")
    )?;
    writeln!(
        o,
        "    /// The raw value on the wire.\n    pub fn raw(self) -> i64 {{ self as i64 }}"
    )?;
    writeln!(
        o,
        "    /// The value for a raw value, if the table defines one.\n    pub fn from_raw(raw: i128) -> Option<Self> {{ match raw {{"
    )?;
    for v in &values {
        writeln!(o, "        {} => Some(Self::{}),", v.raw, camel(&v.label))?;
    }
    writeln!(o, "        _ => None }} }}")?;
    writeln!(
        o,
        "    /// The DBC's label.\n    pub fn label(self) -> &'static str {{ match self {{"
    )?;
    for v in &values {
        writeln!(o, "        Self::{} => {:?},", camel(&v.label), v.label)?;
    }
    writeln!(o, "    }} }}\n}}")?;
    writeln!(
        o,
        "impl std::fmt::Display for {ename} {{ fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {{ f.write_str(self.label()) }} }}\n"
    )?;
    Ok(())
}

/// A message's typed struct: one documented field per signal (E2E signals left out).
fn write_message_struct(o: &mut String, m: &MessageSpec) -> Result<()> {
    let ty = camel(&m.name);
    writeln!(o, "/// {} ({:#x}). {}", m.name, m.id, m.comment)?;
    writeln!(
        o,
        "#[derive(Clone, Copy, Debug, Default, PartialEq)]\npub struct {ty} {{"
    )?;
    for s in m.signals.iter().filter(|s| !s.is_e2e()) {
        let rust_ty = match field_kind(m, s) {
            FieldKind::Bool => "bool".to_owned(),
            FieldKind::Enum(e) => e,
            FieldKind::Int(t) => t.to_owned(),
            FieldKind::Float => "f64".to_owned(),
        };
        let unit = if s.unit.is_empty() {
            String::new()
        } else {
            format!(" {}", s.unit)
        };
        writeln!(
            o,
            "    /// {} [{}, {}]{unit}, resolution {}.",
            if s.comment.is_empty() {
                &s.name
            } else {
                &s.comment
            },
            s.min,
            s.max,
            s.factor
        )?;
        writeln!(o, "    pub {}: {rust_ty},", snake(&s.name))?;
    }
    writeln!(o, "}}")?;
    Ok(())
}

/// `impl CanMessage` for a message's struct: its ID, name and spec (`MESSAGES[mi]`),
/// and its encoder and decoder.
fn write_can_message_impl(o: &mut String, m: &MessageSpec, mi: usize) -> Result<()> {
    let ty = camel(&m.name);
    writeln!(o, "impl CanMessage for {ty} {{")?;
    writeln!(o, "    const ID: u16 = {:#x};", m.id)?;
    writeln!(o, "    const NAME: &'static str = {:?};", m.name)?;
    writeln!(
        o,
        "    fn spec() -> &'static MessageSpec {{ &MESSAGES[{mi}] }}"
    )?;
    write_encode(o, m)?;
    write_decode(o, m)?;
    writeln!(o, "}}\n")?;
    Ok(())
}

/// `CanMessage::encode`: each field set into its signal.
fn write_encode(o: &mut String, m: &MessageSpec) -> Result<()> {
    let key = m.name.to_uppercase();
    writeln!(o, "    fn encode(&self) -> Result<Payload, CodecError> {{")?;
    writeln!(o, "        let mut data: Payload = [0; 8];")?;
    for (si, s) in m.signals.iter().enumerate().filter(|(_, s)| !s.is_e2e()) {
        let f = snake(&s.name);
        match field_kind(m, s) {
            FieldKind::Bool => writeln!(
                o,
                "        SIGNALS_{key}[{si}].set_raw(&mut data, i128::from(self.{f}))?;"
            )?,
            FieldKind::Enum(_) => writeln!(
                o,
                "        SIGNALS_{key}[{si}].set_raw(&mut data, i128::from(self.{f}.raw()))?;"
            )?,
            FieldKind::Int(_) => writeln!(
                o,
                "        SIGNALS_{key}[{si}].set(&mut data, self.{f} as f64)?;"
            )?,
            FieldKind::Float => {
                writeln!(o, "        SIGNALS_{key}[{si}].set(&mut data, self.{f})?;")?
            }
        }
    }
    writeln!(o, "        Ok(data)\n    }}")?;
    Ok(())
}

/// `CanMessage::decode`: each field read from its signal (a value outside its value
/// table is an error).
fn write_decode(o: &mut String, m: &MessageSpec) -> Result<()> {
    let key = m.name.to_uppercase();
    writeln!(
        o,
        "    fn decode(data: &[u8]) -> Result<Self, CodecError> {{"
    )?;
    writeln!(o, "        let data = payload(Self::NAME, data)?;")?;
    writeln!(o, "        Ok(Self {{")?;
    for (si, s) in m.signals.iter().enumerate().filter(|(_, s)| !s.is_e2e()) {
        let f = snake(&s.name);
        let sig = format!("SIGNALS_{key}[{si}]");
        match field_kind(m, s) {
            FieldKind::Bool => writeln!(o, "            {f}: {sig}.get_raw(&data) != 0,")?,
            FieldKind::Enum(e) => writeln!(
                o,
                "            {f}: {{ let raw = {sig}.get_raw(&data); {e}::from_raw(raw).ok_or(CodecError::UndefinedValue {{ message: Self::NAME, signal: {:?}, raw }})? }},",
                s.name
            )?,
            FieldKind::Int(t) => writeln!(o, "            {f}: {sig}.get_raw(&data) as {t},")?,
            FieldKind::Float => writeln!(o, "            {f}: {sig}.get(&data),")?,
        }
    }
    writeln!(o, "        }})\n    }}")?;
    Ok(())
}

/// `GolfCarMessage`, one enum over all messages: decoding by CAN ID, and each
/// message's name, ID and encoder.
fn write_any_message(o: &mut String, net: &NetworkSpec) -> Result<()> {
    writeln!(o, "/// Any message of the golf car network.")?;
    writeln!(
        o,
        "#[derive(Clone, Copy, Debug, PartialEq)]\npub enum GolfCarMessage {{"
    )?;
    for m in net.messages.iter() {
        let ty = camel(&m.name);
        writeln!(o, "    {ty}({ty}),")?;
    }
    writeln!(o, "}}")?;
    writeln!(o, "impl GolfCarMessage {{")?;
    writeln!(o, "    /// Decode a payload by CAN ID.")?;
    writeln!(
        o,
        "    pub fn decode(id: u16, data: &[u8]) -> Result<Self, CodecError> {{ match id {{"
    )?;
    for m in net.messages.iter() {
        let ty = camel(&m.name);
        writeln!(
            o,
            "        {:#x} => Ok(Self::{ty}({ty}::decode(data)?)),",
            m.id
        )?;
    }
    writeln!(
        o,
        "        other => Err(CodecError::UnknownId(u32::from(other))) }} }}"
    )?;
    writeln!(
        o,
        "    /// The DBC name.\n    pub fn name(&self) -> &'static str {{ match self {{"
    )?;
    for m in net.messages.iter() {
        writeln!(o, "        Self::{}(_) => {:?},", camel(&m.name), m.name)?;
    }
    writeln!(o, "    }} }}")?;
    writeln!(
        o,
        "    /// The CAN ID.\n    pub fn id(&self) -> u16 {{ match self {{"
    )?;
    for m in net.messages.iter() {
        writeln!(o, "        Self::{}(_) => {:#x},", camel(&m.name), m.id)?;
    }
    writeln!(o, "    }} }}")?;
    writeln!(
        o,
        "    /// Encode the signals (E2E bytes left zero).\n    pub fn encode(&self) -> Result<Payload, CodecError> {{ match self {{"
    )?;
    for m in net.messages.iter() {
        writeln!(o, "        Self::{}(m) => m.encode(),", camel(&m.name))?;
    }
    writeln!(o, "    }} }}\n}}")?;
    Ok(())
}
