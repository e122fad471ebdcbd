//! The CAN gateway (`ugv-bridge`) on two real vcan interfaces: one stands for the
//! simulator's bus, the other for the physical one (can0). The test's own sockets act
//! as the nodes on each bus; they never receive their own frames, so whatever they
//! read came through the gateway.
//!
//! Needs a kernel with vcan and CAP_NET_ADMIN; fails loudly without them. The
//! README's test command runs this natively or inside `vcan-setup vm`. Nothing here
//! asserts a duration: every wait is for a condition, with a generous limit for an
//! emulated VM.

use std::io::{BufRead, BufReader, Read};
use std::os::fd::AsRawFd;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::Arc;
use std::sync::mpsc;
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail, ensure};
use firmware_bridge::gateway::{
    Gateway, GatewayConfig, GatewayHandle, GatewayStats, LocalCounts, LocalReason, Side,
};
use golf_car_can::NETWORK;
use golf_car_can::candump::parse_line;
use nix::errno::Errno;
use nix::sys::socket::{self, MsgFlags, sockopt};
use socketcan::{CanInterface, CanSocket, Socket};
use ugv_e2e_tests::{TestVcan, workspace_bin};

/// Upper limit of every wait (never reached when things work; the VM is slow).
const WAIT: Duration = Duration::from_secs(180);

const EFF: u32 = libc::CAN_EFF_FLAG;
const RTR: u32 = libc::CAN_RTR_FLAG;
const ERR_BUSOFF: u32 = libc::CAN_ERR_FLAG | libc::CAN_ERR_BUSOFF;

const HEARTBEAT: u32 = 0x080;
const FAULT: u32 = 0x0F0;
const STEERING_CMD: u32 = 0x100;
const STEERING_REPORT: u32 = 0x101;
const THROTTLE_CMD: u32 = 0x110;
const THROTTLE_REPORT: u32 = 0x111;

/// A frame: the raw `can_id` (with EFF/RTR/ERR flags) and the data bytes.
type Frame = (u32, Vec<u8>);

/// A node on one bus: a raw CAN socket of the test's own.
struct Node {
    iface: String,
    sock: CanSocket,
}

impl Node {
    fn open(iface: &str) -> Result<Node> {
        let sock = CanSocket::open(iface).with_context(|| format!("opening {iface}"))?;
        // A deep receive queue: a burst must not overflow the test's own socket.
        socket::setsockopt(&sock, sockopt::RcvBufForce, &(32 << 20))
            .context("SO_RCVBUFFORCE (needs CAP_NET_ADMIN, like creating the vcan)")?;
        sock.set_read_timeout(Duration::from_millis(200))?;
        Ok(Node {
            iface: iface.to_owned(),
            sock,
        })
    }

    /// Send a frame as the kernel's `struct can_frame`, waiting out a full queue.
    fn send(&self, can_id: u32, data: &[u8]) -> Result<()> {
        ensure!(data.len() <= 8);
        let mut bytes = [0u8; 16];
        bytes[..4].copy_from_slice(&can_id.to_ne_bytes());
        bytes[4] = data.len() as u8;
        bytes[8..8 + data.len()].copy_from_slice(data);
        let start = Instant::now();
        loop {
            match socket::send(self.sock.as_raw_fd(), &bytes, MsgFlags::empty()) {
                Ok(16) => return Ok(()),
                Ok(n) => bail!("sent {n} bytes of a 16-byte frame on {}", self.iface),
                Err(Errno::ENOBUFS | Errno::EAGAIN | Errno::EINTR) if start.elapsed() < WAIT => {
                    std::thread::sleep(Duration::from_micros(100));
                }
                Err(e) => bail!("sending {can_id:#x} on {}: {e}", self.iface),
            }
        }
    }

    fn send_frame(&self, f: &Frame) -> Result<()> {
        self.send(f.0, &f.1)
    }

    /// The next frame, or `None` after `timeout` without one.
    fn recv(&self, timeout: Duration) -> Result<Option<Frame>> {
        let deadline = Instant::now() + timeout;
        loop {
            match self.sock.read_raw_frame() {
                Ok(f) => {
                    let len = usize::from(f.can_dlc).min(8);
                    return Ok(Some((f.can_id, f.data[..len].to_vec())));
                }
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::WouldBlock
                            | std::io::ErrorKind::TimedOut
                            | std::io::ErrorKind::Interrupted
                    ) =>
                {
                    if Instant::now() >= deadline {
                        return Ok(None);
                    }
                }
                Err(e) => return Err(e).with_context(|| format!("reading {}", self.iface)),
            }
        }
    }
}

