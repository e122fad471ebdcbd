//! The CAN wire on a real vcan interface, against can-utils (candump, cansend): an
//! independent implementation of SocketCAN on the other end.
//!
//! Needs a kernel with vcan and CAP_NET_ADMIN; fails loudly without them. The
//! README's test command runs this natively or inside `vcan-setup vm`.

use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::time::Duration;

use anyhow::{Context, Result, ensure};
use firmware_bridge::{CanPort, Received};
use golf_car_can::candump::{Compact, parse_line};
use golf_car_can::e2e::protect;
use golf_car_can::{
    CanMessage, E2eError, E2eRx, GolfCarMessage, NETWORK, SteeringCmd, ThrottleCmd, ThrottleCmdGear,
};
use ugv_e2e_tests::{TestVcan, can_utils};

const WAIT: Duration = Duration::from_secs(10);

/// An ID outside the DBC, used to learn that candump is listening.
const PROBE_ID: u16 = 0x7FF;

#[test]
fn candump_receives_what_the_rust_socket_sends() -> Result<()> {
    let vcan = TestVcan::new("dump")?;
    const N: usize = 40;
    let mut candump = Command::new("candump")
        .args(["-L", "-T", "60000", &vcan.name])
        .stdout(Stdio::piped())
        .spawn()
        .context("starting candump (Debian package can-utils)")?;
    let stdout = candump.stdout.take().context("candump stdout")?;
    let (lines_tx, lines) = std::sync::mpsc::channel::<String>();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            if lines_tx.send(line).is_err() {
                break;
            }
        }
    });
    let mut port = CanPort::open(&vcan.name)?;
    // Probe until candump shows it is bound (it prints nothing when it starts).
    let mut ready = false;
    for _ in 0..100 {
        port.send_payload(PROBE_ID, &[0; 8])?;
        if let Ok(line) = lines.recv_timeout(Duration::from_millis(200)) {
            ready = parse_line(&line)?.id == u32::from(PROBE_ID);
            if ready {
                break;
            }
        }
    }
    ensure!(ready, "candump never showed the probe frame");
    while lines.recv_timeout(Duration::from_millis(200)).is_ok() {} // late probes
    let mut sent = Vec::new();
    for i in 0..N {
        let cmd = SteeringCmd {
            enable: i % 2 == 0,
            target_angle: -30.0 + i as f64 * 1.5,
            max_rate: 100.0,
        };
        port.send(&cmd)?;
        sent.push(cmd);
    }
    let mut rx = E2eRx::new(&NETWORK);
    let mut got = Vec::new();
    while got.len() < N {
        let line = lines
            .recv_timeout(WAIT)
            .with_context(|| format!("candump saw {} of {N} frames", got.len()))?;
        let frame = parse_line(&line).with_context(|| format!("candump line {line:?}"))?;
        ensure!(frame.interface.as_deref() == Some(vcan.name.as_str()));
        if frame.id == u32::from(PROBE_ID) {
            continue;
        }
        let (id, payload) = rx.accept_parts(frame.id, frame.extended, frame.remote, &frame.data)?;
        ensure!(id == SteeringCmd::ID);
        got.push(SteeringCmd::decode(&payload)?);
    }
    let _ = candump.kill();
    let _ = candump.wait();
    for (a, b) in sent.iter().zip(&got) {
        ensure!(a.enable == b.enable && (a.target_angle - b.target_angle).abs() < 0.006);
    }
    ensure!(rx.stats().accepted == N as u64 && rx.stats().rejected() == 0);
    Ok(())
}

fn expect_message(port: &mut CanPort) -> Result<GolfCarMessage> {
    match port.recv(WAIT)? {
        Some(Received::Message(m)) => Ok(m),
        other => anyhow::bail!("expected a message, got {other:?}"),
    }
}

fn expect_rejected(port: &mut CanPort) -> Result<E2eError> {
    match port.recv(WAIT)? {
        Some(Received::Rejected(e)) => Ok(e),
        other => anyhow::bail!("expected a rejected frame, got {other:?}"),
    }
}

