//! Sweeps and shards through the `ugv-sim` binary: the merged result of N shards is
//! byte-identical to the unsharded run (N = 1, 2, 3, 7, one of them chosen by a
//! Kubernetes Indexed Job's variables), merge refuses missing, doubled and foreign
//! items, and bad sweep arguments are refused by name.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use anyhow::{Context, Result, ensure};

const SUMMARIES: [&str; 3] = ["summary.md", "summary.json", "junit.xml"];

/// A small, fast suite: two scenarios cut to 1.5 simulated seconds at 50 Hz (the
/// paper's world, and an empty one), so a run takes a fraction of a second.
fn small_suite(dir: &Path) -> Result<PathBuf> {
    let suite = dir.join("suite");
    std::fs::create_dir_all(&suite)?;
    let short = "[sim]\ntime_limit_s = 1.5\nphysics_hz = 50.0\n";
    std::fs::write(
        suite.join("a.toml"),
        format!(
            "{}\n{short}",
            ugv_sim::scenario::PAPER_SCENARIO.replace("name = \"paper\"", "name = \"short-paper\"")
        ),
    )?;
    std::fs::write(
        suite.join("b.toml"),
        format!("name = \"short-empty\"\nobstacles = []\n\n[goal]\nx = 10.0\ny = 0.0\n\n{short}"),
    )?;
    Ok(suite)
}

fn ugv_sim(args: &[&str], env: &[(&str, &str)]) -> Result<Output> {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_ugv-sim"));
    cmd.args(args)
        .env_remove("JOB_COMPLETION_INDEX")
        .env_remove("JOB_COMPLETIONS");
    for (k, v) in env {
        cmd.env(k, v);
    }
    Ok(cmd.output()?)
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

const SWEEP: [&str; 6] = [
    "--seeds",
    "2",
    "--vary",
    "steering.dead_time_s=0.02,0.1",
    "--jobs",
    "2",
];

fn suite_run(suite: &Path, results: &Path, extra: &[&str], env: &[(&str, &str)]) -> Result<Output> {
    let mut args = vec!["suite", suite.to_str().context("path")?, "--results"];
    args.push(results.to_str().context("path")?);
    args.extend(SWEEP);
    args.extend(extra);
    let out = ugv_sim(&args, env)?;
    // 0: all passed, 1: some failed, 5: some ran out of time; anything else is an error.
    ensure!(
        matches!(out.status.code(), Some(0 | 1 | 5)),
        "{:?}: {}",
        out.status,
        stderr(&out)
    );
    Ok(out)
}

fn items(dir: &Path) -> Result<serde_json::Value> {
    Ok(serde_json::from_str(&std::fs::read_to_string(
        dir.join("items.json"),
    )?)?)
}

#[test]
fn merged_shards_are_byte_identical_to_the_unsharded_run() -> Result<()> {
    let tmp = tempfile::tempdir()?;
    let suite = small_suite(tmp.path())?;
    let whole = tmp.path().join("whole");
    suite_run(&suite, &whole, &[], &[])?;
    let all = items(&whole)?;
    let total = all["plan"]["items"].as_array().context("plan items")?.len();
    assert_eq!(total, 2 * 2 * 2, "2 scenarios x 2 grid points x 2 seeds");
    let md = std::fs::read_to_string(whole.join("summary.md"))?;
    assert!(md.contains("## Per scenario and grid point"), "{md}");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(whole.join("summary.json"))?)?;
    let groups = summary["groups"].as_array().context("groups")?;
    assert_eq!(groups.len(), 4);
    assert!(groups.iter().all(|g| g["runs"] == 2), "{groups:?}");

    for n in [1usize, 2, 3, 7] {
        let mut dirs = Vec::new();
        let mut seen = Vec::new();
        for i in 0..n {
            let dir = tmp.path().join(format!("shard-{n}-{i}"));
            let (index, count) = (i.to_string(), n.to_string());
            if n == 3 {
                // As a Kubernetes Indexed Job runs it: the shard from the environment.
                suite_run(
                    &suite,
                    &dir,
                    &[],
                    &[
                        ("JOB_COMPLETION_INDEX", &index),
                        ("JOB_COMPLETIONS", &count),
                    ],
                )?;
            } else {
                suite_run(&suite, &dir, &["--shard", &format!("{i}/{n}")], &[])?;
            }
            let shard = items(&dir)?;
            assert_eq!(shard["shard"]["index"], i);
            assert_eq!(shard["shard"]["count"], n);
            for item in shard["items"].as_array().context("items")? {
                seen.push(item["record"]["index"].as_u64().context("index")?);
            }
            dirs.push(dir);
        }
        seen.sort_unstable();
        assert_eq!(
            seen,
            (0..total as u64).collect::<Vec<_>>(),
            "{n} shards cover every item once"
        );
        let out = tmp.path().join(format!("merged-{n}"));
        let mut args = vec!["merge".to_owned()];
        args.extend(dirs.iter().map(|d| d.display().to_string()));
        args.extend(["--out".to_owned(), out.display().to_string()]);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let merged = ugv_sim(&args, &[])?;
        assert!(
            matches!(merged.status.code(), Some(0 | 1 | 5)),
            "{}",
            stderr(&merged)
        );
        for f in SUMMARIES {
            let a = std::fs::read(whole.join(f))?;
            let b = std::fs::read(out.join(f))?;
            assert!(
                a == b,
                "{n} shards: merged {f} differs from the unsharded run's"
            );
        }
    }
    Ok(())
}

