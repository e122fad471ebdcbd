//! Cross-check against an independent implementation: cantools (PyPI) loads
//! golf_car.dbc, encodes random in-range values for every message and the Rust codec
//! decodes them, and the reverse, agreeing to each signal's resolution.
//!
//! Needs `python3` with `cantools` (scripts/install-deps.sh installs it); fails
//! loudly when it is missing.

// Helpers outside #[test] functions unwrap and panic as the tests do.
#![allow(clippy::expect_used, clippy::panic)]

use std::io::{BufRead, BufReader, Write};
use std::process::{Child, ChildStdin, ChildStdout, Command, Stdio};

use golf_car_can::codec::Payload;
use golf_car_can::{GolfCarMessage, NETWORK, SignalSpec};
use serde_json::{Value, json};

const ROUNDS_PER_MESSAGE: usize = 300;

struct Peer {
    child: Child,
    stdin: ChildStdin,
    stdout: BufReader<ChildStdout>,
}

impl Peer {
    fn start() -> Peer {
        let dir = env!("CARGO_MANIFEST_DIR");
        let mut child = Command::new("python3")
            .arg(format!("{dir}/tests/peers/cantools_peer.py"))
            .arg(format!("{dir}/golf_car.dbc"))
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .spawn()
            .expect("python3 must be installed (scripts/install-deps.sh)");
        let stdin = child.stdin.take().expect("piped stdin");
        let stdout = BufReader::new(child.stdout.take().expect("piped stdout"));
        Peer {
            child,
            stdin,
            stdout,
        }
    }

    fn ask(&mut self, request: Value) -> Value {
        writeln!(self.stdin, "{request}").expect("peer accepts requests");
        let mut line = String::new();
        self.stdout.read_line(&mut line).expect("peer answers");
        assert!(
            !line.is_empty(),
            "the cantools peer died: is cantools installed? (pip install cantools)"
        );
        let answer: Value = serde_json::from_str(&line).expect("peer speaks JSON");
        if let Some(err) = answer.get("error") {
            panic!("cantools refused {request}: {err}");
        }
        answer
    }
}

impl Drop for Peer {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// splitmix64: a fixed-seed generator, so a failure reproduces.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
}

/// A random physical value of the signal: in [min, max], on a raw step, and in the
/// value table when the signal has one.
fn random_value(s: &SignalSpec, rng: &mut Rng) -> f64 {
    if !s.values.is_empty() {
        let v = &s.values[(rng.next() % s.values.len() as u64) as usize];
        return s.to_physical(i128::from(v.raw));
    }
    let lo = s.to_raw(s.min).expect("min encodes");
    let hi = s.to_raw(s.max).expect("max encodes");
    let (lo, hi) = (lo.min(hi), lo.max(hi));
    let raw = lo + i128::from(rng.next()) % (hi - lo + 1);
    s.to_physical(raw)
}

fn assert_close(message: &str, s: &SignalSpec, ours: f64, theirs: f64, dir: &str) {
    assert!(
        (ours - theirs).abs() <= s.factor.abs() / 2.0 + 1e-9,
        "{dir}: {message}.{}: Rust {ours} vs cantools {theirs}",
        s.name
    );
}

fn hex(data: &[u8]) -> String {
    data.iter().map(|b| format!("{b:02x}")).collect()
}

#[test]
fn cantools_encodes_rust_decodes() {
    let mut peer = Peer::start();
    let mut rng = Rng(0x5EED_0001);
    for m in NETWORK.messages.iter() {
        for _ in 0..ROUNDS_PER_MESSAGE {
            let values: Vec<f64> = m
                .signals
                .iter()
                .map(|s| random_value(s, &mut rng))
                .collect();
            let signals: serde_json::Map<String, Value> = m
                .signals
                .iter()
                .zip(&values)
                .map(|(s, v)| (s.name.to_string(), json!(v)))
                .collect();
            let answer = peer.ask(json!({"op": "encode", "message": m.name, "signals": signals}));
            let text = answer["data"].as_str().expect("hex data");
            let bytes: Vec<u8> = (0..text.len())
                .step_by(2)
                .map(|i| u8::from_str_radix(&text[i..i + 2], 16).expect("hex"))
                .collect();
            let data = Payload::try_from(bytes.as_slice()).expect("8 bytes from cantools");
            for ((s, decoded), sent) in m.signals.iter().zip(m.decode_all(&data)).zip(&values) {
                assert_close(&m.name, s, decoded.value, *sent, "cantools->Rust");
            }
            // The typed codec decodes the same bytes and encodes them back unchanged.
            let typed = GolfCarMessage::decode(m.id, &data).expect("typed decode");
            let again = typed.encode().expect("typed encode");
            assert_eq!(&again[..6], &data[..6], "{}: typed re-encode", m.name);
            assert_eq!(
                again[6] & 0xF0,
                data[6] & 0xF0,
                "{}: typed re-encode",
                m.name
            );
        }
    }
}

#[test]
fn rust_encodes_cantools_decodes() {
    let mut peer = Peer::start();
    let mut rng = Rng(0x5EED_0002);
    for m in NETWORK.messages.iter() {
        for _ in 0..ROUNDS_PER_MESSAGE {
            let mut data: Payload = [0; 8];
            let values: Vec<f64> = m
                .signals
                .iter()
                .map(|s| random_value(s, &mut rng))
                .collect();
            for (s, v) in m.signals.iter().zip(&values) {
                s.set(&mut data, *v).expect("in-range value encodes");
            }
            let answer = peer.ask(json!({"op": "decode", "id": m.id, "data": hex(&data)}));
            for (s, v) in m.signals.iter().zip(&values) {
                let theirs = answer["signals"][s.name.as_ref()]
                    .as_f64()
                    .unwrap_or_else(|| panic!("cantools did not decode {}.{}", m.name, s.name));
                assert_close(&m.name, s, *v, theirs, "Rust->cantools");
            }
        }
    }
}
