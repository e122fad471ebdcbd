//! The `ugv-controller` binary on its command line: numbers in the arguments of
//! `anfis train` never panic or abort (capacity overflow, allocation failure); they are
//! refused with the argument and its range named (issue 11, item 8).

// Helpers outside #[test] functions unwrap and panic as the tests do.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::process::Command;

/// `ugv-controller anfis train` on a small valid data set with `extra` arguments: the
/// exit code (None: killed by a signal, as an allocation abort is) and stderr.
fn train(dir: &std::path::Path, extra: &[&str]) -> (Option<i32>, String) {
    let data = dir.join("train.csv");
    let mut csv = String::from("e_y,e_theta,phi_ref,steer_cmd\n");
    for k in 0..20 {
        let x = f64::from(k) / 10.0 - 1.0;
        csv.push_str(&format!("{x},{},{},{}\n", x * 0.5, -x, x * 0.3));
    }
    std::fs::write(&data, csv).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_ugv-controller"))
        .args(["anfis", "train", "--data"])
        .arg(&data)
        .arg("--output")
        .arg(dir.join("model.json"))
        .args(extra)
        .output()
        .unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn anfis_train_huge_epochs_and_mfs_are_refused_not_a_panic_or_an_abort() {
    let dir = tempfile::tempdir().unwrap();
    let cases: [(&[&str], &str, &str); 9] = [
        (
            &["--epochs", "18446744073709551615"],
            "--epochs",
            "1 to 100000",
        ),
        (&["--epochs", "1000000000000"], "--epochs", "1 to 100000"),
        (&["--epochs", "0"], "--epochs", "1 to 100000"),
        (&["--mfs", "100000,100000,100000"], "--mfs", "1 to 32"),
        (&["--mfs", "100000"], "--mfs", "1 to 32"),
        (&["--mfs", "11"], "--mfs", "at most 1024"),
        (&["--step-size", "1e300"], "--step-size", "more than 1"),
        (&["--step-size", "NaN"], "--step-size", "positive"),
        (
            &["--epochs", "99999999999999999999999"],
            "--epochs",
            "invalid value",
        ),
    ];
    for (extra, argument, range) in cases {
        let (code, stderr) = train(dir.path(), extra);
        assert!(
            matches!(code, Some(c) if c != 0 && c != 101),
            "{extra:?}: exit {code:?}: {stderr}"
        );
        assert!(!stderr.contains("panicked"), "{extra:?}: {stderr}");
        assert!(stderr.contains(argument), "{extra:?}: {stderr}");
        assert!(stderr.contains(range), "{extra:?}: {stderr}");
    }
    assert!(!dir.path().join("model.json").exists(), "nothing written");
    // Within the bounds it trains.
    let (code, stderr) = train(dir.path(), &["--mfs", "2", "--epochs", "3"]);
    assert_eq!(code, Some(0), "{stderr}");
}

/// `run`'s output flags say what they write (issue 33): `--record DIR` the recording of
/// its ports (`--log DIR`, its old name, still taken, out of the help),
/// `--training-csv FILE` the ANFIS training data; a `--record` given a CSV file, what
/// it wrote before, is refused at parse time with a pointer to `--training-csv`.
#[test]
fn run_names_the_recording_record_and_the_training_data_training_csv() {
    let run = |args: &[&str]| {
        let out = Command::new(env!("CARGO_BIN_EXE_ugv-controller"))
            .arg("run")
            .args(args)
            .output()
            .unwrap();
        (
            out.status.code(),
            String::from_utf8_lossy(&out.stdout).into_owned(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    };
    let (code, help, _) = run(&["--help"]);
    assert_eq!(code, Some(0));
    assert!(help.contains("--record <DIR>"), "{help}");
    assert!(help.contains("--training-csv <FILE>"), "{help}");
    assert!(!help.contains("--log"), "{help}");
    let wires = ["--gps", "/nonexistent/gps", "--laser", "x"];
    let (code, _, stderr) = run(&[&wires[..], &["--record", "train.csv"]].concat());
    assert_eq!(code, Some(2), "{stderr}");
    assert!(
        stderr.contains("train.csv") && stderr.contains("--training-csv FILE"),
        "{stderr}"
    );
    // The old name parses (and the run then fails later, on the GPS device).
    for args in [["--log", "rec"], ["--record", "rec"]] {
        let (code, _, stderr) = run(&[&wires[..], &args].concat());
        assert!(
            !stderr.contains("unexpected argument") && code != Some(2),
            "{args:?}: {code:?} {stderr}"
        );
    }
}
