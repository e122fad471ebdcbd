//! Replays every committed fuzz corpus (fuzz/corpus/<target>/) through the same
//! function the fuzzer calls, on stable: the README's test command runs the campaigns'
//! findings and coverage without nightly. A target without a corpus, or with an empty
//! one, fails: a missing corpus must not pass as "nothing to replay".

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail, ensure};

fn fuzz_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../fuzz")
}

/// The files of a folder, sorted (inputs are files named by their hash).
fn files(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).with_context(|| format!("reading {}", dir.display()))? {
        let path = entry?.path();
        if path.is_file() {
            out.push(path);
        }
    }
    out.sort();
    Ok(out)
}

/// Runs `target` on every file, each under `catch_unwind`, and names every file that
/// panicked.
fn replay(name: &str, target: ugv_fuzz_targets::Target, inputs: &[PathBuf]) -> Result<()> {
    let mut failed = Vec::new();
    for path in inputs {
        let data = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
        if std::panic::catch_unwind(|| target(&data)).is_err() {
            failed.push(path.display().to_string());
        }
    }
    ensure!(
        failed.is_empty(),
        "{name}: {} of {} inputs panic:\n{}",
        failed.len(),
        inputs.len(),
        failed.join("\n")
    );
    Ok(())
}

fn corpus(name: &str) -> Result<()> {
    let target = ugv_fuzz_targets::TARGETS
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(_, t)| *t)
        .with_context(|| format!("no target {name}"))?;
    let dir = fuzz_dir().join("corpus").join(name);
    ensure!(dir.is_dir(), "the corpus {} is missing", dir.display());
    let inputs = files(&dir)?;
    ensure!(!inputs.is_empty(), "the corpus {} is empty", dir.display());
    replay(name, target, &inputs)
}

macro_rules! corpus_tests {
    ($($name:ident),* $(,)?) => {
        $(
            #[test]
            fn $name() -> Result<()> {
                corpus(stringify!($name))
            }
        )*

        /// Every target has a replay test above, and every test a target.
        #[test]
        fn every_target_is_replayed() {
            let tested = [$(stringify!($name)),*];
            let targets: Vec<&str> = ugv_fuzz_targets::TARGETS.iter().map(|(n, _)| *n).collect();
            assert_eq!(tested.to_vec(), targets);
        }
    };
}

corpus_tests!(
    nmea_stream,
    cola_telegrams,
    cola_server,
    candump_line,
    dbc_spec,
    scenario_toml,
    controller_config,
    plan_json,
    anfis_model,
    anfis_csv,
    laser_frame,
);

/// Inputs kept from fuzz/artifacts/<target>/ (crashes fixed since): each must now
/// run clean. They are also in the corpus; this keeps them even if a `cmin` drops one.
#[test]
fn regressions() -> Result<()> {
    let root = fuzz_dir().join("regressions");
    if !root.is_dir() {
        return Ok(());
    }
    for (name, target) in ugv_fuzz_targets::TARGETS {
        let dir = root.join(name);
        if dir.is_dir() {
            replay(name, *target, &files(&dir)?)?;
        }
    }
    Ok(())
}

/// What the product says of `text` as an input of `target`: its refusal, or `None`
/// when it accepts it (the parse and the checks the target's entry point makes).
fn refusal(target: &str, text: &str) -> Result<Option<String>> {
    use ugv_controller::config::ControllerConfig;
    use ugv_controller::planner::PlanProblem;
    Ok(match target {
        "controller_config" => ControllerConfig::from_toml(text, "f.toml")
            .err()
            .map(|e| e.to_string()),
        "scenario_toml" => ugv_sim::Scenario::from_toml(text, "f.toml")
            .err()
            .map(|e| e.to_string()),
        "plan_json" => serde_json::from_str::<PlanProblem>(text)?
            .validate()
            .err()
            .map(|e| e.to_string()),
        other => bail!("no refusal to check for {other}"),
    })
}

/// Inputs kept as `refused-<field>=<value>` in fuzz/regressions/<target>/ (values no
/// golf car has, which the loaders once accepted): each must now be refused, naming
/// its field. Replayed above too, where a refusal only has to be no panic.
#[test]
fn refused_regressions_name_their_field() -> Result<()> {
    let root = fuzz_dir().join("regressions");
    let mut checked = 0;
    for target in ["controller_config", "scenario_toml", "plan_json"] {
        for path in files(&root.join(target))? {
            let name = path
                .file_name()
                .and_then(|n| n.to_str())
                .unwrap_or_default();
            let Some(field) = name
                .strip_prefix("refused-")
                .and_then(|rest| rest.split_once('='))
                .map(|(field, _)| field)
            else {
                continue;
            };
            let text = std::fs::read_to_string(&path)?;
            match refusal(target, &text)? {
                Some(e) => ensure!(e.contains(&format!("{field}: ")), "{name}: {e}"),
                None => bail!("{target}/{name} is accepted"),
            }
            checked += 1;
        }
    }
    ensure!(checked >= 9, "only {checked} refused inputs found");
    Ok(())
}

/// Candump lines kept as `refused-<words>` in fuzz/regressions/candump_line/ (the
/// parser of `ugv-can decode` once took `(nan)` for a time and dropped a second frame
/// on a line): every line of each file must now be refused, its error holding the
/// words (`refused-one-frame-per-line`: "one frame per line").
#[test]
fn refused_candump_lines_say_why() -> Result<()> {
    let mut checked = 0;
    for path in files(&fuzz_dir().join("regressions").join("candump_line"))? {
        let name = path
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or_default();
        let Some(words) = name.strip_prefix("refused-") else {
            continue;
        };
        let phrase = words.replace('-', " ");
        let text = std::fs::read_to_string(&path)?;
        for line in text.lines().filter(|l| !l.trim().is_empty()) {
            match golf_car_can::candump::parse_line(line) {
                Ok(frame) => bail!("{name}: {line:?} is accepted: {frame:?}"),
                Err(e) => ensure!(e.to_string().contains(&phrase), "{name}: {line:?}: {e}"),
            }
            checked += 1;
        }
    }
    ensure!(checked >= 10, "only {checked} refused candump lines found");
    Ok(())
}
