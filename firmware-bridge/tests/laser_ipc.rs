//! The laser wire over iceoryx2: in one process, across two processes (the
//! `ugv-laser-synth` binary as a publisher, and the `ugv-laser-echo` binary as a
//! subscriber), late subscribers and malformed frames. Every test uses its own service
//! name.

mod common;

use std::io::{BufRead, BufReader, Write};
use std::process::{Command, Stdio};
use std::time::Duration;

use anyhow::{Context, Result, ensure};
use firmware_bridge::laser::{
    LaserError, LaserFrame, LaserPublisher, LaserSubscriber, SUBSCRIBER_BUFFER,
};
use iceoryx2::node::NodeView;
use iceoryx2::prelude::*;

/// Generous: a frame normally arrives in microseconds; this only bounds a broken test.
const WAIT: Duration = Duration::from_secs(20);

fn unique_service(test: &str) -> String {
    common::unique_service("test", test)
}

/// Beam counts up to the maximum, varying with the sequence number.
fn beams_of(seq: u64) -> usize {
    [541, 1081, 181, 1][(seq % 4) as usize]
}

/// A frame whose every field follows from its sequence number, with inf and NaN beams,
/// and a beam count that varies up to the maximum.
fn make_frame(seq: u64) -> LaserFrame {
    LaserFrame::synthetic(seq, beams_of(seq))
}

fn check(frame: &LaserFrame, seq: u64) -> Result<()> {
    ensure!(
        frame.sequence == seq,
        "expected sequence {seq}, got {}",
        frame.sequence
    );
    ensure!(
        frame.bit_eq(&make_frame(seq)),
        "frame {seq} arrived altered: {frame:?}"
    );
    Ok(())
}

#[test]
fn frames_arrive_in_order_and_intact_in_one_process() -> Result<()> {
    let service = unique_service("inproc");
    let sub = LaserSubscriber::new(&service)?;
    let publisher = LaserPublisher::new(&service)?;
    for seq in 0..SUBSCRIBER_BUFFER as u64 {
        assert_eq!(publisher.publish(&make_frame(seq))?, 1);
    }
    for seq in 0..SUBSCRIBER_BUFFER as u64 {
        let f = sub.recv_timeout(WAIT)?.context("frame lost")?;
        check(&f, seq)?;
    }
    assert!(sub.try_recv()?.is_none());
    Ok(())
}

/// A controller of one's own opens the simulator's services and never creates them
/// (docs/wire-contract.md): none while there is no publisher, and after one, the
/// history frame first (handed over when the publisher next connects subscribers).
#[test]
fn an_open_only_subscriber_never_creates_the_service() -> Result<()> {
    let service = unique_service("openonly");
    ensure!(
        LaserSubscriber::open_existing(&service)?.is_none(),
        "opened a service no one created"
    );
    ensure!(
        LaserSubscriber::open_existing(&service)?.is_none(),
        "the first try created the service"
    );
    let publisher = LaserPublisher::new(&service)?;
    publisher.publish(&make_frame(7))?;
    let sub = LaserSubscriber::open_existing(&service)?.context("the publisher's service")?;
    publisher.update_connections()?;
    check(&sub.recv_timeout(WAIT)?.context("the history frame")?, 7)?;
    publisher.publish(&make_frame(8))?;
    check(&sub.recv_timeout(WAIT)?.context("frame 8")?, 8)?;
    Ok(())
}

#[test]
fn a_waiting_subscriber_wakes_when_a_frame_is_published() -> Result<()> {
    let service = unique_service("wake");
    let sub = LaserSubscriber::new(&service)?;
    let waiter = std::thread::spawn(move || sub.recv_timeout(WAIT));
    let publisher = LaserPublisher::new(&service)?;
    std::thread::sleep(Duration::from_millis(50));
    publisher.publish(&make_frame(42))?;
    let got = waiter
        .join()
        .map_err(|_| anyhow::anyhow!("waiter panicked"))??;
    check(&got.context("the waiter timed out")?, 42)
}

#[test]
fn recv_timeout_returns_none_when_nothing_is_published() -> Result<()> {
    let service = unique_service("silent");
    let sub = LaserSubscriber::new(&service)?;
    let _publisher = LaserPublisher::new(&service)?;
    assert!(sub.recv_timeout(Duration::from_millis(30))?.is_none());
    assert!(sub.try_recv()?.is_none());
    Ok(())
}