/// Two fresh vcan interfaces: the simulator's bus and the stand-in for can0.
fn buses(tag: &str) -> Result<(TestVcan, TestVcan)> {
    Ok((
        TestVcan::new(&format!("{tag}s"))?,
        TestVcan::new(&format!("{tag}p"))?,
    ))
}

fn spawn(sim: &TestVcan, phys: &TestVcan, physical_nodes: &[&str]) -> Result<GatewayHandle> {
    Ok(Gateway::spawn(GatewayConfig {
        sim_iface: sim.name.clone(),
        physical_iface: phys.name.clone(),
        physical_nodes: physical_nodes.iter().map(|n| (*n).to_owned()).collect(),
        ..GatewayConfig::default()
    })?)
}

/// Wait until the gateway's stats satisfy `done`.
fn wait_stats(
    gw: &GatewayHandle,
    what: &str,
    done: impl Fn(&GatewayStats) -> bool,
) -> Result<GatewayStats> {
    let start = Instant::now();
    loop {
        let s = gw.stats();
        if done(&s) {
            return Ok(s);
        }
        ensure!(
            start.elapsed() < WAIT,
            "waited {WAIT:?} for {what}; stats: {}",
            serde_json::to_string_pretty(&s)?
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Send `frames` then `sentinel` on `from`; return everything `to` received before the
/// sentinel (the gateway keeps order, so that is all it forwarded of `frames`).
fn exchange(from: &Node, to: &Node, frames: &[Frame], sentinel: &Frame) -> Result<Vec<Frame>> {
    for f in frames {
        from.send_frame(f)?;
    }
    from.send_frame(sentinel)?;
    let mut got = Vec::new();
    loop {
        let f = to.recv(WAIT)?.with_context(|| {
            format!(
                "the sentinel {sentinel:x?} sent on {} never reached {}; got before it: {got:x?}",
                from.iface, to.iface
            )
        })?;
        if &f == sentinel {
            return Ok(got);
        }
        got.push(f);
    }
}

/// One frame of a routing case and what must happen to it.
struct Case {
    side: Side,
    frame: Frame,
    /// `None`: forwarded; `Some(reason)`: kept local for that reason.
    local: Option<LocalReason>,
}

fn case(side: Side, can_id: u32, data: &[u8], local: Option<LocalReason>) -> Case {
    Case {
        side,
        frame: (can_id, data.to_vec()),
        local,
    }
}

fn expected_local(cases: &[Case], side: Side) -> LocalCounts {
    let mut c = LocalCounts::default();
    for k in cases.iter().filter(|k| k.side == side) {
        match k.local {
            None => {}
            Some(LocalReason::UnknownId) => c.unknown_id += 1,
            Some(LocalReason::SenderOnOtherSide) => c.sender_on_other_side += 1,
            Some(LocalReason::NoReceiverAcross) => c.no_receiver_across += 1,
            Some(LocalReason::WrongDlc) => c.wrong_dlc += 1,
            Some(LocalReason::Remote) => c.remote += 1,
            Some(LocalReason::ErrorFrame) => c.error_frame += 1,
            Some(LocalReason::UnknownSource) => c.unknown_source += 1,
        }
    }
    c
}

fn message_name(can_id: u32) -> Result<String> {
    let id = u16::try_from(can_id).context("not an 11-bit ID")?;
    Ok(NETWORK
        .message(id)
        .with_context(|| format!("{id:#x} is not in the DBC"))?
        .name
        .to_string())
}

/// Run a routing case: frames from the simulator's side with a sentinel, then frames
/// from the physical side with a sentinel, then a second sentinel from the simulator's
/// side (anything the gateway echoed would show up before one of them), then the
/// counts.
fn routing(
    tag: &str,
    physical: &[&str],
    cases: &[Case],
    sentinel_sim: Frame,
    sentinel_phys: Frame,
) -> Result<()> {
    let (sim, phys) = buses(tag)?;
    let gw = spawn(&sim, &phys, physical)?;
    let s = Node::open(&sim.name)?;
    let p = Node::open(&phys.name)?;
    let frames = |side: Side| -> Vec<Frame> {
        cases
            .iter()
            .filter(|c| c.side == side)
            .map(|c| c.frame.clone())
            .collect()
    };
    let crossing = |side: Side| -> Vec<Frame> {
        cases
            .iter()
            .filter(|c| c.side == side && c.local.is_none())
            .map(|c| c.frame.clone())
            .collect()
    };

    let out = exchange(&s, &p, &frames(Side::Sim), &sentinel_sim)?;
    ensure!(
        out == crossing(Side::Sim),
        "{physical:?} physical: the physical bus got {out:x?}, expected {:x?}",
        crossing(Side::Sim)
    );
    let back = exchange(&p, &s, &frames(Side::Physical), &sentinel_phys)?;
    ensure!(
        back == crossing(Side::Physical),
        "{physical:?} physical: the simulator's bus got {back:x?}, expected {:x?} (nothing sent from it may come back)",
        crossing(Side::Physical)
    );
    let late = exchange(&s, &p, &[], &sentinel_sim)?;
    ensure!(
        late.is_empty(),
        "the physical bus got {late:x?} after the exchange: an echo"
    );

    let n_sim = frames(Side::Sim).len() as u64 + 2;
    let n_phys = frames(Side::Physical).len() as u64 + 1;
    let stats = wait_stats(&gw, "the counts of every frame sent", |st| {
        st.to_physical.received >= n_sim && st.to_sim.received >= n_phys
    })?;
    let text = serde_json::to_string_pretty(&stats)?;
    // Exactly what the nodes sent, nothing the gateway sent itself.
    ensure!(stats.to_physical.received == n_sim, "{text}");
    ensure!(stats.to_sim.received == n_phys, "{text}");
    ensure!(
        stats.to_physical.forwarded == crossing(Side::Sim).len() as u64 + 2,
        "{text}"
    );
    ensure!(
        stats.to_sim.forwarded == crossing(Side::Physical).len() as u64 + 1,
        "{text}"
    );
    ensure!(
        stats.to_physical.local == expected_local(cases, Side::Sim),
        "{text}"
    );
    ensure!(
        stats.to_sim.local == expected_local(cases, Side::Physical),
        "{text}"
    );
    for (dir, side, sentinel, n_sentinels) in [
        (&stats.to_physical, Side::Sim, &sentinel_sim, 2),
        (&stats.to_sim, Side::Physical, &sentinel_phys, 1),
    ] {
        for (name, counts) in &dir.messages {
            let mut want = 0;
            for f in crossing(side) {
                if message_name(f.0).ok().as_ref() == Some(name) {
                    want += 1;
                }
            }
            if &message_name(sentinel.0)? == name {
                want += n_sentinels;
            }
            ensure!(
                counts.forwarded == want,
                "{name} from the {side} side: forwarded {} expected {want}",
                counts.forwarded
            );
        }
        ensure!(
            dir.tx_dropped == 0 && dir.rx_overflow == 0 && dir.rx_errors == 0,
            "{text}"
        );
        ensure!(dir.latency.samples == dir.forwarded, "{text}");
    }
    ensure!(stats.running && stats.error.is_none(), "{text}");
    let last = gw.stop();
    ensure!(!last.running && last.error.is_none(), "{last:?}");
    Ok(())
}

/// FAULT_REPORT with a Source (1 controller, 2 steering, 3 throttle) and some code.
fn fault(source: u8, code: u8) -> Vec<u8> {
    vec![source, code, 0x12, 0x34, 0, 0, 0x05, 0xA5]
}

#[test]
fn steering_ecu_physical_routes_by_the_dbc() -> Result<()> {
    use LocalReason::*;
    use Side::{Physical as P, Sim as S};
    let d = |b: u8| vec![b, 1, 2, 3, 4, 5, 6, 7];
    let cases = [
        case(S, STEERING_CMD, &d(0x10), None),
        case(S, HEARTBEAT, &d(0x11), None),
        case(S, THROTTLE_CMD, &d(0x12), Some(NoReceiverAcross)),
        case(S, THROTTLE_REPORT, &d(0x13), Some(NoReceiverAcross)),
        // A steering report injected on the simulator's side: its sender is outside.
        case(S, STEERING_REPORT, &d(0x14), Some(SenderOnOtherSide)),
        case(S, FAULT, &fault(1, 7), None),
        case(S, FAULT, &fault(3, 11), None),
        case(S, FAULT, &fault(2, 5), Some(SenderOnOtherSide)),
        case(S, FAULT, &fault(0, 5), Some(UnknownSource)),
        case(S, STEERING_CMD, &d(0x15), None),
        case(S, 0x555, &d(0x16), Some(UnknownId)),
        case(S, STEERING_CMD | EFF, &d(0x17), Some(UnknownId)),
        case(S, STEERING_CMD, &[1, 2, 3, 4], Some(WrongDlc)),
        case(S, STEERING_CMD | RTR, &[], Some(Remote)),
        case(S, ERR_BUSOFF, &[0; 8], Some(ErrorFrame)),
        case(S, STEERING_CMD, &[0xFF; 8], None), // bad CRC: still crosses, verbatim
        case(P, STEERING_REPORT, &d(0x20), None),
        case(P, FAULT, &fault(2, 6), None),
        case(P, FAULT, &fault(1, 7), Some(SenderOnOtherSide)),
        case(P, STEERING_CMD, &d(0x21), Some(SenderOnOtherSide)),
        case(P, HEARTBEAT, &d(0x22), Some(SenderOnOtherSide)),
        case(P, THROTTLE_CMD, &d(0x23), Some(SenderOnOtherSide)),
        case(P, THROTTLE_REPORT, &d(0x24), Some(SenderOnOtherSide)),
        case(P, STEERING_REPORT, &d(0x25), None),
        case(P, 0x7FF, &d(0x26), Some(UnknownId)),
        case(P, STEERING_REPORT, &d(0x27)[..7], Some(WrongDlc)),
        case(P, ERR_BUSOFF, &[0; 8], Some(ErrorFrame)),
    ];
    routing(
        "gws",
        &["STEERING_ECU"],
        &cases,
        (STEERING_CMD, b"SENTINEL".to_vec()),
        (STEERING_REPORT, b"sentinel".to_vec()),
    )
}

#[test]
fn controller_physical_routes_by_the_dbc() -> Result<()> {
    use LocalReason::*;
    use Side::{Physical as P, Sim as S};
    let d = |b: u8| vec![b, 9, 8, 7, 6, 5, 4, 3];
    let cases = [
        case(S, STEERING_REPORT, &d(0x30), None),
        case(S, THROTTLE_REPORT, &d(0x31), None),
        case(S, FAULT, &fault(2, 5), None),
        case(S, FAULT, &fault(3, 6), None),
        case(S, FAULT, &fault(1, 7), Some(SenderOnOtherSide)),
        case(S, STEERING_CMD, &d(0x32), Some(SenderOnOtherSide)),
        case(S, HEARTBEAT, &d(0x33), Some(SenderOnOtherSide)),
        case(S, THROTTLE_CMD, &d(0x34), Some(SenderOnOtherSide)),
        case(S, THROTTLE_REPORT | RTR, &[], Some(Remote)),
        case(P, HEARTBEAT, &d(0x40), None),
        case(P, STEERING_CMD, &d(0x41), None),
        case(P, THROTTLE_CMD, &d(0x42), None),
        case(P, FAULT, &fault(1, 3), None),
        case(P, FAULT, &fault(2, 3), Some(SenderOnOtherSide)),
        case(P, FAULT, &fault(9, 3), Some(UnknownSource)),
        case(P, STEERING_REPORT, &d(0x43), Some(SenderOnOtherSide)),
        case(P, THROTTLE_REPORT, &d(0x44), Some(SenderOnOtherSide)),
        case(P, THROTTLE_CMD, &d(0x45)[..2], Some(WrongDlc)),
        case(P, 0x1234_5678 | EFF, &d(0x46), Some(UnknownId)),
    ];
    routing(
        "gwc",
        &["CONTROLLER"],
        &cases,
        (STEERING_REPORT, b"SENTINEL".to_vec()),
        (STEERING_CMD, b"sentinel".to_vec()),
    )
}

fn seq_payload(i: u32) -> Vec<u8> {
    let mut d = i.to_le_bytes().to_vec();
    d.extend_from_slice(&(!i).to_le_bytes());
    d
}

/// Read `n` frames of `id` and return their sequence numbers in arrival order.
fn receive_sequence(node: &Node, id: u32, n: usize) -> Result<Vec<u32>> {
    let mut seqs = Vec::with_capacity(n);
    while seqs.len() < n {
        let (can_id, data) = node.recv(WAIT)?.with_context(|| {
            format!(
                "{} received {} of {n} frames, then nothing for {WAIT:?}",
                node.iface,
                seqs.len()
            )
        })?;
        ensure!(
            can_id == id,
            "unexpected frame {can_id:#x} on {}",
            node.iface
        );
        ensure!(data.len() == 8, "{can_id:#x} with {} bytes", data.len());
        let seq = u32::from_le_bytes([data[0], data[1], data[2], data[3]]);
        let check = u32::from_le_bytes([data[4], data[5], data[6], data[7]]);
        ensure!(check == !seq, "frame {seq} arrived altered: {data:x?}");
        seqs.push(seq);
    }
    Ok(seqs)
}

fn check_sequence(seqs: &[u32], n: u32, what: &str) -> Result<()> {
    if let Some(i) = (0..n as usize).find(|&i| seqs.get(i) != Some(&(i as u32))) {
        let mut sorted = seqs.to_vec();
        sorted.sort_unstable();
        sorted.dedup();
        bail!(
            "{what}: position {i} holds {:?} (expected {i}); {} frames, {} distinct",
            seqs.get(i),
            seqs.len(),
            sorted.len()
        );
    }
    ensure!(seqs.len() == n as usize, "{what}: {} frames", seqs.len());
    Ok(())
}

/// Send `n` sequence frames of `id` back to back at the bus's full rate: one 8-byte
/// frame per worst-case frame time at the DBC's bit rate, as a saturated bus carries
/// them. vcan has no bit rate; unpaced, a sender in a guest outruns every reader while
/// a real-time forwarder holds the softirqs that empty the input backlog (seen: 4,473
/// frames dropped under a CPU hog), a load no physical bus can carry. A sender that
/// wakes late sends what is due at once, but an idle bus stores no frames: at most
/// `CREDIT` of them.
fn send_at_bus_rate(node: &Node, id: u32, n: u32) -> Result<()> {
    const CREDIT: Duration = Duration::from_millis(2);
    let bits = firmware_bridge::can::arbiter::frame_bits_worst(false, 8);
    let period = Duration::from_secs_f64(bits as f64 / f64::from(NETWORK.baudrate));
    let mut due = Instant::now();
    for i in 0..n {
        let now = Instant::now();
        if due > now {
            std::thread::sleep(due - now);
        } else {
            due = due.max(now - CREDIT);
        }
        node.send(id, &seq_payload(i))?;
        due += period;
    }
    Ok(())
}

#[test]
fn a_burst_each_way_at_once_loses_nothing_and_keeps_order() -> Result<()> {
    const N: u32 = 20_000;
    let (sim, phys) = buses("gwb")?;
    let gw = spawn(&sim, &phys, &["STEERING_ECU"])?;
    let s = Arc::new(Node::open(&sim.name)?);
    let p = Arc::new(Node::open(&phys.name)?);
    let started = Instant::now();
    let rx_out = {
        let p = Arc::clone(&p);
        std::thread::spawn(move || receive_sequence(&p, STEERING_CMD, N as usize))
    };
    let rx_in = {
        let s = Arc::clone(&s);
        std::thread::spawn(move || receive_sequence(&s, STEERING_REPORT, N as usize))
    };
    let tx_out = {
        let s = Arc::clone(&s);
        std::thread::spawn(move || -> Result<()> { send_at_bus_rate(&s, STEERING_CMD, N) })
    };
    let tx_in = {
        let p = Arc::clone(&p);
        std::thread::spawn(move || -> Result<()> { send_at_bus_rate(&p, STEERING_REPORT, N) })
    };
    let join = |t: std::thread::JoinHandle<Result<()>>| {
        t.join().map_err(|_| anyhow::anyhow!("a sender panicked"))?
    };
    join(tx_out)?;
    join(tx_in)?;
    let out = rx_out
        .join()
        .map_err(|_| anyhow::anyhow!("a receiver panicked"))??;
    let inn = rx_in
        .join()
        .map_err(|_| anyhow::anyhow!("a receiver panicked"))??;
    check_sequence(&out, N, "simulator -> physical")?;
    check_sequence(&inn, N, "physical -> simulator")?;
    let took = started.elapsed();

    let n = u64::from(N);
    let stats = wait_stats(&gw, "the counts of the burst", |st| {
        st.to_physical.received >= n && st.to_sim.received >= n
    })?;
    let text = serde_json::to_string_pretty(&stats)?;
    for (dir, name) in [
        (&stats.to_physical, "STEERING_CMD"),
        (&stats.to_sim, "STEERING_REPORT"),
    ] {
        ensure!(dir.received == n && dir.forwarded == n, "{text}");
        ensure!(dir.local.total() == 0, "{text}");
        ensure!(dir.tx_dropped == 0 && dir.rx_overflow == 0, "{text}");
        ensure!(
            dir.messages.get(name).map(|m| m.forwarded) == Some(n),
            "{text}"
        );
        ensure!(
            dir.messages
                .iter()
                .filter(|(k, _)| k.as_str() != name)
                .all(|(_, m)| m.forwarded == 0 && m.local == 0),
            "{text}"
        );
        ensure!(dir.latency.samples == n, "{text}");
    }
    // The wire keeps real time: both threads at the default real-time priority
    // (the VM runs the tests as root).
    let fifo = format!(
        "SCHED_FIFO priority {}",
        firmware_bridge::realtime::DEFAULT_PRIORITY
    );
    ensure!(
        stats.scheduling.len() == 2 && stats.scheduling.iter().all(|line| line.ends_with(&fifo)),
        "{text}"
    );
    eprintln!(
        "burst: {N} frames each way in {took:.2?}; tx retries {} / {}; latency p50/p99 {:.0}/{:.0} us and {:.0}/{:.0} us",
        stats.to_physical.tx_retries,
        stats.to_sim.tx_retries,
        stats.to_physical.latency.p50_us,
        stats.to_physical.latency.p99_us,
        stats.to_sim.latency.p50_us,
        stats.to_sim.latency.p99_us,
    );
    Ok(())
}

#[test]
fn a_full_transmit_queue_is_waited_out_and_nothing_is_lost() -> Result<()> {
    const N: u32 = 1_000;
    let (sim, phys) = buses("gwq")?;
    // A vcan never refuses a frame; a real bus does: can0's queue fills at 500 kbit/s
    // and the kernel answers ENOBUFS. A token bucket on the physical stand-in does the
    // same (16 bytes per frame at 64 kbit/s: 500 frames/s, a queue of 4 frames).
    let tc = Command::new("tc")
        .args(["qdisc", "add", "dev", &phys.name, "root", "tbf"])
        .args(["rate", "64kbit", "burst", "64", "limit", "64"])
        .output()
        .context("running tc (Debian package iproute2)")?;
    ensure!(
        tc.status.success(),
        "tc qdisc add ... tbf: {}",
        String::from_utf8_lossy(&tc.stderr)
    );
    let gw = spawn(&sim, &phys, &["STEERING_ECU"])?;
    let s = Node::open(&sim.name)?;
    let p = Node::open(&phys.name)?;
    for i in 0..N {
        s.send(STEERING_CMD, &seq_payload(i))?;
    }
    let got = receive_sequence(&p, STEERING_CMD, N as usize)?;
    check_sequence(&got, N, "through a full transmit queue")?;
    let n = u64::from(N);
    let stats = wait_stats(&gw, "the counts", |st| st.to_physical.received >= n)?;
    let d = &stats.to_physical;
    let text = serde_json::to_string_pretty(&stats)?;
    ensure!(d.forwarded == n && d.tx_dropped == 0, "{text}");
    ensure!(d.tx_retries > 0, "the queue never filled: {text}");
    eprintln!("full queue: {N} frames, {} transmit retries", d.tx_retries);
    Ok(())
}

#[test]
fn unplugging_the_physical_interface_stops_the_gateway_with_an_error() -> Result<()> {
    let (sim, phys) = buses("gwu")?;
    let gw = spawn(&sim, &phys, &["THROTTLE_ECU"])?;
    ensure!(gw.is_running());
    ensure!(vcan_setup::down(&phys.name)?, "{} was not there", phys.name);
    let stats = wait_stats(&gw, "the gateway to notice", |s| !s.running)?;
    let error = stats.error.context("stopped without an error")?;
    ensure!(
        error.contains(&phys.name) && error.contains("went away"),
        "{error}"
    );
    ensure!(!gw.is_running());
    Ok(())
}

/// A running `ugv-bridge`, its stderr lines on a channel.
struct Bridge {
    child: Child,
    stderr: mpsc::Receiver<String>,
    stdout: std::thread::JoinHandle<String>,
}

impl Bridge {
    fn start(args: &[&str]) -> Result<Bridge> {
        let mut child = Command::new(workspace_bin("ugv-bridge")?)
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .context("starting ugv-bridge")?;
        let err = child.stderr.take().context("stderr")?;
        let mut out = child.stdout.take().context("stdout")?;
        let (tx, stderr) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(err).lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        let stdout = std::thread::spawn(move || {
            let mut s = String::new();
            let _ = out.read_to_string(&mut s);
            s
        });
        Ok(Bridge {
            child,
            stderr,
            stdout,
        })
    }

    /// Wait for a stderr line that satisfies `want`; returns it.
    fn wait_line(&self, what: &str, want: impl Fn(&str) -> bool) -> Result<String> {
        let deadline = Instant::now() + WAIT;
        let mut seen = Vec::new();
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.stderr.recv_timeout(left) {
                Ok(line) if want(&line) => return Ok(line),
                Ok(line) => seen.push(line),
                Err(_) => bail!("ugv-bridge never printed {what}; stderr so far: {seen:#?}"),
            }
        }
    }

    /// Wait for the process to end; its status, stdout and remaining stderr.
    fn wait(mut self) -> Result<(ExitStatus, String, String)> {
        let deadline = Instant::now() + WAIT;
        let status = loop {
            if let Some(status) = self.child.try_wait()? {
                break status;
            }
            if Instant::now() >= deadline {
                let _ = self.child.kill();
                bail!("ugv-bridge did not exit within {WAIT:?}");
            }
            std::thread::sleep(Duration::from_millis(20));
        };
        let stdout = self
            .stdout
            .join()
            .map_err(|_| anyhow::anyhow!("stdout reader panicked"))?;
        let mut stderr = String::new();
        while let Ok(line) = self.stderr.recv_timeout(Duration::from_secs(5)) {
            stderr.push_str(&line);
            stderr.push('\n');
        }
        Ok((status, stdout, stderr))
    }
}

/// Run `ugv-bridge` to completion (for the error cases).
fn bridge_fails(args: &[&str]) -> Result<(i32, String)> {
    let (status, _, stderr) = Bridge::start(args)?.wait()?;
    Ok((status.code().unwrap_or(-1), stderr))
}

#[test]
fn the_binary_forwards_logs_counts_and_stops_on_sigterm() -> Result<()> {
    let (sim, phys) = buses("gwx")?;
    let dir = tempfile::tempdir()?;
    let log = dir.path().join("forwarded.log");
    let stats_path = dir.path().join("stats.json");
    let bridge = Bridge::start(&[
        "--sim",
        &sim.name,
        "--physical",
        &phys.name,
        "--node",
        "steering_ecu",
        "--log",
        log.to_str().context("temp path")?,
        "--stats",
        stats_path.to_str().context("temp path")?,
        "--interval",
        "0.5",
    ])?;
    bridge.wait_line("that it is forwarding", |l| {
        l.starts_with("ugv-bridge: forwarding between")
    })?;
    let s = Node::open(&sim.name)?;
    let p = Node::open(&phys.name)?;
    const N: u8 = 10;
    let cmds: Vec<Frame> = (0..N)
        .map(|i| {
            (
                STEERING_CMD,
                vec![i, 0xC0, 0xFF, 0xEE, 0, 1, i & 0x0F, 0x55],
            )
        })
        .collect();
    let reports: Vec<Frame> = (0..N)
        .map(|i| (STEERING_REPORT, vec![i, 0xAB, 0, 0, 0, 0, i & 0x0F, 0x66]))
        .collect();
    s.send(THROTTLE_CMD, &[0; 8])?; // stays on the simulator's bus
    let out = exchange(&s, &p, &cmds[..9], &cmds[9])?;
    ensure!(out == cmds[..9], "{out:x?}");
    let back = exchange(&p, &s, &reports[..9], &reports[9])?;
    ensure!(back == reports[..9], "{back:x?}");
    // The periodic stats line catches up with the traffic.
    bridge.wait_line("a stats line with both directions at 10", |l| {
        l.starts_with("ugv-bridge: ") && l.matches("forwarded 10 ").count() == 2
    })?;

    let pid = nix::unistd::Pid::from_raw(i32::try_from(bridge.child.id())?);
    nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGTERM)?;
    let (status, stdout, stderr) = bridge.wait()?;
    ensure!(status.success(), "{status}; stderr: {stderr}");

    let summary: serde_json::Value =
        serde_json::from_str(&stdout).with_context(|| format!("stdout: {stdout}"))?;
    let file: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&stats_path)?)?;
    ensure!(summary == file, "--stats differs from stdout");
    let get = |path: &str| summary.pointer(path).and_then(serde_json::Value::as_u64);
    ensure!(
        get("/to_physical/forwarded") == Some(u64::from(N)),
        "{stdout}"
    );
    ensure!(
        get("/to_physical/received") == Some(u64::from(N) + 1),
        "{stdout}"
    );
    ensure!(
        get("/to_physical/local/no_receiver_across") == Some(1),
        "{stdout}"
    );
    ensure!(
        get("/to_physical/messages/STEERING_CMD/forwarded") == Some(u64::from(N)),
        "{stdout}"
    );
    ensure!(get("/to_sim/forwarded") == Some(u64::from(N)), "{stdout}");
    ensure!(
        get("/to_sim/messages/STEERING_REPORT/forwarded") == Some(u64::from(N)),
        "{stdout}"
    );
    ensure!(summary["physical_nodes"] == serde_json::json!(["STEERING_ECU"]));
    ensure!(summary["error"].is_null(), "{stdout}");

    // Two lines per forwarded frame: R as read on one bus, T as sent on the other.
    let text = std::fs::read_to_string(&log)?;
    let lines: Vec<&str> = text.lines().collect();
    ensure!(lines.len() == 4 * usize::from(N), "{text}");
    let mut forwarded_out = Vec::new();
    let mut forwarded_in = Vec::new();
    for pair in lines.chunks(2) {
        let (r, t) = (parse_line(pair[0])?, parse_line(pair[1])?);
        ensure!(
            pair[0].ends_with(" R") && pair[1].ends_with(" T"),
            "{pair:?}"
        );
        ensure!(r.id == t.id && r.data == t.data, "{pair:?}");
        let frame = (r.id, r.data.clone());
        match (r.interface.as_deref(), t.interface.as_deref()) {
            (Some(a), Some(b)) if a == sim.name && b == phys.name => forwarded_out.push(frame),
            (Some(a), Some(b)) if a == phys.name && b == sim.name => forwarded_in.push(frame),
            _ => bail!("unexpected interfaces in {pair:?}"),
        }
    }
    ensure!(forwarded_out == cmds, "{text}");
    ensure!(forwarded_in == reports, "{text}");
    Ok(())
}

