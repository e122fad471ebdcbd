//! The controller's trace is written while it drives (issue 11, finding 3: it was
//! written only at a clean exit, so SIGKILL or a crash left nothing).

// Helpers outside #[test] functions unwrap and panic as the tests do.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::io::Write;

use ugv_controller::config::ControllerConfig;
use ugv_controller::control::{Controller, Sample};
use ugv_controller::guidance::FollowInputs;
use ugv_controller::localisation::Pose;
use ugv_controller::trace::{TRACE_FLUSH_PERIOD, Trace, TraceWriter};

fn sample(t: f64) -> Sample {
    Sample {
        t,
        pose: Pose {
            x: t,
            y: 0.0,
            theta: 0.0,
            v: 2.0,
            phi: 0.0,
        },
        inputs: FollowInputs {
            e_y: 0.1,
            e_theta: 0.0,
            phi_ref: 0.0,
            v: 2.0,
        },
        steer_cmd: 0.01 * t,
        speed_cmd: 2.0,
    }
}

/// The controller's 10 ms loop for `seconds`, a sample per tick, the writer updated
/// every tick as the runtime does.
fn drive<W: Write>(ctl: &mut Controller, w: &mut TraceWriter<W>, from: f64, seconds: f64) {
    let ticks = (seconds / 0.01).round() as usize;
    for i in 0..ticks {
        let t = from + i as f64 * 0.01;
        ctl.samples.push(sample(t));
        w.update(t, ctl, &[]).expect("write");
    }
}

#[test]
fn a_killed_controller_leaves_its_trace_up_to_its_last_second() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (path, csv) = (dir.path().join("trace.jsonl"), dir.path().join("train.csv"));
    let mut ctl = Controller::new(&ControllerConfig::default()).expect("controller");
    let mut w = TraceWriter::new(
        Some(std::fs::File::create(&path).expect("trace")),
        Some(std::fs::File::create(&csv).expect("csv")),
    )
    .expect("writer");
    drive(&mut ctl, &mut w, 0.0, 5.5);
    // SIGKILL: no destructor runs, nothing buffered is flushed.
    std::mem::forget(w);
    let text = std::fs::read_to_string(&path).expect("read");
    let trace = Trace::from_jsonl(&text).expect("a readable trace");
    let last = trace.samples.last().map(|s| s.t).expect("samples");
    assert!(
        last >= 5.49 - TRACE_FLUSH_PERIOD,
        "the last second at most is lost: {last}"
    );
    assert!(trace.duration >= 4.5, "{}", trace.duration);
    let rows = std::fs::read_to_string(&csv).expect("csv").lines().count();
    assert!(rows > 400, "training rows on disk: {rows}");
}

#[test]
fn a_trace_cut_mid_line_reads_up_to_the_cut() {
    let mut ctl = Controller::new(&ControllerConfig::default()).expect("controller");
    let mut buf = Vec::new();
    {
        let mut w = TraceWriter::new(Some(&mut buf), None).expect("writer");
        drive(&mut ctl, &mut w, 0.0, 2.0);
        w.finish(2.0, &ctl, &[]).expect("finish");
    }
    let text = String::from_utf8(buf).expect("utf-8");
    let whole = Trace::from_jsonl(&text).expect("whole");
    assert_eq!(whole.samples.len(), 200);
    assert_eq!(whole.duration, 2.0);
    assert_eq!(&whole.mode, ctl.mode());
    let tr = Trace::of(&ctl, 2.0);
    assert!((whole.tracking_error_rms - tr.tracking_error_rms).abs() < 1e-12);
    // Killed while writing its last line.
    let cut = &text[..text.len() - 7];
    let partial = Trace::from_jsonl(cut).expect("a cut last line is dropped");
    assert!(partial.samples.len() >= 199, "{}", partial.samples.len());
    // A bad line elsewhere is an error that names it.
    let broken = text.replacen("{\"sample\"", "{\"sampel\"", 1);
    let e = Trace::from_jsonl(&broken)
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(e.starts_with("trace line 1:"), "{e}");
}

#[test]
fn a_full_disk_does_not_stop_the_writer_from_reporting_it() {
    struct Full;
    impl Write for Full {
        fn write(&mut self, _: &[u8]) -> std::io::Result<usize> {
            Err(std::io::Error::other("no space left on device"))
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }
    let mut ctl = Controller::new(&ControllerConfig::default()).expect("controller");
    let mut w = TraceWriter::new(Some(Full), None).expect("writer");
    ctl.samples.push(sample(0.0));
    let e = w.update(0.0, &ctl, &[]).expect_err("an error");
    assert!(e.to_string().contains("no space"), "{e}");
}
