#!/usr/bin/env python3
"""Count phantom movers in the BARN worlds: every obstacle there is static, so a plan
made with moving obstacles in view (the trace's `plans[].moving`, set when the
perception reported an obstacle with a velocity past its dead band) is a phantom, and
so is any obstacle of the trace's last obstacle list with a velocity.

Runs each world with `ugv-sim run --sil --no-record` one at a time and prints per-world
figures and totals (runs with a phantom, plans with one, goals reached).

    scripts/lab/barn_phantoms.py [--every N] [--bin target/release/ugv-sim]
        [--worlds /work/shared/benchmarks/barn/worlds] [--out /tmp/barn-phantoms]
        [--json FILE]
"""

import argparse
import json
import pathlib
import shutil
import subprocess
import sys
import time


def run_world(binary, world, out):
    shutil.rmtree(out, ignore_errors=True)
    subprocess.run(
        [binary, "run", "--sil", "--no-record", str(world), "--results", str(out)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        check=False,
    )
    trace = json.loads((out / "trace.json").read_text())
    verdict = json.loads((out / "verdict.json").read_text())
    plans = trace["plans"]
    moving = [p["time"] for p in plans if p.get("moving")]
    last_moving = [o for o in trace["obstacles"] if o["vx"] != 0.0 or o["vy"] != 0.0]
    infeasible = sum(1 for p in plans if not p["feasible"])
    return {
        "world": world.stem,
        "plans": len(plans),
        "moving_plans": len(moving),
        "first_moving": moving[0] if moving else None,
        "last_obstacles_moving": len(last_moving),
        "infeasible_plans": infeasible,
        "passed": verdict.get("passed", False),
        "outcome": verdict.get("outcome"),
        "time": verdict.get("time"),
    }


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--every", type=int, default=1)
    ap.add_argument("--bin", default="target/release/ugv-sim")
    ap.add_argument("--worlds", default="/work/shared/benchmarks/barn/worlds")
    ap.add_argument("--out", default="/tmp/barn-phantoms")
    ap.add_argument("--json")
    args = ap.parse_args()
    worlds = sorted(pathlib.Path(args.worlds).glob("*.toml"))[:: args.every]
    out = pathlib.Path(args.out)
    rows = []
    start = time.monotonic()
    for w in worlds:
        r = run_world(args.bin, w, out)
        rows.append(r)
        print(
            f"{r['world']}: {r['moving_plans']:4d}/{r['plans']:4d} plans with a mover"
            f" (first at {r['first_moving']}), {r['infeasible_plans']} infeasible,"
            f" {r['outcome']} {'PASS' if r['passed'] else 'FAIL'}",
            flush=True,
        )
    elapsed = time.monotonic() - start
    runs = len(rows)
    with_phantom = sum(1 for r in rows if r["moving_plans"] or r["last_obstacles_moving"])
    moving_plans = sum(r["moving_plans"] for r in rows)
    plans = sum(r["plans"] for r in rows)
    passed = sum(1 for r in rows if r["passed"])
    print(
        f"TOTAL {runs} worlds in {elapsed:.0f} s: {with_phantom} runs with a phantom mover,"
        f" {moving_plans} of {plans} plans with one; passed {passed}/{runs}"
        f" ({100.0 * passed / max(runs, 1):.1f}%)"
    )
    if args.json:
        pathlib.Path(args.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
