//! Shards: `--shard I/N` runs a deterministic 1/N of a plan's items, balanced by their
//! expected cost; without it, a Kubernetes Indexed Job's `JOB_COMPLETION_INDEX` with
//! `JOB_COMPLETIONS` (which the Job's manifest sets to its completions) choose it.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

/// The index a Kubernetes Indexed Job gives each pod (0-based).
pub const INDEX_VAR: &str = "JOB_COMPLETION_INDEX";
/// The shard count; Kubernetes does not set it: the manifest does, to `completions`.
pub const COUNT_VAR: &str = "JOB_COMPLETIONS";
/// Most shards.
pub const MAX_SHARDS: usize = 100_000;

/// Shard `index` (0-based, like `JOB_COMPLETION_INDEX`) of `count`; read from a shard
/// file with the checks of `--shard` (`{"index": 5, "count": 3}` or 0/0 is refused).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(try_from = "ShardFields")]
pub struct Shard {
    pub index: usize,
    pub count: usize,
}

/// A shard as written in a shard file, before its checks.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ShardFields {
    index: usize,
    count: usize,
}

impl TryFrom<ShardFields> for Shard {
    type Error = String;

    fn try_from(s: ShardFields) -> Result<Shard, String> {
        Shard::new(s.index, s.count).map_err(|e| format!("shard {}/{}: {e}", s.index, s.count))
    }
}

impl fmt::Display for Shard {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl Shard {
    /// The whole plan.
    pub const ALL: Shard = Shard { index: 0, count: 1 };

    fn new(index: usize, count: usize) -> Result<Shard, String> {
        if !(1..=MAX_SHARDS).contains(&count) {
            return Err(format!(
                "the shard count must be 1 to {MAX_SHARDS}, is {count}"
            ));
        }
        if index >= count {
            return Err(format!(
                "the shard index is 0-based (like {INDEX_VAR}): 0 to {}, is {index}",
                count - 1
            ));
        }
        Ok(Shard { index, count })
    }

    /// The shard the environment names: `Some` when `JOB_COMPLETION_INDEX` is set
    /// (then `JOB_COMPLETIONS` must be too), `None` when neither is.
    pub fn from_env(var: impl Fn(&str) -> Option<String>) -> Result<Option<Shard>, String> {
        match (var(INDEX_VAR), var(COUNT_VAR)) {
            (None, None) => Ok(None),
            (Some(i), Some(n)) => {
                let parse = |name: &str, v: &str| {
                    v.trim()
                        .parse::<usize>()
                        .map_err(|_| format!("{name}={v:?} is not a whole number"))
                };
                Shard::new(parse(INDEX_VAR, &i)?, parse(COUNT_VAR, &n)?)
                    .map(Some)
                    .map_err(|e| format!("{INDEX_VAR}={i} {COUNT_VAR}={n}: {e}"))
            }
            (Some(_), None) => Err(format!(
                "{INDEX_VAR} is set but {COUNT_VAR} is not: set it to the Job's completions, or pass --shard"
            )),
            (None, Some(_)) => Err(format!(
                "{COUNT_VAR} is set but {INDEX_VAR} is not: pass --shard I/N"
            )),
        }
    }
}

impl FromStr for Shard {
    type Err = String;

