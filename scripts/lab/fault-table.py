#!/usr/bin/env python3
"""The safe-state table of a fault sweep: per fault kind (and node, where the kind has
one), how many injections, what detected them first, the time from the fault's start
to its detection and to each ECU's safe state (p50 and max, milliseconds).

Reads the summary.json of `ugv-sim suite` (or `ugv-sim merge`), whose items carry their
whole verdicts, and prints a Markdown table:

    ugv-sim suite sim/scenarios/faults --seeds 10 --results results/faults
    python3 scripts/lab/fault-table.py results/faults/summary.json
"""
import json
import sys
from collections import Counter, defaultdict


def pct(values, q):
    """The q-quantile by the nearest rank, as the simulator's own percentiles."""
    xs = sorted(values)
    return xs[round((len(xs) - 1) * q)]


def cell(values):
    """`p50 / max` in ms, or what is missing."""
    if not values:
        return "-"
    return f"{pct(values, 0.5):.0f} / {pct(values, 1.0):.0f}"


def main(path):
    with open(path, encoding="utf-8") as f:
        summary = json.load(f)
    rows = defaultdict(lambda: {"n": 0, "runs": set(), "passed": 0, "undetected": 0,
                                "by": Counter(), "det": [], "steer": [], "thr": []})
    for item in summary["items"]:
        verdict = item.get("verdict") or {}
        for fault in verdict.get("faults", []):
            if fault.get("started_s") is None:
                continue
            key = fault["kind"] + (f" ({fault['node']})" if "node" in fault else "")
            row = rows[key]
            row["n"] += 1
            if item["id"] not in row["runs"]:
                row["runs"].add(item["id"])
                row["passed"] += int(item["passed"])
            if fault.get("detection_ms") is None:
                row["undetected"] += 1
            else:
                row["det"].append(fault["detection_ms"])
                # The detector without its reason's details: "steering ECU", "controller: estop".
                by = fault.get("detected_by") or "?"
                row["by"][by if by.startswith("controller: estop") else by.split(":")[0]] += 1
            for name, field in (("steer", "steering_safe_ms"), ("thr", "throttle_safe_ms")):
                if fault.get(field) is not None:
                    row[name].append(fault[field])
    if not rows:
        sys.exit(f"{path}: no injected faults in its verdicts")
    print("| fault | injections | runs passed | detected first by | detection ms p50 / max "
          "| steering safe ms p50 / max | throttle safe ms p50 / max |")
    print("|---|---|---|---|---|---|---|")
    for key in sorted(rows):
        r = rows[key]
        by = ", ".join(f"{name} {count}" for name, count in r["by"].most_common())
        if r["undetected"]:
            by += f"{', ' if by else ''}ridden out {r['undetected']}"
        print(f"| {key} | {r['n']} | {r['passed']}/{len(r['runs'])} | {by} | {cell(r['det'])} "
              f"| {cell(r['steer'])} | {cell(r['thr'])} |")


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: fault-table.py SUMMARY.json")
    main(sys.argv[1])
