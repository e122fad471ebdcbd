//! The exit codes of `ugv-sim run`, `suite` and `merge`: one table, which each
//! command's `--help` shows and docs/simulator.md repeats.

use crate::run::Outcome;
use crate::suite::{ItemRecord, Summary};

/// How a run, or the worst of a suite's items, ended. Declared from the least to
/// the most severe: a suite exits with its most severe item's code.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Exit {
    /// 0: the verdict's criteria met.
    Passed,
    /// 5: the time limit reached without passing.
    TimeLimit,
    /// 1: a collision, or the goal reached with a criterion missed.
    Failed,
    /// 3: ended from outside: Ctrl-C, or the controller exited.
    Stopped,
    /// 4: could not run, or not to the end: a bad scenario, a wire, no controller.
    Setup,
}

/// 2: the command line; clap exits with it before anything runs.
pub const USAGE: u8 = 2;

impl Exit {
    /// The process's exit code.
    pub fn code(self) -> u8 {
        match self {
            Exit::Passed => 0,
            Exit::Failed => 1,
            Exit::Stopped => 3,
            Exit::Setup => 4,
            Exit::TimeLimit => 5,
        }
    }

    /// A run that ended with `outcome` and a verdict that `passed` or not.
    pub fn of_run(outcome: &Outcome, passed: bool) -> Exit {
        match outcome {
            Outcome::Stopped { .. } => Exit::Stopped,
            _ if passed => Exit::Passed,
            Outcome::TimeLimit { .. } => Exit::TimeLimit,
            Outcome::GoalReached { .. } | Outcome::Collision { .. } => Exit::Failed,
        }
    }

    /// A suite's item as its summary holds it: what `run` would have exited with, and
    /// [`Exit::Setup`] for an item that could not run (no verdict).
    pub fn of_item(r: &ItemRecord) -> Exit {
        let outcome = r.verdict.as_ref().map(|v| v["outcome"].as_str());
        match outcome {
            None => Exit::Setup,
            Some(Some("stopped")) => Exit::Stopped,
            Some(_) if r.passed => Exit::Passed,
            Some(Some("time_limit")) => Exit::TimeLimit,
            Some(_) => Exit::Failed,
        }
    }

    /// A suite (or a merge of its shards): its most severe item's.
    pub fn of_suite(summary: &Summary) -> Exit {
        summary
            .items
            .iter()
            .map(Exit::of_item)
            .max()
            .unwrap_or(Exit::Passed)
    }
}

/// `ugv-sim run`'s exit codes, for `run --help`.
pub const RUN_HELP: &str = "Exit codes:
  0  passed: the verdict's criteria are met (the goal reached, or a safe stop where the scenario asks for one)
  1  failed its criteria: a collision, or the goal reached with a criterion missed (clearance, route, safe state)
  2  usage error: the command line
  3  stopped: Ctrl-C, or the controller exited
  4  setup or run error: a bad scenario, a wire that cannot be opened, no controller within 60 s
  5  time limit: the run reached sim.time_limit_s without passing";

/// `ugv-sim suite`'s (and `merge`'s) exit codes, for their `--help`.
pub const SUITE_HELP: &str = "Exit codes (the summaries are written whatever the code, except 2 and a refused folder or argument):
  0  passed: every item passed
  1  failed its criteria: an item collided, or reached the goal with a criterion missed
  2  usage error: the command line
  3  stopped: an item was stopped (Ctrl-C, or in HIL the controller exited)
  4  setup error: the folder (none, or no *.toml in it), an argument's value (--vary, --shard, merge's shards), or an item that could not run (a bad scenario file, a controller that did not start)
  5  time limit: the only failures are items that reached sim.time_limit_s without passing
Items that end differently give the first of 4, 3, 1, 5 that applies.";

#[cfg(test)]
mod tests {
    use super::*;

    fn item(passed: bool, outcome: Option<&str>) -> ItemRecord {
        ItemRecord {
            index: 0,
            id: "a".to_owned(),
            file: "a.toml".to_owned(),
            name: "a".to_owned(),
            point: Vec::new(),
            seed_index: 0,
            seed: None,
            passed,
            outcome: String::new(),
            metrics: None,
            verdict: outcome.map(|o| serde_json::json!({ "outcome": o, "passed": passed })),
            error: outcome.is_none().then(|| "a.toml: bad".to_owned()),
        }
    }

    #[test]
    fn a_suite_exits_with_its_most_severe_item() {
        let passed = item(true, Some("goal_reached"));
        let safe_stop = item(true, Some("time_limit"));
        let late = item(false, Some("time_limit"));
        let hit = item(false, Some("collision"));
        let stopped = item(false, Some("stopped"));
        let bad = item(false, None);
        let code = |items: &[&ItemRecord]| {
            Exit::of_suite(&Summary::of(items.iter().map(|&i| i.clone()).collect())).code()
        };
        assert_eq!(code(&[]), 0);
        assert_eq!(code(&[&passed, &safe_stop]), 0, "a safe stop passes");
        assert_eq!(code(&[&passed, &late]), 5, "only time limits");
        assert_eq!(code(&[&late, &hit]), 1);
        assert_eq!(code(&[&hit, &stopped, &late]), 3);
        assert_eq!(code(&[&passed, &stopped, &bad]), 4);
    }
}
