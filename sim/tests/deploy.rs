//! The deploy files agree with `ugv-sim`: the Kubernetes manifest validates against
//! the API models and its indices run every item of its sweep exactly once; the
//! GitHub Actions workflow's matrix does the same with `--shard` and its merge job
//! reads what the shards upload; the Dockerfile builds packages and copies binaries
//! and folders that exist, and its default command is a suite `ugv-sim` accepts.
//! (No Docker daemon here: the image itself is not built by the tests.)

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{Context, Result, bail, ensure};
use serde_json::Value;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_default()
}

/// deploy_check.py's JSON for `what` on `file`.
fn check(what: &str, file: &Path) -> Result<Value> {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/deploy_check.py");
    let out = Command::new("python3")
        .arg(&script)
        .arg(what)
        .arg(file)
        .output()
        .context("python3 (scripts/install-deps.sh installs kubernetes and pyyaml)")?;
    ensure!(
        out.status.success(),
        "{} {what}: {}",
        file.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    Ok(serde_json::from_slice(&out.stdout)?)
}

/// The item ids `ugv-sim suite ARGS --list` prints with `env`.
fn listed(args: &[String], env: &[(&str, &str)]) -> Result<Vec<String>> {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_ugv-sim"));
    cmd.args(args)
        .arg("--list")
        .env_remove("JOB_COMPLETION_INDEX")
        .env_remove("JOB_COMPLETIONS")
        .current_dir(repo());
    for (k, v) in env {
        cmd.env(k, v);
    }
    let out = cmd.output()?;
    ensure!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    Ok(String::from_utf8(out.stdout)?
        .lines()
        .map(str::to_owned)
        .collect())
}

/// Every id of `all` is in exactly one of `shards`.
fn exactly_once(all: &[String], shards: &[Vec<String>]) -> Result<()> {
    let mut count: BTreeMap<&str, usize> = all.iter().map(|id| (id.as_str(), 0)).collect();
    for id in shards.iter().flatten() {
        *count
            .get_mut(id.as_str())
            .with_context(|| format!("{id} is not an item of the sweep"))? += 1;
    }
    let wrong: Vec<_> = count.iter().filter(|(_, n)| **n != 1).collect();
    ensure!(wrong.is_empty(), "items not run exactly once: {wrong:?}");
    ensure!(!all.is_empty(), "the sweep has no items");
    Ok(())
}

/// The image's folder of scenarios, as the Dockerfile copies it: (in the image, in
/// the repository).
fn image_scenarios() -> Result<(String, String)> {
    let docker = std::fs::read_to_string(repo().join("deploy/Dockerfile"))?;
    let copy = docker
        .lines()
        .find(|l| l.starts_with("COPY sim/scenarios "))
        .context("the Dockerfile copies sim/scenarios")?;
    let mut words = copy.split_whitespace().skip(1);
    let (src, dst) = (words.next(), words.next());
    Ok((
        dst.context("COPY's destination")?.to_owned(),
        src.context("COPY's source")?.to_owned(),
    ))
}

/// `args` with the image's scenario folder replaced by the repository's.
fn in_repo(args: &[String]) -> Result<Vec<String>> {
    let (image, here) = image_scenarios()?;
    Ok(args.iter().map(|a| a.replacen(&image, &here, 1)).collect())
}

/// The workspace's `rust-version`.
fn rust_version() -> Result<String> {
    let workspace = std::fs::read_to_string(repo().join("Cargo.toml"))?;
    Ok(workspace
        .lines()
        .find_map(|l| l.strip_prefix("rust-version = "))
        .context("rust-version")?
        .trim_matches('"')
        .to_owned())
}

fn strings(v: &Value) -> Result<Vec<String>> {
    v.as_array()
        .context("a list")?
        .iter()
        .map(|s| s.as_str().map(str::to_owned).context("a string"))
        .collect()
}

fn env_value(container: &Value, name: &str) -> Option<String> {
    container["env"]
        .as_array()?
        .iter()
        .find(|e| e["name"] == name)
        .and_then(|e| e["value"].as_str().map(str::to_owned))
}

#[test]
fn the_indexed_job_validates_and_its_indices_run_every_item_once() -> Result<()> {
    let k8s = check("k8s", &repo().join("deploy/k8s/suite-job.yaml"))?;
    assert_eq!(
        k8s["kinds"],
        serde_json::json!(["PersistentVolumeClaim", "Job", "Job"])
    );
    let objects = k8s["objects"].as_array().context("objects")?;
    let claim = objects[0]["metadata"]["name"].as_str().context("claim")?;
    let suite = &objects[1]["spec"];
    assert_eq!(suite["completionMode"], "Indexed");
    let completions = suite["completions"].as_u64().context("completions")?;
    let parallelism = suite["parallelism"].as_u64().context("parallelism")?;
    assert!((1..=completions).contains(&parallelism), "{parallelism}");
    let pod = &suite["template"]["spec"];
    let shard = &pod["containers"][0];
    assert_eq!(
        env_value(shard, "JOB_COMPLETIONS"),
        Some(completions.to_string()),
        "JOB_COMPLETIONS is the Job's completions"
    );
    // The results volume is the manifest's claim, mounted where --results points.
    assert_eq!(
        pod["volumes"][0]["persistentVolumeClaim"]["claimName"],
        claim
    );
    let mount = shard["volumeMounts"][0]["mountPath"]
        .as_str()
        .context("mount")?;
    // `sh -c 'ugv-sim suite "$@" ...' NAME ARGS...`: the args are the suite's.
    let command = strings(&shard["command"])?;
    assert!(
        command[2].starts_with("ugv-sim suite \"$@\""),
        "{command:?}"
    );
    let args = in_repo(&strings(&shard["args"])?)?;
    let results = args
        .iter()
        .skip_while(|a| *a != "--results")
        .nth(1)
        .context("--results")?;
    assert!(
        results.starts_with(mount),
        "{results} is on the volume {mount}"
    );
    let mut suite_args = vec!["suite".to_owned()];
    suite_args.extend(args.iter().cloned());
    let all = listed(&suite_args, &[])?;
    let n = completions.to_string();
    let mut shards = Vec::new();
    for i in 0..completions {
        let index = i.to_string();
        let expanded: Vec<String> = suite_args
            .iter()
            .map(|a| a.replace("$(JOB_COMPLETION_INDEX)", &index))
            .collect();
        shards.push(listed(
            &expanded,
            &[("JOB_COMPLETION_INDEX", &index), ("JOB_COMPLETIONS", &n)],
        )?);
    }
    exactly_once(&all, &shards)?;
    assert!(shards.iter().all(|s| !s.is_empty()), "no index idles");

    // The merge Job waits for as many shards, and merges the folders they write.
    let merge = &objects[2]["spec"]["template"]["spec"];
    let container = &merge["containers"][0];
    assert_eq!(env_value(container, "JOB_COMPLETIONS"), Some(n.clone()));
    assert_eq!(
        merge["volumes"][0]["persistentVolumeClaim"]["claimName"],
        claim
    );
    let script = strings(&container["command"])?.join(" ");
    let glob = results.replace("$(JOB_COMPLETION_INDEX)", "*");
    assert!(
        script.contains(&format!("ugv-sim merge {glob} --out")),
        "{script}"
    );
    assert!(script.contains(&format!("{glob}/items.json")), "{script}");
    Ok(())
}

/// The steps of the workflow's job `job`.
fn steps(jobs: &Value, job: &str) -> Result<Vec<Value>> {
    Ok(jobs[job]["steps"].as_array().context("steps")?.clone())
}

/// The command of the first step of job `job` that runs `what`.
fn run_line(jobs: &Value, job: &str, what: &str) -> Result<String> {
    steps(jobs, job)?
        .iter()
        .filter_map(|s| s["run"].as_str())
        .find(|r| r.contains(what))
        .map(str::to_owned)
        .with_context(|| format!("a {job} step runs {what}"))
}

/// The merge job needs the shards, runs when they failed scenarios, downloads every
/// shard's artifact (uploaded as `uploads`) into a folder of its own and merges them all.
fn the_merge_reads_every_shard(jobs: &Value, uploads: &[String]) -> Result<()> {
    let merge = &jobs["merge"];
    assert_eq!(merge["needs"], "suite");
    assert!(
        merge["if"]
            .as_str()
            .is_some_and(|c| c.contains("!cancelled()")),
        "{}",
        merge["if"]
    );
    let download = steps(jobs, "merge")?
        .into_iter()
        .find(|s| s["with"]["pattern"].is_string())
        .context("the merge downloads the shards by pattern")?;
    let pattern = download["with"]["pattern"].as_str().context("pattern")?;
    let prefix = pattern.strip_suffix('*').context("a prefix pattern")?;
    assert!(
        uploads.iter().all(|u| u.starts_with(prefix)),
        "{uploads:?} {pattern}"
    );
    assert!(
        !download["with"]["merge-multiple"]
            .as_bool()
            .unwrap_or(false),
        "each shard in a folder of its own"
    );
    let dir = download["with"]["path"].as_str().context("path")?;
    let line = run_line(jobs, "merge", "ugv-sim merge")?;
    assert!(line.contains(&format!("merge {dir}/* --out")), "{line}");
    Ok(())
}

#[test]
fn the_workflow_matrix_runs_every_item_once_and_the_merge_reads_every_shard() -> Result<()> {
    let wf = check("workflow", &repo().join(".github/workflows/suite.yml"))?;
    let jobs = &wf["jobs"];
    let matrix: Vec<u64> = jobs["suite"]["strategy"]["matrix"]["shard"]
        .as_array()
        .context("matrix.shard")?
        .iter()
        .filter_map(Value::as_u64)
        .collect();
    // The build uses the workspace's toolchain.
    let toolchain = steps(jobs, "build")?
        .iter()
        .find_map(|s| s["with"]["toolchain"].as_str().map(str::to_owned))
        .context("the build job names its toolchain")?;
    assert_eq!(toolchain, rust_version()?);
    let suite = run_line(jobs, "suite", "ugv-sim suite")?;
    // The matrix value as one word (the expression has spaces).
    const SHARD: &str = "${{ matrix.shard }}";
    let words: Vec<String> = suite
        .replace(SHARD, "{SHARD}")
        .split_whitespace()
        .map(str::to_owned)
        .collect();
    let shard = words
        .iter()
        .skip_while(|w| *w != "--shard")
        .nth(1)
        .context("--shard")?;
    let count: u64 = shard
        .strip_prefix("{SHARD}/")
        .with_context(|| format!("--shard {shard}: the matrix value, then /N"))?
        .parse()
        .with_context(|| format!("--shard {shard}: N is not a number"))?;
    assert_eq!(matrix, (0..count).collect::<Vec<_>>(), "the matrix is 0..N");

    let args = words
        .iter()
        .skip_while(|w| !w.ends_with("ugv-sim"))
        .skip(1)
        .cloned()
        .collect::<Vec<_>>();
    let unsharded: Vec<String> = {
        let mut a = args.clone();
        let at = a.iter().position(|w| w == "--shard").context("--shard")?;
        a.drain(at..at + 2);
        a
    };
    let all = listed(&unsharded, &[])?;
    let mut shards = Vec::new();
    let mut uploads = Vec::new();
    for i in &matrix {
        let sub = |s: &str| {
            s.replace(SHARD, "{SHARD}")
                .replace("{SHARD}", &i.to_string())
        };
        shards.push(listed(
            &args.iter().map(|a| sub(a)).collect::<Vec<_>>(),
            &[],
        )?);
        let upload = steps(jobs, "suite")?
            .into_iter()
            .find(|s| {
                s["uses"]
                    .as_str()
                    .is_some_and(|u| u.starts_with("actions/upload-artifact"))
            })
            .context("the shard uploads its results")?;
        let results = args
            .iter()
            .skip_while(|a| *a != "--results")
            .nth(1)
            .context("--results")?;
        assert_eq!(upload["with"]["path"].as_str().map(sub), Some(sub(results)));
        uploads.push(sub(upload["with"]["name"].as_str().context("name")?));
    }
    exactly_once(&all, &shards)?;

    the_merge_reads_every_shard(jobs, &uploads)
}

#[test]
fn the_dockerfile_builds_and_copies_what_exists_and_runs_a_valid_suite() -> Result<()> {
    let docker = std::fs::read_to_string(repo().join("deploy/Dockerfile"))?;
    let lines: Vec<&str> = docker.lines().filter(|l| !l.starts_with('#')).collect();
    // The toolchain is the workspace's rust-version.
    let version = rust_version()?;
    assert!(
        lines
            .iter()
            .any(|l| l.starts_with(&format!("FROM rust:{version}-"))),
        "FROM rust:{version}"
    );
    // The packages built are workspace members whose binaries are copied.
    let build = lines
        .iter()
        .find(|l| l.contains("cargo build --release --locked"))
        .context("a release build")?;
    let packages: Vec<&str> = build
        .split_whitespace()
        .skip_while(|w| *w != "-p")
        .collect::<Vec<_>>()
        .chunks(2)
        .filter(|c| c[0] == "-p")
        .filter_map(|c| c.get(1).copied())
        .collect();
    assert_eq!(packages, ["ugv-sim", "ugv-controller"]);
    for (dir, package) in [("sim", "ugv-sim"), ("controller", "ugv-controller")] {
        let manifest = std::fs::read_to_string(repo().join(dir).join("Cargo.toml"))?;
        assert!(manifest.contains(&format!("name = \"{package}\"")), "{dir}");
    }
    let copied = lines
        .iter()
        .find(|l| l.starts_with("COPY --from=build"))
        .context("binaries copied from the build")?;
    let mut binaries = Vec::new();
    for path in copied.split_whitespace().skip(2) {
        if let Some(bin) = path.strip_prefix("/src/target/release/") {
            binaries.push(bin.to_owned());
        }
    }
    assert_eq!(binaries, ["ugv-sim", "ugv-controller"]);
    // Both are built here too: the names are the binaries cargo makes.
    let target = PathBuf::from(env!("CARGO_BIN_EXE_ugv-sim"));
    assert_eq!(target.file_name().and_then(|f| f.to_str()), Some("ugv-sim"));
    let sim = std::fs::read_to_string(repo().join("sim/Cargo.toml"))?;
    assert!(sim.contains("name = \"ugv-sim\"\npath = \"src/main.rs\""));
    assert!(
        repo().join("controller/src/main.rs").is_file()
            || repo()
                .join("controller/src/bin/ugv-controller.rs")
                .is_file()
    );
    // The folders copied exist, and the default command is a suite ugv-sim runs.
    let (image, here) = image_scenarios()?;
    assert!(repo().join(&here).is_dir(), "{here}");
    let entry = lines
        .iter()
        .find_map(|l| l.strip_prefix("ENTRYPOINT "))
        .context("ENTRYPOINT")?;
    assert_eq!(serde_json::from_str::<Vec<String>>(entry)?, ["ugv-sim"]);
    let cmd: Vec<String> = serde_json::from_str(
        lines
            .iter()
            .find_map(|l| l.strip_prefix("CMD "))
            .context("CMD")?,
    )?;
    assert!(cmd[1].starts_with(&image), "{cmd:?}");
    let ids = listed(&in_repo(&cmd)?, &[])?;
    let scenarios = std::fs::read_dir(repo().join(&here).join("suite"))?
        .flatten()
        .filter(|e| e.path().extension().is_some_and(|x| x == "toml"))
        .count();
    assert_eq!(ids.len(), scenarios, "the whole suite, once");
    // The build context leaves out build output.
    let ignore = std::fs::read_to_string(repo().join("deploy/Dockerfile.dockerignore"))?;
    if !ignore.lines().any(|l| l == "target") {
        bail!("deploy/Dockerfile.dockerignore must leave out target/");
    }
    Ok(())
}
