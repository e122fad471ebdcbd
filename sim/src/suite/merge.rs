//! `ugv-sim merge`: shard files (`items.json`) joined into the plan's summaries. Every
//! shard must be of the same plan (its fields and its fingerprint), of the same split
//! (one shard count, each index once), and every item of the plan in exactly one of
//! them, each item's record agreeing with its place in the plan.

use std::collections::BTreeMap;
use std::io::Read;
use std::os::unix::fs::{FileTypeExt, OpenOptionsExt};
use std::path::{Path, PathBuf};

use super::{ItemRecord, ShardFile, ShardItem, Summary};
use crate::sweep::{PlanInfo, Shard, item_id};

/// Why shard files do not merge.
#[derive(Debug, thiserror::Error)]
pub enum MergeError {
    #[error("no shard files to merge")]
    Empty,
    #[error("reading {path} (a shard's items.json): {error}")]
    Read { path: String, error: String },
    #[error("{path} is {kind}, not a regular file: a shard's items.json is one")]
    NotRegular { path: String, kind: &'static str },
    #[error("{path}: not a shard's items.json: {error}")]
    Parse { path: String, error: String },
    #[error(
        "--out {out} is the folder of the shard {input}: the merge would overwrite it; merge into another folder"
    )]
    OutIsInput { out: String, input: String },
    #[error(
        "{name}: its plan does not match its fingerprint (edited by hand, or written by another version of ugv-sim)"
    )]
    Fingerprint { name: String },
    #[error("{later} is a shard of another sweep than {first}: {what} differ")]
    OtherPlan {
        first: String,
        later: String,
        what: &'static str,
    },
    #[error(
        "{later} is shard {later_shard} and {first} shard {first_shard}: shards of different splits do not merge"
    )]
    OtherSplit {
        first: String,
        first_shard: Shard,
        later: String,
        later_shard: Shard,
    },
    #[error("shard {shard} is in both {first} and {second} (a shard given twice)")]
    DoubledShard {
        shard: Shard,
        first: String,
        second: String,
    },
    #[error("{source_name}: item {index} is {id:?}, but the plan's item {index} is {planned:?}")]
    Mismatch {
        source_name: String,
        index: usize,
        id: String,
        planned: String,
    },
    #[error("{source_name}: item {index} ({id:?}): {why}")]
    Inconsistent {
        source_name: String,
        index: usize,
        id: String,
        why: String,
    },
    #[error(
        "item {id:?} is in both {first} and {second} (a shard given twice, or shards of different splits?)"
    )]
    Doubled {
        id: String,
        first: String,
        second: String,
    },
    #[error(
        "{missing} of {total} items are in no shard file, among them {examples} (shards given: {shards})"
    )]
    Missing {
        missing: usize,
        total: usize,
        examples: String,
        shards: String,
    },
    #[error("shards {missing} of {count} are missing (shards given: {shards})")]
    MissingShards {
        missing: String,
        count: usize,
        shards: String,
    },
}

/// What a file that is not a regular one is, for the refusal.
fn kind_of(t: std::fs::FileType) -> &'static str {
    if t.is_dir() {
        "a folder"
    } else if t.is_fifo() {
        "a FIFO"
    } else if t.is_socket() {
        "a socket"
    } else if t.is_char_device() || t.is_block_device() {
        "a device"
    } else {
        "not a file"
    }
}

/// The text of the regular file `path`. Opened without blocking (a FIFO would wait for
/// a writer forever) and its type checked on the open descriptor (no race with a
/// rename in between) before anything is read.
fn read_regular(path: &Path) -> Result<String, MergeError> {
    let failed = |e: std::io::Error| MergeError::Read {
        path: path.display().to_string(),
        error: e.to_string(),
    };
    let mut file = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK)
        .open(path)
        .map_err(failed)?;
    let kind = file.metadata().map_err(failed)?.file_type();
    if !kind.is_file() {
        return Err(MergeError::NotRegular {
            path: path.display().to_string(),
            kind: kind_of(kind),
        });
    }
    let mut text = String::new();
    file.read_to_string(&mut text).map_err(failed)?;
    Ok(text)
}

