//! SICK CoLa-A on TCP: the driver's telegram stream (framing, `Message::parse`,
//! `LMDscandata` into a laser frame) and the emulated scanner's request handling.

use firmware_bridge::cola::{
    ClientConfig, DecodeOptions, Device, EncodeOptions, FrameError, Message, ScanData,
    ServerConfig, TelegramDecoder, UserLevel, frame_from_scan, scan_from_frame,
};

type Item = Result<Vec<u8>, FrameError>;

/// The decoder's output for `stream`, fed in the chunks of [`crate::chunks`] or whole.
fn decode(max_len: usize, data: &[u8], chunked: bool) -> (Vec<Item>, u64, usize) {
    let mut decoder = TelegramDecoder::new(max_len);
    let mut items = Vec::new();
    let mut feed = |d: &mut TelegramDecoder, bytes: &[u8]| {
        d.push(bytes);
        while let Some(item) = d.next_telegram() {
            items.push(item);
        }
    };
    if chunked {
        for chunk in crate::chunks(data) {
            feed(&mut decoder, chunk);
        }
    } else if let Some((_, stream)) = data.split_first() {
        feed(&mut decoder, stream);
    }
    let (garbage, partial) = (decoder.garbage_bytes(), decoder.partial_len());
    (items, garbage, partial)
}

/// The stream cut in reads or whole gives the same telegrams, garbage count and
/// partial telegram; every telegram respects the bound and holds no STX or ETX.
fn framed(max_len: usize, data: &[u8]) -> Vec<Item> {
    let chunked = decode(max_len, data, true);
    let whole = decode(max_len, data, false);
    assert_eq!(
        chunked, whole,
        "the telegrams depend on how the stream was cut"
    );
    for payload in chunked.0.iter().flatten() {
        assert!(payload.len() <= max_len.max(1));
        assert!(!payload.contains(&0x02) && !payload.contains(&0x03));
    }
    chunked.0
}

/// A parsed message encodes, and the encoding parses back to a message that encodes
/// to the same bytes (parse . encode is the identity on encodings).
fn round_trip(msg: &Message) {
    let Ok(encoded) = msg.encode() else {
        panic!("a parsed message does not encode: {msg:?}");
    };
    let again = match Message::parse(&encoded) {
        Ok(m) => m,
        Err(e) => panic!(
            "an encoded message does not parse ({e}): {:?}",
            String::from_utf8_lossy(&encoded)
        ),
    };
    let Ok(re_encoded) = again.encode() else {
        panic!("a re-parsed message does not encode: {again:?}");
    };
    assert_eq!(
        String::from_utf8_lossy(&encoded),
        String::from_utf8_lossy(&re_encoded),
        "encode . parse . encode differs from encode"
    );
}

/// What the driver does with a scan: `frame_from_scan` with its default options (the
/// frame is validated inside); a frame that came out is valid and encodes again as the
/// emulated scanner would send it.
fn scan(data: &ScanData) {
    let Ok(frame) = frame_from_scan(data, &DecodeOptions::default()) else {
        return;
    };
    if let Err(e) = frame.validate() {
        panic!("frame_from_scan returned an invalid frame ({e}): {frame:?}");
    }
    if let Ok(back) = scan_from_frame(&frame, &EncodeOptions::default()) {
        let msg = Message::Scan {
            kind: firmware_bridge::cola::ScanKind::Streamed,
            data: Box::new(back),
        };
        round_trip(&msg);
    }
}

/// `cola_telegrams`: the bytes as TCP reads from a scanner, through the driver's path
/// (`ColaClient::next_message`): `TelegramDecoder` with the client's bound, then
/// `Message::parse` of every telegram, then a scan into a laser frame
/// (`ColaClient::frame_of` calls `frame_from_scan`). A second decoder with a small
/// bound exercises the oversize path.
///
/// Invariants: framing does not depend on the read boundaries; parse . encode round
/// trips; frames from scans are valid.
pub fn cola_telegrams(data: &[u8]) {
    let _ = framed(64, data);
    for item in framed(ClientConfig::default().max_telegram, data) {
        let Ok(payload) = item else { continue };
        let Ok(msg) = Message::parse(&payload) else {
            continue;
        };
        round_trip(&msg);
        if let Message::Scan { data, .. } = &msg {
            scan(data);
        }
    }
}

/// Sessions the `cola_server` input can address.
const SESSIONS: u64 = 4;