#[test]
fn merge_refuses_missing_doubled_and_foreign_items() -> Result<()> {
    let tmp = tempfile::tempdir()?;
    let suite = small_suite(tmp.path())?;
    let shard = |i: usize, extra: &[&str]| -> Result<PathBuf> {
        let dir = tmp.path().join(format!("s{i}-{}", extra.len()));
        let spec = format!("{i}/3");
        let mut args = vec!["--shard", spec.as_str()];
        args.extend(extra);
        suite_run(&suite, &dir, &args, &[])?;
        Ok(dir)
    };
    let (s0, s1) = (shard(0, &[])?, shard(1, &[])?);
    let other = shard(
        2,
        &[
            "--follower",
            "optimal",
            "--vary",
            "throttle.dead_time_s=0.1",
        ],
    )?;
    let merge = |dirs: &[&PathBuf]| -> Result<String> {
        let mut args = vec!["merge".to_owned()];
        args.extend(dirs.iter().map(|d| d.display().to_string()));
        args.extend([
            "--out".to_owned(),
            tmp.path().join("m").display().to_string(),
        ]);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let out = ugv_sim(&args, &[])?;
        ensure!(out.status.code() == Some(4), "{:?}", out.status);
        Ok(stderr(&out))
    };
    let missing = merge(&[&s0, &s1])?;
    assert!(missing.contains("items are in no shard file"), "{missing}");
    assert!(missing.contains("shards given: 0/3"), "{missing}");
    let doubled = merge(&[&s0, &s1, &s0])?;
    assert!(doubled.contains("is in both"), "{doubled}");
    let foreign = merge(&[&s0, &other])?;
    assert!(foreign.contains("a shard of another sweep"), "{foreign}");
    assert!(foreign.contains("the --vary settings differ"), "{foreign}");
    let nothing = merge(&[&tmp.path().join("nowhere")])?;
    assert!(nothing.contains("a shard's items.json"), "{nothing}");
    Ok(())
}

#[test]
fn bad_sweep_arguments_are_refused_by_name() -> Result<()> {
    let tmp = tempfile::tempdir()?;
    let suite = small_suite(tmp.path())?;
    let dir = suite.to_str().context("path")?;
    for (args, env, code, says) in [
        (
            vec!["--vary", "steering.dead_tim_s=0.1"],
            vec![],
            4,
            "--vary steering.dead_tim_s=0.1: ",
        ),
        (
            vec!["--vary", "steering.dead_time_s=0:9:3"],
            vec![],
            4,
            "steering.dead_time_s: must be within [0, 5] s, is 6",
        ),
        (
            vec!["--vary", "steering.dead_time_s"],
            vec![],
            2,
            "is not KEY=SPEC",
        ),
        (vec!["--shard", "2/2"], vec![], 2, "0-based"),
        (vec!["--seeds", "0"], vec![], 2, "--seeds"),
        (
            vec![],
            vec![("JOB_COMPLETION_INDEX", "1")],
            4,
            "JOB_COMPLETIONS is not",
        ),
    ] {
        let mut all = vec!["suite", dir, "--results"];
        let results = tmp.path().join("r");
        all.push(results.to_str().context("path")?);
        all.extend(&args);
        let out = ugv_sim(&all, &env)?;
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(code), "{args:?}: {err}");
        assert!(err.contains(says), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{err}");
    }
    Ok(())
}