/// The folder a file is in (`.` for a bare name), resolved.
fn folder_of(path: &Path) -> Option<PathBuf> {
    let parent = path.parent().filter(|p| !p.as_os_str().is_empty());
    parent.unwrap_or(Path::new(".")).canonicalize().ok()
}

/// Read the shard files `inputs` (each an `items.json` or the folder holding one),
/// named by their paths, refusing a merge whose output folder `out` holds one of them.
pub fn read_shards(inputs: &[PathBuf], out: &Path) -> Result<Vec<(String, ShardFile)>, MergeError> {
    let out_dir = out.canonicalize().ok();
    let mut shards = Vec::with_capacity(inputs.len());
    for input in inputs {
        let path = if input.is_dir() {
            input.join("items.json")
        } else {
            input.clone()
        };
        let name = path.display().to_string();
        if out_dir.is_some() && folder_of(&path) == out_dir {
            return Err(MergeError::OutIsInput {
                out: out.display().to_string(),
                input: name,
            });
        }
        let text = read_regular(&path)?;
        let file: ShardFile = serde_json::from_str(&text).map_err(|e| MergeError::Parse {
            path: name.clone(),
            error: e.to_string(),
        })?;
        shards.push((name, file));
    }
    Ok(shards)
}

/// `shard`'s plan is `first`'s (named `first_name`), and its fields are its
/// fingerprint's.
fn check_plan(
    first_name: &str,
    first: &PlanInfo,
    name: &str,
    plan: &PlanInfo,
) -> Result<(), MergeError> {
    if plan.fingerprint != plan.digest() {
        return Err(MergeError::Fingerprint {
            name: name.to_owned(),
        });
    }
    let what = if plan.files != first.files {
        Some("the scenario files")
    } else if plan.seeds != first.seeds {
        Some("the seeds")
    } else if plan.vary != first.vary {
        Some("the --vary settings")
    } else if plan.settings != first.settings {
        Some("the run settings (mode, follower, model)")
    } else if plan.items != first.items {
        Some("the items")
    } else if plan.scenarios != first.scenarios {
        Some("the scenarios (a file's contents)")
    } else if plan.fingerprint != first.fingerprint {
        Some("the fingerprints")
    } else {
        None
    };
    match what {
        Some(what) => Err(MergeError::OtherPlan {
            first: first_name.to_owned(),
            later: name.to_owned(),
            what,
        }),
        None => Ok(()),
    }
}

/// Every shard of one split (the first's count), each index at most once.
fn check_split(shards: &[(String, ShardFile)]) -> Result<(), MergeError> {
    let mut seen: BTreeMap<usize, &str> = BTreeMap::new();
    let Some((first_name, first)) = shards.first() else {
        return Err(MergeError::Empty);
    };
    for (name, file) in shards {
        if file.shard.count != first.shard.count {
            return Err(MergeError::OtherSplit {
                first: first_name.clone(),
                first_shard: first.shard,
                later: name.clone(),
                later_shard: file.shard,
            });
        }
        if let Some(other) = seen.insert(file.shard.index, name) {
            return Err(MergeError::DoubledShard {
                shard: file.shard,
                first: other.to_owned(),
                second: name.clone(),
            });
        }
    }
    Ok(())
}

/// Why a record disagrees with itself or with its place in the plan (a field edited
/// by hand), if it does.
fn inconsistency(r: &ItemRecord, plan: &PlanInfo) -> Option<String> {
    let stem = Path::new(&r.file)
        .file_stem()
        .map_or_else(String::new, |s| s.to_string_lossy().into_owned());
    let id = item_id(&stem, &r.point, plan.seeds, r.seed_index);
    let verdict_passed = r
        .verdict
        .as_ref()
        .map(|v| v.get("passed").and_then(serde_json::Value::as_bool));
    if id != r.id {
        Some(format!(
            "its file, grid point and seed index make the id {id:?}"
        ))
    } else if r.passed != (r.outcome == "passed") {
        Some(format!(
            "passed is {} but the outcome is {:?}",
            r.passed, r.outcome
        ))
    } else if r.metrics.is_some() != r.verdict.is_some() {
        Some("metrics and verdict are not both given or both absent".to_owned())
    } else if verdict_passed.is_some_and(|p| p != Some(r.passed)) {
        Some(format!(
            "passed is {} but its verdict says otherwise",
            r.passed
        ))
    } else if r.verdict.is_none() != r.outcome.starts_with("ERROR") {
        Some(format!(
            "the outcome {:?} does not match its verdict",
            r.outcome
        ))
    } else {
        None
    }
}