#[test]
fn a_late_subscriber_gets_the_latest_frame_from_history() -> Result<()> {
    let service = unique_service("late");
    let publisher = LaserPublisher::new(&service)?;
    for seq in 1..=5 {
        assert_eq!(publisher.publish(&make_frame(seq))?, 0);
    }
    let sub = LaserSubscriber::new(&service)?;
    publisher.update_connections()?;
    check(&sub.recv_timeout(WAIT)?.context("no history")?, 5)?;
    assert!(
        sub.try_recv()?.is_none(),
        "history holds only the latest frame"
    );
    publisher.publish(&make_frame(6))?;
    check(&sub.recv_timeout(WAIT)?.context("frame 6 lost")?, 6)?;

    // A subscriber that appears while frames keep coming gets the history, then the new
    // frame, without an explicit update_connections.
    let sub2 = LaserSubscriber::new(&service)?;
    publisher.publish(&make_frame(7))?;
    check(&sub2.recv_timeout(WAIT)?.context("no history")?, 6)?;
    check(&sub2.recv_timeout(WAIT)?.context("frame 7 lost")?, 7)?;
    Ok(())
}

#[test]
fn a_full_buffer_drops_the_oldest_frames() -> Result<()> {
    let service = unique_service("overflow");
    let sub = LaserSubscriber::new(&service)?;
    let publisher = LaserPublisher::new(&service)?;
    let n = SUBSCRIBER_BUFFER as u64 + 10;
    for seq in 0..n {
        publisher.publish(&make_frame(seq))?;
    }
    check(
        &sub.try_recv()?.context("empty")?,
        n - SUBSCRIBER_BUFFER as u64,
    )?;
    check(&sub.try_recv_latest()?.context("empty")?, n - 1)?;
    Ok(())
}

#[test]
fn the_publisher_refuses_malformed_frames() -> Result<()> {
    let service = unique_service("refuse");
    let publisher = LaserPublisher::new(&service)?;
    let mut f = make_frame(1);
    f.range_min = 30.0;
    assert!(matches!(
        publisher.publish(&f),
        Err(LaserError::RangeLimits { .. })
    ));
    Ok(())
}

#[test]
fn the_subscriber_refuses_malformed_frames_from_a_foreign_publisher() -> Result<()> {
    let service = unique_service("foreign");
    let sub = LaserSubscriber::new(&service)?;
    // A publisher that does not validate: raw iceoryx2 on the same service.
    let node = NodeBuilder::new().create::<ipc_threadsafe::Service>()?;
    let raw = node
        .service_builder(&ServiceName::new(&service)?)
        .publish_subscribe::<LaserFrame>()
        .open()?
        .publisher_builder()
        .create()?;
    let mut bad = make_frame(1);
    bad.version = 2;
    raw.send_copy(bad)?;
    raw.send_copy(make_frame(2))?;
    assert!(matches!(
        sub.try_recv(),
        Err(LaserError::WrongVersion {
            found: 2,
            expected: 1
        })
    ));
    check(
        &sub.try_recv()?
            .context("the good frame after the bad one")?,
        2,
    )?;
    Ok(())
}

#[test]
fn a_bad_service_name_is_refused() {
    assert!(matches!(
        LaserSubscriber::new(""),
        Err(LaserError::ServiceName { .. })
    ));
}

/// `ugv-laser-synth` publishing `service` (each frame to reach exactly one subscriber
/// when `expect_one`), its stdin and stdout piped.
fn synth(service: &str, expect_one: bool) -> Result<std::process::Child> {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_ugv-laser-synth"));
    cmd.arg(service);
    if expect_one {
        cmd.args(["--expect-subscribers", "1"]);
    }
    Ok(cmd.stdin(Stdio::piped()).stdout(Stdio::piped()).spawn()?)
}

