#!/usr/bin/env python3
"""BARN as a benchmark: run a folder of BARN worlds (ugv-sim scenario files converted for
the golf car, ../shared/benchmarks/barn/README.md) in SIL and score them as the BARN
challenge does.

    scripts/barn.py [--worlds DIR] [--every N] [--jobs N] [--bin target/release/ugv-sim]
        [--out /tmp/barn-bench] [--exclude-list FILE] [--json FILE] [--markdown]

Each world is run with `ugv-sim run --sil --no-record WORLD --results OUT/STEM` and
judged from its verdict.json:

- outcome: success (goal reached, no contact, within the world's limit of 8 x OT),
  collision (the footprint touched an obstacle), time-out (the limit passed), or stop
  (a controlled stop; its reason is the controller's `stop_reason`, else the run's; a
  run that reaches its limit with the car standing in a controlled stop is a stop);
- t: simulated seconds when the run ended; OT: the optimal time, from the file's
  header ("for the car ... X m, Y s at 2.0 m/s"); t/OT;
- score: success x OT / clip(t, 2 OT, 8 OT), the challenge's (so at most 0.5);
- left: the distance from the goal at the end, and the closest approach to any obstacle.

Totals: success, collision, time-out and stop rates, the mean score, t/OT over the
successes, and the stop reasons. With --exclude-list (worlds with no way through for
the car, one file stem per line, `#` comments) the success rate is also given over the
worlds with a way through, and a controlled stop in a listed world counts as correct.

A benchmark, not a test: the exit status is 0 whatever the outcomes, 2 when the runs
could not be started (no binary, no worlds).
"""

import argparse
import collections
import concurrent.futures
import datetime
import json
import os
import pathlib
import re
import shutil
import subprocess
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parent.parent
DEFAULT_WORLDS = ROOT.parent / "shared" / "benchmarks" / "barn" / "worlds"

# "# BARN path 12.43 m, optimal time 6.22 s at 2 m/s; for the car 34.69 m, 17.35 s at 2.0 m/s; ..."
# Below this speed the car stands (as sim/src/verdict.rs), m/s.
STOPPED = 0.05

HEADER = re.compile(r"for the car\s+([0-9.]+)\s*m,\s*([0-9.]+)\s*s\s+at\s+([0-9.]+)\s*m/s")


def optimal_time(world):
    """The car's optimal time and reference path length from the world's header comment."""
    for line in world.read_text().splitlines():
        if not line.startswith("#"):
            break
        m = HEADER.search(line)
        if m:
            return float(m.group(2)), float(m.group(1))
    return None, None


def score(success, t, ot):
    """The BARN challenge's score: success x OT / clip(t, 2 OT, 8 OT)."""
    if not success or ot is None or t is None:
        return 0.0
    return ot / min(max(t, 2.0 * ot), 8.0 * ot)