/// The items of all shards by plan index, each checked against the plan.
fn items_by_index<'a>(
    shards: &'a [(String, ShardFile)],
    plan: &PlanInfo,
) -> Result<BTreeMap<usize, (&'a str, &'a ShardItem)>, MergeError> {
    let mut by_index: BTreeMap<usize, (&str, &ShardItem)> = BTreeMap::new();
    for (name, shard) in shards {
        for item in &shard.items {
            let r = &item.record;
            let planned = plan
                .items
                .get(r.index)
                .map(String::as_str)
                .unwrap_or("(none)");
            if planned != r.id {
                return Err(MergeError::Mismatch {
                    source_name: name.clone(),
                    index: r.index,
                    id: r.id.clone(),
                    planned: planned.to_owned(),
                });
            }
            if let Some(why) = inconsistency(r, plan) {
                return Err(MergeError::Inconsistent {
                    source_name: name.clone(),
                    index: r.index,
                    id: r.id.clone(),
                    why,
                });
            }
            if let Some((other, _)) = by_index.insert(r.index, (name, item)) {
                return Err(MergeError::Doubled {
                    id: r.id.clone(),
                    first: other.to_owned(),
                    second: name.clone(),
                });
            }
        }
    }
    Ok(by_index)
}

/// The shards given, for messages: `0/3 (path), ...`.
fn shards_given(shards: &[(String, ShardFile)]) -> String {
    shards
        .iter()
        .map(|(n, s)| format!("{} ({n})", s.shard))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Every item of the plan in some shard, and every shard index given.
fn check_complete(
    shards: &[(String, ShardFile)],
    plan: &PlanInfo,
    by_index: &BTreeMap<usize, (&str, &ShardItem)>,
) -> Result<(), MergeError> {
    let missing: Vec<&String> = plan
        .items
        .iter()
        .enumerate()
        .filter(|(i, _)| !by_index.contains_key(i))
        .map(|(_, id)| id)
        .collect();
    if !missing.is_empty() {
        let mut examples: Vec<String> =
            missing.iter().take(5).map(|id| format!("{id:?}")).collect();
        if missing.len() > 5 {
            examples.push("...".to_owned());
        }
        return Err(MergeError::Missing {
            missing: missing.len(),
            total: plan.items.len(),
            examples: examples.join(", "),
            shards: shards_given(shards),
        });
    }
    let count = shards.first().map_or(0, |(_, s)| s.shard.count);
    let absent: Vec<String> = (0..count)
        .filter(|i| !shards.iter().any(|(_, s)| s.shard.index == *i))
        .map(|i| i.to_string())
        .collect();
    if absent.is_empty() {
        Ok(())
    } else {
        Err(MergeError::MissingShards {
            missing: absent.join(", "),
            count,
            shards: shards_given(shards),
        })
    }
}

/// Join shard files (each named by where it came from) into the plan's summary and
/// the merged shard file; every item of the plan must be in exactly one of them.
pub fn merge(shards: &[(String, ShardFile)]) -> Result<(Summary, ShardFile), MergeError> {
    let (first_name, first) = shards.first().ok_or(MergeError::Empty)?;
    let plan = &first.plan;
    for (name, shard) in shards {
        check_plan(first_name, plan, name, &shard.plan)?;
    }
    check_split(shards)?;
    let by_index = items_by_index(shards, plan)?;
    check_complete(shards, plan, &by_index)?;
    let items: Vec<ShardItem> = by_index.into_values().map(|(_, i)| i.clone()).collect();
    let summary = Summary::of(items.iter().map(|i| i.record.clone()).collect());
    Ok((
        summary,
        ShardFile {
            plan: plan.clone(),
            shard: Shard::ALL,
            items,
        },
    ))
}
