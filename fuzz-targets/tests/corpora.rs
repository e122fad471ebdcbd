//! Replays every committed fuzz corpus through the same function the fuzzer calls, on
//! stable: the README's test command runs the campaigns' findings and coverage without
//! nightly. A target's corpus is in two parts, both replayed in full: its seed folder
//! `fuzz/corpus/<target>/` (plain files, the minimised set `cargo fuzz cmin` keeps) and
//! its archive `fuzz/corpus/<target>.tar.gz` (every other input the campaigns kept, one
//! gzipped tar, read here in memory). A target without a seed folder, with an empty one,
//! or whose archive is missing, unreadable or empty, fails: a missing corpus must not
//! pass as "nothing to replay". `scripts/lab/fuzz-campaign.sh unpack|pack` moves inputs
//! between the two (RELIABILITY.md, Fuzzing).

use std::collections::BTreeSet;
use std::io::Read;
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

/// One input: where it came from (a path, or `archive:entry`) and its bytes.
#[derive(Debug)]
struct Input {
    name: String,
    data: Vec<u8>,
}

/// The files of a folder, read.
fn folder_inputs(dir: &Path) -> Result<Vec<Input>> {
    files(dir)?
        .into_iter()
        .map(|path| {
            let data =
                std::fs::read(&path).with_context(|| format!("reading {}", path.display()))?;
            Ok(Input {
                name: path.display().to_string(),
                data,
            })
        })
        .collect()
}

/// Every file of a gzipped tar, in the archive's order. Anything but a file or a folder
/// in it, a damaged gzip stream (read to its end, so its CRC is checked) or a damaged
/// tar is an error.
fn archive_inputs(label: &str, reader: impl Read) -> Result<Vec<Input>> {
    let mut archive = tar::Archive::new(flate2::read::GzDecoder::new(reader));
    let mut out = Vec::new();
    for entry in archive
        .entries()
        .with_context(|| format!("reading {label}"))?
    {
        let mut entry = entry.with_context(|| format!("reading {label}"))?;
        let path = entry
            .path()
            .with_context(|| format!("reading {label}"))?
            .display()
            .to_string();
        match entry.header().entry_type() {
            tar::EntryType::Regular => {
                let mut data = Vec::new();
                entry
                    .read_to_end(&mut data)
                    .with_context(|| format!("reading {label}:{path}"))?;
                out.push(Input {
                    name: format!("{label}:{path}"),
                    data,
                });
            }
            tar::EntryType::Directory => {}
            other => bail!("{label}:{path} is a {other:?}, not a file"),
        }
    }
    std::io::copy(&mut archive.into_inner(), &mut std::io::sink())
        .with_context(|| format!("reading {label} to its end"))?;
    Ok(out)
}

/// A target's whole corpus under `fuzz`: its seed folder's inputs, then its archive's;
/// and how many came from each.
fn corpus_inputs(fuzz: &Path, name: &str) -> Result<(Vec<Input>, usize, usize)> {
    let dir = fuzz.join("corpus").join(name);
    ensure!(dir.is_dir(), "the corpus {} is missing", dir.display());
    let mut inputs = folder_inputs(&dir)?;
    ensure!(!inputs.is_empty(), "the corpus {} is empty", dir.display());
    let seeds = inputs.len();
    let path = fuzz.join("corpus").join(format!("{name}.tar.gz"));
    ensure!(
        path.is_file(),
        "the corpus archive {} is missing",
        path.display()
    );
    let file = std::fs::File::open(&path).with_context(|| format!("opening {}", path.display()))?;
    let archived = archive_inputs(&path.display().to_string(), file)?;
    ensure!(
        !archived.is_empty(),
        "the corpus archive {} holds no input",
        path.display()
    );
    // The two parts are disjoint (`pack` keeps them so): the counts are of distinct inputs.
    let seed_names: BTreeSet<_> = files(&dir)?
        .iter()
        .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        .collect();
    for input in &archived {
        let entry = input.name.rsplit(['/', ':']).next().unwrap_or_default();
        ensure!(
            !seed_names.contains(entry),
            "{} is also in the seed folder {}",
            input.name,
            dir.display()
        );
    }
    let count = archived.len();
    inputs.extend(archived);
    Ok((inputs, seeds, count))
}

/// Runs `target` on every input, each under `catch_unwind`, and names every input that
/// panicked.
fn replay(name: &str, target: ugv_fuzz_targets::Target, inputs: &[Input]) -> Result<()> {
    let mut failed = Vec::new();
    for input in inputs {
        if std::panic::catch_unwind(|| target(&input.data)).is_err() {
            failed.push(input.name.clone());
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
    let (inputs, seeds, archived) = corpus_inputs(&fuzz_dir(), name)?;
    replay(name, target, &inputs)?;
    // Shown with `-- --nocapture`: RELIABILITY.md's counts.
    println!(
        "{name}: {} inputs replayed ({seeds} seeds + {archived} archived)",
        inputs.len()
    );
    Ok(())
}

/// A corpus whose archive is missing, cut short or damaged fails, as does one without
/// its seed folder (on copies under the temporary folder).
#[test]
fn a_missing_or_damaged_archive_fails() -> Result<()> {
    let real = std::fs::read(fuzz_dir().join("corpus").join("laser_frame.tar.gz"))?;
    ensure!(!archive_inputs("whole", &real[..])?.is_empty());
    let cut = &real[..real.len() / 2];
    ensure!(archive_inputs("cut", cut).is_err(), "a cut archive reads");
    let mut flipped = real.clone();
    let middle = flipped.len() / 2;
    flipped[middle] ^= 0x55;
    ensure!(
        archive_inputs("flipped", &flipped[..]).is_err(),
        "a damaged archive reads"
    );

    let fuzz = std::env::temp_dir().join(format!("ugv-corpora-{}", std::process::id()));
    let result = (|| -> Result<Vec<String>> {
        let mut errors = Vec::new();
        let mut check = |what: &str| match corpus_inputs(&fuzz, "t") {
            Ok(_) => bail!("{what}: accepted"),
            Err(e) => {
                errors.push(format!("{e:#}"));
                Ok(())
            }
        };
        check("no corpus")?;
        std::fs::create_dir_all(fuzz.join("corpus").join("t"))?;
        check("an empty seed folder")?;
        std::fs::write(fuzz.join("corpus").join("t").join("seed"), b"x")?;
        check("no archive")?;
        std::fs::write(fuzz.join("corpus").join("t.tar.gz"), cut)?;
        check("a cut archive")?;
        std::fs::write(fuzz.join("corpus").join("t.tar.gz"), &real)?;
        let (inputs, seeds, archived) = corpus_inputs(&fuzz, "t")?;
        ensure!(seeds == 1 && archived + 1 == inputs.len() && archived > 0);
        Ok(errors)
    })();
    std::fs::remove_dir_all(&fuzz)?;
    let errors = result?;
    for (error, words) in errors
        .iter()
        .zip(["is missing", "is empty", "archive", "reading"])
    {
        ensure!(error.contains(words), "{error:?} does not say {words:?}");
    }
    Ok(())
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
            replay(name, *target, &folder_inputs(&dir)?)?;
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