def run_world(binary, world, out_root):
    out = out_root / world.stem
    shutil.rmtree(out, ignore_errors=True)
    ot, ref_len = optimal_time(world)
    row = {"world": world.stem, "ot": ot, "ref_length": ref_len}
    wall = time.monotonic()
    proc = subprocess.run(
        [str(binary), "run", "--sil", "--no-record", str(world), "--results", str(out)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        check=False,
    )
    row["wall_s"] = round(time.monotonic() - wall, 2)
    row["exit"] = proc.returncode
    verdict_file = out / "verdict.json"
    if not verdict_file.exists():
        tail = proc.stderr.strip().splitlines()[-1:] if proc.stderr else []
        row.update(
            outcome="error",
            reason=(tail[0] if tail else f"exit {proc.returncode}, no verdict"),
            success=False,
            time=None,
            t_ot=None,
            score=0.0,
            left=None,
            clearance=None,
        )
        return row
    v = json.loads(verdict_file.read_text())
    kind = v.get("outcome")
    t = v.get("time")
    ctrl = v.get("controller") or {}
    reason = None
    success = bool(v.get("passed")) and bool(v.get("goal_reached"))
    if kind == "goal_reached":
        outcome = "success" if success else "goal, failed"
        if not success:
            reason = "; ".join(v.get("failures", []))
    elif kind == "collision":
        outcome = "collision"
    elif kind == "time_limit":
        # The guidance holding a controlled stop with the car standing when the limit
        # came is a stop (the run does not end on it), not a time-out.
        final_v = abs((v.get("final_state") or {}).get("v", 1.0))
        if ctrl.get("stop_reason") and final_v < STOPPED:
            outcome = "stop"
            reason = ctrl["stop_reason"]
        else:
            outcome = "time-out"
    elif kind == "stopped":
        outcome = "stop"
        reason = ctrl.get("stop_reason") or v.get("reason")
    else:
        outcome = str(kind)
    clear = v.get("min_clearance") or []
    row.update(
        outcome=outcome,
        reason=reason,
        success=success,
        time=t,
        t_ot=(t / ot if ot and t is not None else None),
        score=score(success, t, ot),
        left=v.get("distance_to_goal"),
        clearance=(min(clear) if clear else None),
        reversals=ctrl.get("reversals"),
        replans=ctrl.get("replans"),
    )
    return row


def fmt(x, spec):
    return "-" if x is None else format(x, spec)


def outcome_text(r):
    return r["outcome"] + (f" ({r['reason']})" if r.get("reason") else "")


def print_row(r):
    print(
        f"{r['world']:<10} {outcome_text(r):<58} t {fmt(r['time'], '6.1f')} s"
        f"  OT {fmt(r['ot'], '5.1f')} s  t/OT {fmt(r['t_ot'], '4.2f')}"
        f"  score {r['score']:.3f}  left {fmt(r['left'], '5.1f')} m"
        f"  clear {fmt(r['clearance'], '4.2f')} m",
        flush=True,
    )


def pct(k, n):
    return f"{k}/{n} ({100.0 * k / n:.1f} %)" if n else f"{k}/0"


def totals(rows, excluded):
    n = len(rows)
    count = collections.Counter(r["outcome"] for r in rows)
    succ = [r for r in rows if r["success"]]
    t_ot = sorted(r["t_ot"] for r in succ if r["t_ot"] is not None)
    reasons = collections.Counter(r["reason"] or "-" for r in rows if r["outcome"] == "stop")
    tot = {
        "worlds": n,
        "success": count["success"],
        "collision": count["collision"],
        "time_out": count["time-out"],
        "stop": count["stop"],
        "other": n - count["success"] - count["collision"] - count["time-out"] - count["stop"],
        "mean_score": (sum(r["score"] for r in rows) / n) if n else 0.0,
        "mean_t_ot_success": (sum(t_ot) / len(t_ot)) if t_ot else None,
        "median_t_ot_success": (t_ot[len(t_ot) // 2] if t_ot else None),
        "stop_reasons": dict(reasons.most_common()),
    }
    if excluded is not None:
        listed = [r for r in rows if r["world"] in excluded]
        through = [r for r in rows if r["world"] not in excluded]
        tot["excluded_run"] = len(listed)
        tot["with_way_through"] = len(through)
        tot["success_with_way_through"] = sum(1 for r in through if r["success"])
        tot["collision_with_way_through"] = sum(1 for r in through if r["outcome"] == "collision")
        tot["mean_score_with_way_through"] = (
            sum(r["score"] for r in through) / len(through) if through else 0.0
        )
        # A controlled stop where there is no way through is the right answer.
        tot["correct"] = tot["success"] + sum(1 for r in listed if r["outcome"] == "stop")
        tot["listed_but_reached"] = [r["world"] for r in listed if r["success"]]
    return tot


def print_totals(tot, elapsed):
    n = tot["worlds"]
    print(f"TOTAL {n} worlds in {elapsed:.0f} s wall")
    print(f"  success   {pct(tot['success'], n)}")
    print(f"  collision {pct(tot['collision'], n)}")
    print(f"  time-out  {pct(tot['time_out'], n)}")
    print(f"  stop      {pct(tot['stop'], n)}")
    if tot["other"]:
        print(f"  other     {pct(tot['other'], n)} (runs that failed otherwise or did not run)")
    print(f"  mean score {tot['mean_score']:.3f} (at most 0.5: t is clipped at 2 OT)")
    if tot["mean_t_ot_success"] is not None:
        print(
            f"  t/OT of the successes: mean {tot['mean_t_ot_success']:.2f},"
            f" median {tot['median_t_ot_success']:.2f}"
        )
    if tot["stop_reasons"]:
        print("  stop reasons:")
        for reason, k in tot["stop_reasons"].items():
            print(f"    {k:4d}  {reason}")
    if "with_way_through" in tot:
        w = tot["with_way_through"]
        print(
            f"  worlds with a way through ({tot['excluded_run']} listed as having none):"
            f" success {pct(tot['success_with_way_through'], w)},"
            f" collision {tot['collision_with_way_through']},"
            f" mean score {tot['mean_score_with_way_through']:.3f}"
        )
        print(f"  correct over all (success, or a stop where there is no way through): {pct(tot['correct'], n)}")
        if tot["listed_but_reached"]:
            print(f"  listed as having no way through yet reached: {', '.join(tot['listed_but_reached'])}")


def print_markdown(rows, tot, command, binary):
    n = tot["worlds"]
    stamp = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    try:
        head = subprocess.run(
            ["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"],
            capture_output=True, text=True, check=False,
        ).stdout.strip()
    except OSError:
        head = "?"
    built = datetime.datetime.fromtimestamp(
        binary.stat().st_mtime, datetime.timezone.utc
    ).strftime("%Y-%m-%d %H:%M UTC")
    print()
    print(f"{stamp}, HEAD {head}, binary built {built}: `{command}`")
    print()
    print("| world | outcome | t (s) | OT (s) | t/OT | score | left (m) | clearance (m) |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['world']} | {outcome_text(r)} | {fmt(r['time'], '.1f')} | {fmt(r['ot'], '.1f')}"
            f" | {fmt(r['t_ot'], '.2f')} | {r['score']:.3f} | {fmt(r['left'], '.1f')}"
            f" | {fmt(r['clearance'], '.2f')} |"
        )
    print()
    line = (
        f"**{n} worlds: success {pct(tot['success'], n)}**, collision {pct(tot['collision'], n)},"
        f" time-out {pct(tot['time_out'], n)}, stop {pct(tot['stop'], n)}"
    )
    if tot["other"]:
        line += f", other {pct(tot['other'], n)}"
    line += f"; mean score {tot['mean_score']:.3f}"
    if tot["mean_t_ot_success"] is not None:
        line += f"; t/OT of the successes mean {tot['mean_t_ot_success']:.2f}"
    print(line + ".")
    if "with_way_through" in tot:
        w = tot["with_way_through"]
        print(
            f"Over the {w} worlds with a way through: success {pct(tot['success_with_way_through'], w)};"
            f" correct over all (a stop counts where there is no way through): {pct(tot['correct'], n)}."
        )
    if tot["stop_reasons"]:
        print()
        print("| stop reason | worlds |")
        print("|---|---|")
        for reason, k in tot["stop_reasons"].items():
            print(f"| {reason} | {k} |")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--worlds", default=str(DEFAULT_WORLDS), help="a folder of BARN worlds (*.toml), or one file")
    ap.add_argument("--every", type=int, default=1, help="every Nth world (sorted by name)")
    ap.add_argument("--jobs", type=int, default=1, help="runs in parallel")
    ap.add_argument("--bin", default="target/release/ugv-sim")
    ap.add_argument("--out", default="/tmp/barn-bench", help="each run's results go to OUT/STEM")
    ap.add_argument("--exclude-list", help="worlds with no way through, one stem per line")
    ap.add_argument("--json", help="write the rows and totals here")
    ap.add_argument("--markdown", action="store_true", help="also print a table for BENCHMARKS.md")
    args = ap.parse_args()
    command = "scripts/barn.py " + " ".join(sys.argv[1:])

    binary = pathlib.Path(args.bin)
    if not binary.is_absolute():
        binary = ROOT / binary
    if not (binary.is_file() and os.access(binary, os.X_OK)):
        print(f"barn.py: no executable {binary} (cargo build --release -p ugv-sim)", file=sys.stderr)
        return 2
    src = pathlib.Path(args.worlds)
    worlds = [src] if src.is_file() else sorted(src.glob("*.toml"))
    worlds = worlds[:: max(args.every, 1)]
    if not worlds:
        print(f"barn.py: no worlds (*.toml) in {src}", file=sys.stderr)
        return 2
    excluded = None
    if args.exclude_list:
        excluded = set()
        for line in pathlib.Path(args.exclude_list).read_text().splitlines():
            stem = line.split("#", 1)[0].strip()
            if stem:
                excluded.add(pathlib.Path(stem).stem)
    out_root = pathlib.Path(args.out)
    out_root.mkdir(parents=True, exist_ok=True)

    built = datetime.datetime.fromtimestamp(binary.stat().st_mtime, datetime.timezone.utc)
    print(f"{len(worlds)} worlds from {src}, {binary} built {built:%Y-%m-%d %H:%M:%S} UTC, {args.jobs} job(s)", flush=True)
    start = time.monotonic()
    rows = []
    try:
        with concurrent.futures.ThreadPoolExecutor(max_workers=max(args.jobs, 1)) as pool:
            for r in pool.map(lambda w: run_world(binary, w, out_root), worlds):
                rows.append(r)
                print_row(r)
    except OSError as e:
        print(f"barn.py: could not start a run: {e}", file=sys.stderr)
        return 2
    elapsed = time.monotonic() - start
    tot = totals(rows, excluded)
    print_totals(tot, elapsed)
    if args.markdown:
        print_markdown(rows, tot, command, binary)
    if args.json:
        pathlib.Path(args.json).write_text(
            json.dumps({"command": command, "totals": tot, "worlds": rows}, indent=1)
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
