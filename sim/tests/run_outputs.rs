//! What `ugv-sim run --sil` writes into its results directory, and what
//! `--no-figures` and `--no-record` leave out (issue 37 item 6): the verdict and the
//! traces are written either way.

use std::path::Path;
use std::process::Command;

/// The files a run's results directory holds after `ugv-sim run --sil` with `args`
/// (a 2 s run of the paper's scenario), sorted.
fn outputs(dir: &Path, args: &[&str]) -> std::io::Result<Vec<String>> {
    let results = dir.join("results");
    let out = Command::new(env!("CARGO_BIN_EXE_ugv-sim"))
        .args(["run", "--sil", "--time-limit", "2", "--results"])
        .arg(&results)
        .args(args)
        .current_dir(dir)
        .output()?;
    // Exit 5: the time limit ended the run (its verdict written all the same).
    assert_eq!(
        out.status.code(),
        Some(5),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mut names = std::fs::read_dir(&results)?
        .map(|e| e.map(|e| e.file_name().to_string_lossy().into_owned()))
        .collect::<std::io::Result<Vec<_>>>()?;
    names.sort();
    Ok(names)
}

#[test]
fn no_figures_skips_the_figure_and_keeps_the_verdict_and_traces() -> std::io::Result<()> {
    let all = tempfile::tempdir()?;
    assert_eq!(
        outputs(all.path(), &[])?,
        [
            "bus.log",
            "figure.png",
            "figure.svg",
            "gps.nmea",
            "run.mcap",
            "trace.json",
            "training.csv",
            "verdict.json"
        ],
        "by default a run writes its results, its figure and its recording"
    );

    let bare = tempfile::tempdir()?;
    assert_eq!(
        outputs(bare.path(), &["--no-figures", "--no-record"])?,
        ["trace.json", "training.csv", "verdict.json"]
    );
    let verdict: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(
        bare.path().join("results/verdict.json"),
    )?)?;
    assert_eq!(verdict["passed"], false, "the time limit fails the run");

    let drawn = tempfile::tempdir()?;
    assert_eq!(
        outputs(drawn.path(), &["--no-record"])?,
        [
            "figure.png",
            "figure.svg",
            "trace.json",
            "training.csv",
            "verdict.json"
        ]
    );
    Ok(())
}