    fn from_str(s: &str) -> Result<Shard, String> {
        let (i, n) = s
            .split_once('/')
            .ok_or_else(|| format!("{s:?} is not I/N (shard I of N, I from 0)"))?;
        let parse = |v: &str| {
            v.trim()
                .parse::<usize>()
                .map_err(|_| format!("{s:?}: {v:?} is not a whole number"))
        };
        Shard::new(parse(i)?, parse(n)?)
    }
}

/// The shard of each item, balanced by cost: the dearest item first, each to the
/// shard with the least cost so far (longest processing time first; ties to the
/// earlier item and the lower shard), so every run of the same plan splits alike.
pub fn assign(costs: &[f64], count: usize) -> Vec<usize> {
    let mut order: Vec<usize> = (0..costs.len()).collect();
    order.sort_by(|&a, &b| costs[b].total_cmp(&costs[a]).then(a.cmp(&b)));
    let mut load = vec![0.0_f64; count.max(1)];
    let mut shard = vec![0; costs.len()];
    for i in order {
        let (least, _) = load
            .iter()
            .enumerate()
            .fold(
                (0, f64::INFINITY),
                |best, (s, l)| if *l < best.1 { (s, *l) } else { best },
            );
        shard[i] = least;
        load[least] += costs[i];
    }
    shard
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shard_arguments_are_checked() {
        assert_eq!("2/3".parse::<Shard>(), Ok(Shard { index: 2, count: 3 }));
        for (arg, says) in [
            ("3/3", "0-based"),
            ("0/0", "1 to 100000"),
            ("1", "is not I/N"),
            ("a/2", "\"a\" is not a whole number"),
            ("-1/2", "is not a whole number"),
        ] {
            let e = arg.parse::<Shard>().unwrap_err();
            assert!(e.contains(says), "{arg}: {e}");
        }
    }

    #[test]
    fn a_shard_read_from_a_file_is_checked_like_the_argument() {
        let read = |json: &str| serde_json::from_str::<Shard>(json).map_err(|e| e.to_string());
        assert_eq!(
            read(r#"{"index": 2, "count": 3}"#),
            Ok(Shard { index: 2, count: 3 })
        );
        for (json, says) in [
            (
                r#"{"index": 5, "count": 3}"#,
                "shard 5/3: the shard index is 0-based (like JOB_COMPLETION_INDEX): 0 to 2, is 5",
            ),
            (
                r#"{"index": 0, "count": 0}"#,
                "shard 0/0: the shard count must be 1 to 100000, is 0",
            ),
            (r#"{"index": 0, "count": 1, "of": 2}"#, "unknown field `of`"),
        ] {
            let e = read(json).unwrap_err();
            assert!(e.contains(says), "{json}: {e}");
        }
    }

    #[test]
    fn the_environment_of_an_indexed_job_names_the_shard() {
        let env = |vars: &'static [(&'static str, &'static str)]| {
            move |k: &str| {
                vars.iter()
                    .find(|(n, _)| *n == k)
                    .map(|(_, v)| v.to_string())
            }
        };
        assert_eq!(Shard::from_env(env(&[])), Ok(None));
        assert_eq!(
            Shard::from_env(env(&[(INDEX_VAR, "4"), (COUNT_VAR, "7")])),
            Ok(Some(Shard { index: 4, count: 7 }))
        );
        for (vars, says) in [
            (&[(INDEX_VAR, "4")][..], "JOB_COMPLETIONS is not"),
            (&[(COUNT_VAR, "4")][..], "JOB_COMPLETION_INDEX is not"),
            (&[(INDEX_VAR, "7"), (COUNT_VAR, "7")][..], "0-based"),
            (
                &[(INDEX_VAR, "x"), (COUNT_VAR, "7")][..],
                "JOB_COMPLETION_INDEX=\"x\"",
            ),
        ] {
            let e = Shard::from_env(env(vars)).unwrap_err();
            assert!(e.contains(says), "{vars:?}: {e}");
        }
    }

    #[test]
    fn assignment_covers_every_item_once_and_balances_cost() {
        let costs: Vec<f64> = (0..50).map(|i| f64::from(i % 7 + 1) * 10.0).collect();
        for n in [1, 2, 3, 7, 60] {
            let a = assign(&costs, n);
            assert_eq!(a.len(), costs.len());
            assert!(a.iter().all(|s| *s < n));
            assert_eq!(a, assign(&costs, n), "deterministic");
            let mut load = vec![0.0; n];
            for (i, s) in a.iter().enumerate() {
                load[*s] += costs[i];
            }
            let (lo, hi) = load.iter().fold((f64::INFINITY, 0.0_f64), |(lo, hi), l| {
                (lo.min(*l), hi.max(*l))
            });
            if n <= costs.len() {
                // LPT: no shard exceeds another by more than the dearest item.
                assert!(hi - lo <= 70.0, "{n}: {load:?}");
            }
        }
    }
}
