//! CAN text and the CAN contract: candump lines (`ugv-can decode`) and the runtime DBC
//! loader (`ugv-can --dbc`).

use std::collections::BTreeMap;

use golf_car_can::candump::{Compact, parse_compact, parse_line};
use golf_car_can::codec::payload;
use golf_car_can::{E2eRx, NETWORK, NetworkSpec, Payload};

/// What `ugv-can decode` does with one parsed frame: the E2E check of its interface,
/// the message by ID, its payload and every signal decoded (and shown as JSON).
fn decode_frame<'n>(
    network: &'n NetworkSpec,
    receivers: &mut BTreeMap<String, E2eRx<'n>>,
    frame: &golf_car_can::candump::TextFrame,
) {
    let iface = frame.interface.clone().unwrap_or_default();
    let _ = receivers
        .entry(iface)
        .or_insert_with(|| E2eRx::new(network))
        .accept_parts(frame.id, frame.extended, frame.remote, &frame.data);
    let message = (!frame.extended)
        .then(|| u16::try_from(frame.id).ok())
        .flatten()
        .and_then(|id| network.message(id));
    if let (Some(m), Ok(p)) = (message, payload("", &frame.data)) {
        for v in m.decode_all(&p) {
            let _ = serde_json::to_value(&v);
        }
    }
}

/// `candump_line`: the bytes as a candump log read by `ugv-can decode`: split into
/// lines, each line (lossily UTF-8, so a bad byte costs only its line) through
/// `candump::parse_line` unless blank, every frame through the E2E receiver of its
/// interface and the DBC decode.
///
/// Invariants: a frame has at most 8 bytes and an ID within its width; the cansend form
/// of a frame (`Compact`) parses back to the same ID, width and data.
pub fn candump_line(data: &[u8]) {
    let mut receivers = BTreeMap::new();
    for line in data.split(|b| *b == b'\n') {
        let line = String::from_utf8_lossy(line);
        if line.trim().is_empty() {
            continue;
        }
        let Ok(frame) = parse_line(&line) else {
            continue;
        };
        assert!(frame.data.len() <= 8, "{frame:?}");
        if frame.extended {
            assert!(frame.id <= 0x1FFF_FFFF, "{frame:?}");
        } else {
            assert!(frame.id <= 0x7FF, "{frame:?}");
        }
        if frame.remote {
            assert!(frame.data.is_empty(), "{frame:?}");
        } else {
            let text = Compact {
                id: frame.id,
                extended: frame.extended,
                data: &frame.data,
            }
            .to_string();
            match parse_compact(&text) {
                Ok((id, extended, remote, bytes)) => assert_eq!(
                    (id, extended, remote, &bytes),
                    (frame.id, frame.extended, false, &frame.data),
                    "{text} does not parse back to {frame:?}"
                ),
                Err(e) => panic!("{text} (from {frame:?}) does not parse: {e}"),
            }
        }
        decode_frame(&NETWORK, &mut receivers, &frame);
    }
}

/// `dbc_spec`: the bytes as a DBC file given to `ugv-can --dbc` (read as UTF-8 text,
/// then `NetworkSpec::from_dbc`).
///
/// Invariants of a network that loads: message IDs are unique 11-bit IDs; every
/// signal's bits lie in the frame and no two signals share one; every raw value a
/// signal's bits hold writes and reads back unchanged (its bounds, 0, and -1 when
/// signed), without touching another signal; the E2E receiver and the decode of
/// `ugv-can decode` take frames of every message.
pub fn dbc_spec(data: &[u8]) {
    let Some(text) = crate::text(data) else {
        return;
    };
    let Ok(network) = NetworkSpec::from_dbc(text) else {
        return;
    };
    let mut rx = E2eRx::new(&network);
    for (k, m) in network.messages.iter().enumerate() {
        assert!(m.id <= 0x7FF, "message {} has ID {:#x}", m.name, m.id);
        assert!(
            network.messages[..k].iter().all(|o| o.id != m.id),
            "message ID {:#x} twice",
            m.id
        );
        let mut owner = [false; 64];
        for s in m.signals.iter() {
            for bit in s.bit_positions() {
                assert!(bit < 64, "signal {} bit {bit}", s.name);
                assert!(!owner[bit], "signal {} overlaps at bit {bit}", s.name);
                owner[bit] = true;
            }
        }
        for s in m.signals.iter() {
            let (lo, hi) = s.raw_bounds();
            let mut raws = vec![lo, hi, 0];
            if s.signed {
                raws.push(-1);
            }
            for raw in raws {
                let mut p: Payload = [0xA5; 8];
                let before: Vec<i128> = m
                    .signals
                    .iter()
                    .filter(|o| o.name != s.name)
                    .map(|o| o.get_raw(&p))
                    .collect();
                if let Err(e) = s.set_raw(&mut p, raw) {
                    panic!("signal {} refuses raw {raw} within its bounds: {e}", s.name);
                }
                assert_eq!(s.get_raw(&p), raw, "signal {} raw {raw}", s.name);
                let after: Vec<i128> = m
                    .signals
                    .iter()
                    .filter(|o| o.name != s.name)
                    .map(|o| o.get_raw(&p))
                    .collect();
                assert_eq!(before, after, "writing {} changed another signal", s.name);
            }
            // The physical value of a raw value in range converts back to it.
            let _ = s.to_raw(s.to_physical(0));
        }
        let p: Payload = [0; 8];
        for v in m.decode_all(&p) {
            let _ = serde_json::to_value(&v);
        }
        let _ = rx.accept_parts(u32::from(m.id), false, false, &p);
    }
}