/// `cola_server`: the emulated scanner's request handling, `Device` (the pure state
/// machine `ColaServer` runs behind its sockets, with `ServerConfig::default()`'s
/// `device_config()`), driven by a script of client actions. Byte 0: bit 0 set gives the
/// device a latest scan first (as `ColaServer::publish` does), so polls are answered.
/// Then records `op len bytes...`: session `op & 3`; `op >> 2 & 3` is 3 to close the
/// session (`Device::close`, no `len`), else `Device::receive` of the next `len` bytes
/// (a TCP read).
///
/// Invariants: one answer per telegram the session's stream completes (a mirror
/// `TelegramDecoder` counts them), fewer only when the last one closes the session;
/// every answer is one framed telegram that parses (the driver can read it); the
/// counters add up; only the controlling session (the first to log in, until it
/// closes) has a login, and only it can start or stop the measurement; the
/// controller, if any, is an open session.
pub fn cola_server(data: &[u8]) {
    let server = ServerConfig::default();
    let config = server.device_config();
    let Ok(mut device) = Device::new(config.clone()) else {
        panic!("the default device configuration is refused");
    };
    let Some((&flags, mut rest)) = data.split_first() else {
        return;
    };
    if flags & 1 == 1 {
        device.set_latest_scan(std::sync::Arc::new(latest_scan()));
    }
    let mut mirrors: Vec<TelegramDecoder> = (0..SESSIONS)
        .map(|_| TelegramDecoder::new(config.max_telegram))
        .collect();
    let mut answers_total = 0u64;
    while let Some((&op, tail)) = rest.split_first() {
        let id = u64::from(op & 3);
        let slot = (op & 3) as usize;
        if (op >> 2) & 3 == 3 {
            device.close(id);
            mirrors[slot] = TelegramDecoder::new(config.max_telegram);
            rest = tail;
            check_device(&device);
            continue;
        }
        let Some((&len, tail)) = tail.split_first() else {
            break;
        };
        let (bytes, tail) = tail.split_at(usize::from(len).min(tail.len()));
        rest = tail;
        let measuring = device.is_measuring();
        mirrors[slot].push(bytes);
        let expected = std::iter::from_fn(|| mirrors[slot].next_telegram()).count();
        let answers = device.receive(id, bytes);
        answers_total += answers.len() as u64;
        let closed = answers.last().is_some_and(|a| a.disconnect);
        if closed {
            assert!(
                answers.len() <= expected,
                "{} answers to {expected} telegrams",
                answers.len()
            );
            assert!(answers[..answers.len() - 1].iter().all(|a| !a.disconnect));
            assert_eq!(
                device.level(id),
                None,
                "a session closed for errors is still open"
            );
            mirrors[slot] = TelegramDecoder::new(config.max_telegram);
        } else {
            assert_eq!(
                answers.len(),
                expected,
                "answers and telegrams differ in number"
            );
        }
        for a in &answers {
            check_answer(&a.telegram);
        }
        if device.is_measuring() != measuring && !closed {
            assert_eq!(
                device.controller(),
                Some(id),
                "session {id} changed the measurement without being in control"
            );
        }
        check_device(&device);
    }
    let stats = device.stats();
    assert_eq!(
        stats.requests + stats.bad_telegrams,
        answers_total,
        "{stats:?}"
    );
}

/// A scan as `ColaServer::publish` frames it.
fn latest_scan() -> Vec<u8> {
    let mut frame = firmware_bridge::laser::LaserFrame {
        count: 3,
        angle_min: -0.5,
        angle_increment: 0.01,
        range_min: 0.5,
        range_max: 20.0,
        ..Default::default()
    };
    frame.ranges[..3].copy_from_slice(&[1.0, f32::INFINITY, f32::NAN]);
    let Ok(scan) = scan_from_frame(&frame, &EncodeOptions::default()) else {
        panic!("the probe frame does not encode");
    };
    let Ok(t) = (Message::Scan {
        kind: firmware_bridge::cola::ScanKind::Streamed,
        data: Box::new(scan),
    })
    .to_telegram() else {
        panic!("the probe scan does not encode");
    };
    t
}

fn check_answer(telegram: &[u8]) {
    let inner = telegram
        .strip_prefix(&[0x02])
        .and_then(|t| t.strip_suffix(&[0x03]));
    let Some(inner) = inner else {
        panic!(
            "an answer is not one framed telegram: {:?}",
            String::from_utf8_lossy(telegram)
        );
    };
    assert!(!inner.contains(&0x02) && !inner.contains(&0x03));
    if let Err(e) = Message::parse(inner) {
        panic!(
            "an answer does not parse ({e}): {:?}",
            String::from_utf8_lossy(inner)
        );
    }
}

fn check_device(device: &Device) {
    if let Some(c) = device.controller() {
        assert!(
            device.level(c).is_some(),
            "the controller {c} is not an open session"
        );
    }
    for id in 0..SESSIONS {
        if device.level(id).is_some_and(|l| l > UserLevel::Run) {
            assert_eq!(
                device.controller(),
                Some(id),
                "session {id} has a login but is not in control"
            );
        }
    }
}