/// Frames published by another process arrive in order and bit-identical. The parent
/// asks for them in batches on the publisher's stdin, so no frame can overflow the
/// subscriber's buffer however slow the machine.
#[test]
fn frames_cross_processes_in_order_and_intact() -> Result<()> {
    const BATCH: u64 = 8;
    const BATCHES: u64 = 25;
    let service = unique_service("xproc");
    let sub = LaserSubscriber::new(&service)?;
    let mut child = synth(&service, true)?;
    let mut to_child = child.stdin.take().context("child stdin")?;
    let from_child = BufReader::new(child.stdout.take().context("child stdout")?);
    // Drain the child's lines on a thread, so a full pipe never blocks it.
    let lines = std::thread::spawn(move || from_child.lines().map_while(Result::ok).count());
    let result = (|| -> Result<()> {
        for b in 0..BATCHES {
            for seq in b * BATCH..(b + 1) * BATCH {
                writeln!(to_child, "{seq} {}", beams_of(seq))?;
            }
            to_child.flush()?;
            for seq in b * BATCH..(b + 1) * BATCH {
                let f = sub
                    .recv_timeout(WAIT)?
                    .with_context(|| format!("frame {seq} did not arrive"))?;
                check(&f, seq)?;
            }
        }
        writeln!(to_child, "quit")?;
        Ok(())
    })();
    drop(to_child);
    let status = child.wait()?;
    let printed = lines
        .join()
        .map_err(|_| anyhow::anyhow!("line reader panicked"))?;
    result?;
    ensure!(status.success(), "child publisher failed: {status}");
    // "ready", then one "published N" per frame.
    ensure!(printed as u64 == 1 + BATCH * BATCHES, "{printed} lines");
    Ok(())
}

/// `ugv-laser-echo --json` in its own process receives what this process publishes.
#[test]
fn ugv_laser_echo_prints_frames_as_json_lines() -> Result<()> {
    let service = unique_service("echo");
    let publisher = LaserPublisher::new(&service)?;
    let mut echo = Command::new(env!("CARGO_BIN_EXE_ugv-laser-echo"))
        .args([&service, "--json", "--count", "3", "--timeout", "60"])
        .stdout(Stdio::piped())
        .spawn()?;
    let stdout = echo.stdout.take().context("echo stdout")?;
    let reader = std::thread::spawn(move || {
        BufReader::new(stdout)
            .lines()
            .collect::<std::io::Result<Vec<String>>>()
    });
    // Publish until the echo has had its three frames (it may connect at any point; the
    // first one it sees can be the history).
    let mut seq = 100;
    while echo.try_wait()?.is_none() && seq < 100 + 30_000 {
        publisher.publish(&make_frame(seq))?;
        seq += 1;
        std::thread::sleep(Duration::from_millis(2));
    }
    let status = echo.wait()?;
    ensure!(status.success(), "ugv-laser-echo failed: {status}");
    let lines = reader
        .join()
        .map_err(|_| anyhow::anyhow!("reader panicked"))??;
    ensure!(lines.len() == 3, "{lines:?}");
    let mut last = None;
    for line in &lines {
        let j: serde_json::Value = serde_json::from_str(line)?;
        let s = j["sequence"].as_u64().context("sequence")?;
        ensure!(last.is_none_or(|l| s > l), "out of order: {lines:?}");
        last = Some(s);
        let want = serde_json::to_string(&make_frame(s))?;
        ensure!(*line == want, "frame {s} differs:\n{line}\n{want}");
    }
    Ok(())
}

/// Nodes of process `pid` that iceoryx2 sees as dead (their resources still around).
fn dead_nodes_of(pid: u32) -> Result<usize> {
    let mut dead = 0;
    Node::<ipc_threadsafe::Service>::list(Config::global_config(), |state| {
        if let NodeState::Dead(view) = &state
            && let Some(details) = view.details()
            && i64::from(details.process_id().value()) == i64::from(pid)
        {
            dead += 1;
        }
        CallbackProgression::Continue
    })
    .map_err(|e| anyhow::anyhow!("listing nodes: {e:?}"))?;
    Ok(dead)
}

/// A publisher killed with SIGKILL leaves its node behind; the next endpoint on the
/// service removes it and the service works again.
#[test]
fn a_killed_publisher_is_cleaned_up_and_its_service_reused() -> Result<()> {
    let service = unique_service("crash");
    let mut child = synth(&service, false)?;
    let mut to_child = child.stdin.take().context("child stdin")?;
    let mut from_child = BufReader::new(child.stdout.take().context("child stdout")?).lines();
    let mut wait_for = |want: &str| from_child.any(|l| l.is_ok_and(|l| l == want));
    let published = wait_for("ready")
        && writeln!(to_child, "1 541")
            .and_then(|()| to_child.flush())
            .is_ok()
        && wait_for("published 1");
    child.kill()?;
    child.wait()?;
    ensure!(published, "the publisher never published its frame");

    let sub = LaserSubscriber::new(&service)?;
    ensure!(
        dead_nodes_of(child.id())? == 0,
        "the killed publisher's node is still registered"
    );
    let publisher = LaserPublisher::new(&service)?;
    publisher.publish(&make_frame(9))?;
    check(&sub.recv_timeout(WAIT)?.context("frame lost")?, 9)
}