/// `ugv-sim merge` of `inputs` into `out`: its exit code and stderr, killed (and an
/// error) if it takes over a minute (a FIFO given as items.json used to hang it).
fn merge_into(inputs: &[&Path], out: &Path) -> Result<(Option<i32>, String)> {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_ugv-sim"));
    cmd.arg("merge")
        .args(inputs)
        .arg("--out")
        .arg(out)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped());
    let mut child = cmd.spawn()?;
    let started = std::time::Instant::now();
    while child.try_wait()?.is_none() {
        if started.elapsed() > std::time::Duration::from_secs(60) {
            child.kill()?;
            child.wait()?;
            anyhow::bail!("merge of {inputs:?} still running after a minute");
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    let out = child.wait_with_output()?;
    Ok((out.status.code(), stderr(&out)))
}

/// A copy of the shard folder `from` as `to`, its items.json changed by `edit`.
fn edited(from: &Path, to: &Path, edit: impl Fn(&mut serde_json::Value)) -> Result<PathBuf> {
    std::fs::create_dir_all(to)?;
    let mut json = items(from)?;
    edit(&mut json);
    std::fs::write(to.join("items.json"), serde_json::to_string_pretty(&json)?)?;
    Ok(to.to_path_buf())
}

#[test]
fn merge_refuses_bad_shard_headers_forged_fields_fifos_and_its_own_inputs() -> Result<()> {
    let tmp = tempfile::tempdir()?;
    let suite = small_suite(tmp.path())?;
    let run = |name: &str, shard: &str| -> Result<PathBuf> {
        let dir = tmp.path().join(name);
        suite_run(&suite, &dir, &["--shard", shard], &[])?;
        Ok(dir)
    };
    let s: Vec<PathBuf> = (0..3)
        .map(|i| run(&format!("s{i}"), &format!("{i}/3")))
        .collect::<Result<_>>()?;
    let out = tmp.path().join("merged");
    let (code, err) = merge_into(&[&s[0], &s[1], &s[2]], &out)?;
    ensure!(matches!(code, Some(0 | 1 | 5)), "the good merge: {err}");
    let refused = |inputs: &[&Path], says: &str| -> Result<()> {
        let (code, err) = merge_into(inputs, &out)?;
        ensure!(code == Some(4), "{inputs:?}: exit {code:?}: {err}");
        ensure!(err.contains(says), "{inputs:?}\n got: {err}\nwant: {says}");
        Ok(())
    };
    let edit = |name: &str, edit: &dyn Fn(&mut serde_json::Value)| {
        edited(&s[2], &tmp.path().join(name), edit)
    };
    // A shard header no --shard would be, and unknown fields.
    let past = edit("past", &|j| j["shard"]["index"] = 5.into())?;
    refused(
        &[&s[0], &s[1], &past],
        "not a shard's items.json: shard 5/3: the shard index is 0-based (like JOB_COMPLETION_INDEX): 0 to 2, is 5",
    )?;
    let zero = edit("zero", &|j| {
        j["shard"] = serde_json::json!({"index": 0, "count": 0})
    })?;
    refused(
        &[&zero],
        "shard 0/0: the shard count must be 1 to 100000, is 0",
    )?;
    let extra = edit("extra", &|j| j["plan"]["note"] = "x".into())?;
    refused(&[&s[0], &s[1], &extra], "unknown field `note`")?;
    // Forged fields: the plan edited, an item's verdict flipped.
    let seeds = edit("seeds", &|j| j["plan"]["seeds"] = 3.into())?;
    refused(
        &[&s[0], &s[1], &seeds],
        "items.json: its plan does not match its fingerprint",
    )?;
    let flipped = edit("flipped", &|j| {
        let r = &mut j["items"][0]["record"];
        r["passed"] = (!r["passed"].as_bool().unwrap_or(false)).into();
    })?;
    refused(&[&s[0], &s[1], &flipped], "but the outcome is")?;
    // Shards of one split only, each once; and all of them.
    let two = run("two", "1/2")?;
    refused(
        &[&s[0], &s[1], &two],
        "is shard 1/2 and", // of a split of 3
    )?;
    let whole = run("whole", "0/1")?;
    let half = edited(&whole, &tmp.path().join("half"), |j| {
        j["shard"] = serde_json::json!({"index": 0, "count": 2});
    })?;
    refused(&[&half], "shards 1 of 2 are missing")?;
    // A shard of the same files, names and items, one of whose contents changed.
    let a = suite.join("a.toml");
    let text = std::fs::read_to_string(&a)?;
    std::fs::write(&a, text.replace("physics_hz = 50.0", "physics_hz = 40.0"))?;
    let changed = run("changed", "2/3")?;
    refused(
        &[&s[0], &s[1], &changed],
        "is a shard of another sweep than",
    )?;
    refused(
        &[&s[0], &s[1], &changed],
        "the scenarios (a file's contents) differ",
    )?;
    // A FIFO as items.json: refused at once, not waited on.
    let fifo = tmp.path().join("fifo");
    std::fs::create_dir_all(&fifo)?;
    let made = Command::new("mkfifo")
        .arg(fifo.join("items.json"))
        .status()?;
    ensure!(made.success(), "mkfifo");
    refused(&[&s[0], &fifo], "items.json is a FIFO, not a regular file")?;
    // --out one of the inputs' folders.
    let (code, err) = merge_into(&[&s[0], &s[1], &s[2]], &s[1])?;
    ensure!(code == Some(4), "exit {code:?}: {err}");
    ensure!(err.contains("is the folder of the shard"), "{err}");
    let (code, err) = merge_into(&[&s[0], &s[1], &s[2].join("items.json")], &s[2])?;
    ensure!(
        code == Some(4) && err.contains("the merge would overwrite it"),
        "{err}"
    );
    Ok(())
}

#[test]
fn a_value_given_twice_is_refused() -> Result<()> {
    let tmp = tempfile::tempdir()?;
    let suite = small_suite(tmp.path())?;
    let results = tmp.path().join("r");
    let out = ugv_sim(
        &[
            "suite",
            suite.to_str().context("path")?,
            "--results",
            results.to_str().context("path")?,
            "--vary",
            "steering.dead_time_s=0.1,0.1",
            "--list",
        ],
        &[],
    )?;
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("steering.dead_time_s: the value 0.1 is given twice"),
        "{err}"
    );
    Ok(())
}