#[test]
fn the_binary_explains_bad_interfaces_and_nodes() -> Result<()> {
    let (sim, phys) = buses("gwe")?;
    let missing = format!("vtnone{}", std::process::id() % 100_000);
    let (code, err) = bridge_fails(&[
        "--sim",
        &sim.name,
        "--physical",
        &missing,
        "--node",
        "STEERING_ECU",
    ])?;
    ensure!(code == 1, "exit {code}: {err}");
    ensure!(
        err.contains(&missing) && err.contains("does not exist") && err.contains("vcan-setup up"),
        "{err}"
    );
    ensure!(!err.contains("panicked"), "{err}");

    CanInterface::open(&phys.name)?.bring_down()?;
    let (code, err) = bridge_fails(&[
        "--sim",
        &sim.name,
        "--physical",
        &phys.name,
        "--node",
        "STEERING_ECU",
    ])?;
    ensure!(code == 1, "exit {code}: {err}");
    ensure!(
        err.contains(&phys.name)
            && err.contains("is down")
            && err.contains(&format!("ip link set {} up", phys.name)),
        "{err}"
    );

    let (code, err) = bridge_fails(&[
        "--sim",
        &sim.name,
        "--physical",
        &phys.name,
        "--node",
        "BRAKE_ECU",
    ])?;
    ensure!(code == 1, "exit {code}: {err}");
    ensure!(
        err.contains("BRAKE_ECU") && err.contains("CONTROLLER, STEERING_ECU, THROTTLE_ECU"),
        "{err}"
    );

    let (code, err) = bridge_fails(&[
        "--sim",
        &sim.name,
        "--physical",
        &sim.name,
        "--node",
        "CONTROLLER",
    ])?;
    ensure!(code == 1 && err.contains("both"), "exit {code}: {err}");

    let (code, err) = bridge_fails(&["--sim", &sim.name, "--physical", &phys.name])?;
    ensure!(code == 2 && err.contains("--node"), "exit {code}: {err}");
    Ok(())
}