fn cansend(iface: &str, id: u16, data: &[u8; 8]) -> Result<()> {
    let frame = Compact {
        id: u32::from(id),
        extended: false,
        data,
    }
    .to_string();
    let out = can_utils("cansend", &[iface, &frame])?;
    ensure!(
        out.status.success(),
        "cansend {iface} {frame}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    Ok(())
}

#[test]
fn rust_socket_receives_what_cansend_sends() -> Result<()> {
    let vcan = TestVcan::new("send")?;
    let mut port = CanPort::open(&vcan.name)?;
    let cmd = ThrottleCmd {
        enable: true,
        gear: ThrottleCmdGear::Forward,
        brake: 0.0,
        target_speed: 2.35,
        accel_limit: 1.0,
    };
    for counter in 0..20u8 {
        let mut data = cmd.encode()?;
        protect(ThrottleCmd::ID, &mut data, counter);
        cansend(&vcan.name, ThrottleCmd::ID, &data)?;
        match expect_message(&mut port)? {
            GolfCarMessage::ThrottleCmd(got) => {
                ensure!(got.gear == ThrottleCmdGear::Forward && got.enable);
                ensure!((got.target_speed - 2.35).abs() < 1e-9, "{got:?}");
            }
            other => anyhow::bail!("wrong message {other:?}"),
        }
    }
    ensure!(port.stats().accepted == 20 && port.stats().rejected() == 0);
    Ok(())
}

#[test]
fn e2e_rejects_corrupted_replayed_and_skipped_frames_from_cansend() -> Result<()> {
    let vcan = TestVcan::new("e2e")?;
    let mut port = CanPort::open(&vcan.name)?;
    let cmd = SteeringCmd {
        enable: true,
        target_angle: 10.0,
        max_rate: 50.0,
    };
    let frame = |counter: u8| -> Result<[u8; 8]> {
        let mut data = cmd.encode()?;
        protect(SteeringCmd::ID, &mut data, counter);
        Ok(data)
    };
    cansend(&vcan.name, SteeringCmd::ID, &frame(0)?)?;
    expect_message(&mut port)?;

    // Replay: the same frame again.
    cansend(&vcan.name, SteeringCmd::ID, &frame(0)?)?;
    ensure!(matches!(
        expect_rejected(&mut port)?,
        E2eError::RepeatedCounter { counter: 0, .. }
    ));

    // Corrupted: one data bit flipped after the CRC was computed.
    let mut corrupt = frame(1)?;
    corrupt[2] ^= 0x10;
    cansend(&vcan.name, SteeringCmd::ID, &corrupt)?;
    ensure!(matches!(
        expect_rejected(&mut port)?,
        E2eError::BadCrc { .. }
    ));

    // The genuine frame 1 still passes, then a skip from 1 to 3.
    cansend(&vcan.name, SteeringCmd::ID, &frame(1)?)?;
    expect_message(&mut port)?;
    cansend(&vcan.name, SteeringCmd::ID, &frame(3)?)?;
    ensure!(matches!(
        expect_rejected(&mut port)?,
        E2eError::SkippedCounter {
            expected: 2,
            found: 3,
            ..
        }
    ));

    // Wrong DLC and an unknown ID.
    let out = can_utils("cansend", &[&vcan.name, "100#0102"])?;
    ensure!(out.status.success());
    ensure!(matches!(
        expect_rejected(&mut port)?,
        E2eError::WrongDlc { dlc: 2, .. }
    ));
    let out = can_utils("cansend", &[&vcan.name, "555#0102030405060708"])?;
    ensure!(out.status.success());
    ensure!(matches!(
        expect_rejected(&mut port)?,
        E2eError::UnknownId { id: 0x555, .. }
    ));

    let s = port.stats();
    ensure!(s.accepted == 2, "{s:?}");
    ensure!(
        (
            s.repeated_counter,
            s.bad_crc,
            s.skipped_counter,
            s.wrong_dlc,
            s.unknown_id
        ) == (1, 1, 1, 1, 1),
        "{s:?}"
    );
    Ok(())
}

/// The controller's acceptance filter: frames on IDs it neither sends nor receives
/// (a babbler's) never reach it, its own and its ECUs' still do (a bad one still
/// counted), and so do frames on its own IDs from someone else (the second sender).
#[test]
fn an_acceptance_filter_keeps_other_ids_away_and_lets_the_nodes_own_through() -> Result<()> {
    let vcan = TestVcan::new("filt")?;
    let mut port = CanPort::open(&vcan.name)?;
    port.accept_only(&golf_car_can::NETWORK.ids_of_node("CONTROLLER"))?;
    let cmd = SteeringCmd {
        enable: true,
        target_angle: 10.0,
        max_rate: 50.0,
    };
    let mut data = cmd.encode()?;
    protect(SteeringCmd::ID, &mut data, 0);
    for _ in 0..50 {
        let out = can_utils("cansend", &[&vcan.name, "000#0102030405060708"])?;
        ensure!(out.status.success());
        let out = can_utils("cansend", &[&vcan.name, "555#0102030405060708"])?;
        ensure!(out.status.success());
    }
    cansend(&vcan.name, SteeringCmd::ID, &data)?;
    // The first frame through is the steering command, after 100 of others.
    expect_message(&mut port)?;
    let out = can_utils("cansend", &[&vcan.name, "100#0102"])?;
    ensure!(out.status.success());
    ensure!(matches!(
        expect_rejected(&mut port)?,
        E2eError::WrongDlc { dlc: 2, .. }
    ));
    ensure!(port.recv(Duration::from_millis(200))?.is_none());
    let s = port.stats();
    ensure!(s.unknown_id == 0 && s.accepted == 1, "{s:?}");
    Ok(())
}

/// The timed socket of the simulator's HIL loop: a frame is handed out once the
/// horizon has passed its kernel receive time, in order, never before.
#[test]
fn a_timed_socket_hands_out_only_the_frames_that_arrived_by_its_horizon() -> Result<()> {
    use embedded_can::nb::Can;
    use firmware_bridge::can::timed::{Horizon, TimedSocket};
    use std::time::SystemTime;

    let vcan = TestVcan::new("timed")?;
    let horizon = Horizon::new();
    horizon.set(SystemTime::now());
    let mut timed = TimedSocket::open(&vcan.name, horizon.clone())?;
    let mut sender = CanPort::open(&vcan.name)?;
    let mut sent_by = Vec::new();
    for id in 1..=3u16 {
        sender.send_bytes(id, &[id as u8])?;
        std::thread::sleep(Duration::from_millis(20));
        sent_by.push(SystemTime::now());
    }
    let take = |timed: &mut TimedSocket| -> Result<Option<u32>> {
        match timed.receive() {
            Ok(f) => Ok(Some(match embedded_can::Frame::id(&f) {
                embedded_can::Id::Standard(s) => u32::from(s.as_raw()),
                embedded_can::Id::Extended(e) => e.as_raw(),
            })),
            Err(nb::Error::WouldBlock) => Ok(None),
            Err(nb::Error::Other(e)) => anyhow::bail!("receive: {e}"),
        }
    };
    ensure!(take(&mut timed)?.is_none(), "a frame before the horizon");
    // Twice: a held frame stays held.
    ensure!(take(&mut timed)?.is_none(), "a held frame came out");
    horizon.set(sent_by[0]);
    ensure!(take(&mut timed)? == Some(1));
    ensure!(take(&mut timed)?.is_none(), "frame 2 before its time");
    horizon.set(sent_by[2]);
    ensure!(take(&mut timed)? == Some(2));
    ensure!(take(&mut timed)? == Some(3));
    ensure!(take(&mut timed)?.is_none());
    Ok(())
}

/// A reader stalled while a burst crosses the bus: the timed socket's deep queue
/// (`DEEP_QUEUE_BYTES`) keeps every frame and the kernel drops none, where a socket
/// with the kernel's usual default queue (208 KiB) loses most of them and the
/// kernel counts what it dropped (the figure the HIL verdict reports per ECU).
#[test]
fn a_stalled_timed_socket_keeps_every_frame_of_a_burst_a_default_queue_drops_them() -> Result<()> {
    use embedded_can::nb::Can;
    use firmware_bridge::can::timed::{Horizon, TimedSocket};
    use firmware_bridge::can::{QueueDrops, set_receive_queue};
    use socketcan::{CanSocket, Socket};

    const BURST: usize = 3000;
    let vcan = TestVcan::new("deep")?;
    let mut timed = TimedSocket::open(&vcan.name, Horizon::new())?;
    let shallow = CanSocket::open(&vcan.name)?;
    shallow.set_nonblocking(true)?;
    set_receive_queue(&shallow, 212_992 / 2).context("the usual default queue")?;
    let mut sender = CanPort::open(&vcan.name)?;
    for n in 0..BURST {
        let data = (n as u32).to_le_bytes();
        // The sender's own queue may be full for a moment: try again.
        let mut tries = 0;
        while let Err(e) = sender.send_bytes(0x123, &data) {
            tries += 1;
            ensure!(tries < 1000, "sending frame {n}: {e}");
            std::thread::sleep(Duration::from_millis(1));
        }
    }
    // Only now do the readers look.
    ensure!(timed.queue_drops() == Some(0), "{:?}", timed.queue_drops());
    let mut kept = Vec::new();
    loop {
        match timed.receive() {
            Ok(f) => {
                let d = embedded_can::Frame::data(&f);
                kept.push(u32::from_le_bytes([d[0], d[1], d[2], d[3]]));
            }
            Err(nb::Error::WouldBlock) => break,
            Err(nb::Error::Other(e)) => anyhow::bail!("receive: {e}"),
        }
    }
    ensure!(
        kept == (0..BURST as u32).collect::<Vec<_>>(),
        "the deep queue kept {} of {BURST} frames",
        kept.len()
    );
    let mut read = 0;
    while shallow.read_frame().is_ok() {
        read += 1;
    }
    let dropped = shallow.queue_drops().context("SO_MEMINFO")?;
    ensure!(
        read < BURST / 2 && read + dropped as usize == BURST,
        "the default queue kept {read} and dropped {dropped} of {BURST}"
    );
    Ok(())
}
