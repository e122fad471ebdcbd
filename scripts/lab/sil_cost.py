#!/usr/bin/env python3
"""SIL cost benchmark (issue 37 item 8), run by hand, not in CI.

    scripts/lab/sil_cost.py instructions [--suite] [--scenarios DIR] [--barn N] [--jobs N] [--bin B] [--out DIR]
    scripts/lab/sil_cost.py rtf [--rounds N] [--bin B] [--venv DIR] [--out DIR]
    scripts/lab/sil_cost.py all [the options of both]

instructions: callgrind instructions per simulated second of
`ugv-sim run --sil --no-record SCENARIO --results DIR` under
`valgrind --tool=callgrind`: the paper scenario (sim/scenarios/paper.toml) always,
every scenario of sim/scenarios/suite with --suite (71 runs, about 2,000 simulated
seconds; `--jobs 2` runs two callgrinds at a time), every scenario of a folder with
--scenarios DIR (e.g. the routes of scripts/lab/gen_posts_route.py), every N-th
BARN world of ../shared/benchmarks/barn/worlds with --barn N (--barn 50: 5 worlds,
over 30 minutes under load, as a world the car struggles in runs to its 8 x OT limit
under callgrind; --barn 1: all 250, a day). Simulated seconds are `time` in each run's
verdict.json; instructions are the `totals:` line of the callgrind output. Prints a
markdown table per item and the totals per group (instructions over simulated
seconds summed). Instructions do not depend on the machine's load.

rtf: real-time factors of the paper scenario against IR-SIM 2.12 (PyPI `ir-sim`, in a
venv this script makes, default target/sil-cost/venv) on a comparable world
(scripts/lab/sil_cost/irsim_paper.yaml: a car-like robot, a 541-beam 270-degree
lidar scanned every 0.02 s step, one circular obstacle), stepped for the paper run's
simulated seconds. Paired and interleaved: each round is one hyperfine invocation
(`--runs 1`) of both commands, whose order alternates between rounds; the ratio
ugv-sim RTF / IR-SIM RTF is taken per round and its median reported. Wall time is
whole processes (IR-SIM's includes importing Python, numpy and matplotlib); the
IR-SIM runner also prints its stepping loop alone, reported beside. Wall-clock
figures depend on the load: the script prints the load average before and after.

Needs valgrind (instructions), hyperfine and python3 -m venv with network access to
PyPI on the first run (rtf). Exits 1 with a message on a missing tool or bad input.
"""

import argparse
import concurrent.futures
import json
import os
import pathlib
import re
import shlex
import shutil
import statistics
import subprocess
import sys
import tempfile

ROOT = pathlib.Path(__file__).resolve().parents[2]
HERE = pathlib.Path(__file__).resolve().parent / "sil_cost"
PAPER = ROOT / "sim" / "scenarios" / "paper.toml"
SUITE = ROOT / "sim" / "scenarios" / "suite"
BARN = ROOT.parent / "shared" / "benchmarks" / "barn" / "worlds"
IRSIM_SPEC = "ir-sim==2.12.*"

COMMANDS = []  # every command line run, printed at the end


def die(msg):
    print(f"sil_cost: error: {msg}", file=sys.stderr)
    sys.exit(1)


def need(tool, how):
    path = shutil.which(tool)
    if not path:
        die(f"`{tool}` not found on PATH; {how}")
    return path


def run(cmd, **kw):
    COMMANDS.append(shlex.join(str(c) for c in cmd))
    r = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, **kw)
    if r.returncode != 0:
        die(f"command failed ({r.returncode}): {COMMANDS[-1]}\n{r.stderr[-2000:]}")
    return r


def loadavg():
    return " ".join(open("/proc/loadavg").read().split()[:3])


def sim_seconds(results):
    verdict = results / "verdict.json"
    if not verdict.is_file():
        die(f"no {verdict}: the run wrote no verdict")
    t = json.loads(verdict.read_text()).get("time")
    if not isinstance(t, (int, float)) or t <= 0:
        die(f"{verdict} has no positive `time`")
    return float(t)


def callgrind_item(binary, scenario, out):
    stem = scenario.stem
    cg = out / f"{stem}.callgrind"
    res = out / stem
    if res.exists():
        shutil.rmtree(res)
    run(["nice", "-n", "19", "valgrind", "--tool=callgrind", f"--callgrind-out-file={cg}",
         binary, "run", "--sil", "--no-record", scenario, "--results", res])
    m = re.search(r"^(?:totals|summary):\s*(\d+)", cg.read_text(), re.M)
    if not m:
        die(f"no totals line in {cg}")
    ir = int(m.group(1))
    t = sim_seconds(res)
    cg.unlink()  # the profiles are large; the figure is what is kept
    return ir, t


def fmt_m(x):
    return f"{x / 1e6:,.1f} M"


def instructions(args, binary, out):
    need("valgrind", "install it with `apt-get install -y valgrind`")
    if args.barn < 0:
        die("--barn N needs N >= 1 (0, the default, runs no BARN world)")
    groups = [("paper", [PAPER])]
    if args.suite:
        files = sorted(SUITE.glob("*.toml"))
        if not files:
            die(f"no scenarios in {SUITE}")
        groups.append(("suite", files))
    for d in args.scenarios:
        files = sorted(pathlib.Path(d).glob("*.toml"))
        if not files:
            die(f"no scenarios (*.toml) in {d}")
        groups.append((d, files))
    if args.barn:
        worlds = pathlib.Path(args.barn_worlds)
        files = sorted(worlds.glob("*.toml"))
        if not files:
            die(f"no BARN worlds (*.toml) in {worlds}")
        groups.append((f"BARN (every {args.barn}-th)", files[:: args.barn]))
    out.mkdir(parents=True, exist_ok=True)
    print(f"load average before: {loadavg()}", file=sys.stderr)
    lines = ["| group | item | simulated s | instructions | per simulated second |",
             "|---|---|---|---|---|"]
    totals = []

    def item(f):
        print(f"callgrind: {f.name} ...", file=sys.stderr, flush=True)
        ir, t = callgrind_item(binary, f, out)
        # As it goes too, so a long run interrupted keeps what it measured.
        print(f"  {f.stem}: {t:.2f} s simulated, {ir} instructions, {fmt_m(ir / t)} per simulated second",
              file=sys.stderr, flush=True)
        return ir, t

    for name, files in groups:
        sum_ir = sum_t = 0
        # Instruction counts do not depend on the load: items run `--jobs` at a time.
        with concurrent.futures.ThreadPoolExecutor(max_workers=max(1, args.jobs)) as pool:
            measured = list(pool.map(item, files))
        for f, (ir, t) in zip(files, measured):
            sum_ir += ir
            sum_t += t
            lines.append(f"| {name} | {f.stem} | {t:.2f} | {fmt_m(ir)} | {fmt_m(ir / t)} |")
        totals.append(f"| {name} | **total, {len(files)} runs** | {sum_t:.2f} | {fmt_m(sum_ir)} | "
                      f"**{fmt_m(sum_ir / sum_t)}** |")
    print(f"load average after: {loadavg()}", file=sys.stderr)
    print("\n## Instructions per simulated second (callgrind)\n")
    print("\n".join(lines + totals))


def ensure_venv(venv):
    py = venv / "bin" / "python"
    if not py.exists():
        run([sys.executable, "-m", "venv", venv])
    # importlib.metadata only: importing irsim prints matplotlib backend notes on stdout.
    have = subprocess.run([py, "-c", "import importlib.metadata as m; print(m.version('ir-sim'))"],
                          capture_output=True, text=True)
    if have.returncode != 0 or not have.stdout.startswith("2.12."):
        idx = subprocess.run([py, "-m", "pip", "index", "versions", "ir-sim"], capture_output=True, text=True)
        served = re.findall(r"\b2\.12\.\d+\b", idx.stdout)
        spec = IRSIM_SPEC
        if not served:
            nearest = re.search(r"Available versions:\s*([0-9.]+)", idx.stdout)
            if not nearest:
                die(f"`pip index versions ir-sim` found nothing (no network?):\n{idx.stderr[-1000:]}")
            spec = f"ir-sim=={nearest.group(1)}"
            print(f"sil_cost: ir-sim 2.12 is not served; taking {spec}", file=sys.stderr)
        run([py, "-m", "pip", "install", "-q", spec])
        have = run([py, "-c", "import importlib.metadata as m; print(m.version('ir-sim'))"])
    return py, have.stdout.strip()


def rtf(args, binary, out):
    need("hyperfine", "install it with `apt-get install -y hyperfine` (Debian 12 packages it)")
    if args.rounds < 1:
        die("--rounds N needs N >= 1")
    py, version = ensure_venv(pathlib.Path(args.venv).resolve())
    world = HERE / "irsim_paper.yaml"
    runner = HERE / "irsim_run.py"
    out.mkdir(parents=True, exist_ok=True)
    res = out / "paper-rtf"
    ugv = shlex.join([str(binary), "run", "--sil", "--no-record", str(PAPER), "--results", str(res)])
    run(shlex.split(ugv))
    t_sim = sim_seconds(res)
    irs = f"MPLBACKEND=Agg {shlex.quote(str(py))} {shlex.quote(str(runner))} {shlex.quote(str(world))} {t_sim}"
    probe = run(["bash", "-c", irs])
    # IR-SIM prints matplotlib backend notes on stdout; the runner's line is the last.
    probe_line = probe.stdout.strip().splitlines()[-1] if probe.stdout.strip() else ""
    print(f"IR-SIM {version} probe: {probe_line}", file=sys.stderr)
    m = re.search(r"= ([0-9.]+) s simulated", probe_line)
    t_irs = float(m.group(1)) if m else die(f"unexpected runner output: {probe.stdout}")
    print(f"load average before: {loadavg()}", file=sys.stderr)
    pairs, steps_rtf = [], []
    for i in range(args.rounds):
        order = [ugv, irs] if i % 2 == 0 else [irs, ugv]
        js = out / f"round-{i}.json"
        run(["nice", "-n", str(args.nice), "hyperfine", "--runs", "1", "--style", "none",
             "--export-json", js, *order])
        times = {r["command"]: r["times"][0] for r in json.loads(js.read_text())["results"]}
        pairs.append((times[ugv], times[irs]))
        print(f"round {i + 1}/{args.rounds}: ugv-sim {times[ugv]:.3f} s, IR-SIM {times[irs]:.2f} s",
              file=sys.stderr, flush=True)
    print(f"load average after: {loadavg()}", file=sys.stderr)
    u_rtf = [t_sim / u for u, _ in pairs]
    i_rtf = [t_irs / w for _, w in pairs]
    ratio = [a / b for a, b in zip(u_rtf, i_rtf)]
    med = statistics.median
    print(f"\n## Real-time factor, paper scenario against IR-SIM {version} ({args.rounds} paired rounds)\n")
    print("| simulator | simulated s | wall s, median (min-max) | RTF, median (min-max) |")
    print("|---|---|---|---|")
    uw = [u for u, _ in pairs]
    iw = [w for _, w in pairs]
    print(f"| ugv-sim (whole process) | {t_sim:.3f} | {med(uw):.3f} ({min(uw):.3f}-{max(uw):.3f}) | "
          f"{med(u_rtf):.0f} ({min(u_rtf):.0f}-{max(u_rtf):.0f}) |")
    print(f"| IR-SIM {version} (whole process) | {t_irs:.3f} | {med(iw):.2f} ({min(iw):.2f}-{max(iw):.2f}) | "
          f"{med(i_rtf):.2f} ({min(i_rtf):.2f}-{max(i_rtf):.2f}) |")
    print(f"\nugv-sim RTF / IR-SIM RTF per round: median **{med(ratio):.0f}x** "
          f"(min {min(ratio):.0f}, max {max(ratio):.0f}); IR-SIM's stepping loop alone in the probe run: "
          f"{probe_line}")


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("what", choices=["instructions", "rtf", "all"])
    p.add_argument("--bin", default=str(ROOT / "target" / "release" / "ugv-sim"), help="ugv-sim binary")
    p.add_argument("--out", default=str(ROOT / "results" / "sil-cost"), help="results folder (default results/sil-cost)")
    p.add_argument("--suite", action="store_true", help="also every scenario of sim/scenarios/suite (slow)")
    p.add_argument("--scenarios", action="append", default=[], metavar="DIR",
                   help="also every scenario in DIR (a group of its own; may be given again)")
    p.add_argument("--barn", type=int, default=0, metavar="N", help="also every N-th BARN world (1: all 250)")
    p.add_argument("--barn-worlds", default=str(BARN), help=f"BARN worlds folder (default {BARN})")
    p.add_argument("--jobs", type=int, default=1, help="callgrind runs at a time for instructions (default 1)")
    p.add_argument("--rounds", type=int, default=10, help="paired rounds for rtf (default 10)")
    p.add_argument("--venv", default=str(ROOT / "target" / "sil-cost" / "venv"), help="IR-SIM venv")
    p.add_argument("--nice", type=int, default=19, help="niceness of the timed runs (default 19)")
    args = p.parse_args()
    binary = pathlib.Path(args.bin).resolve()
    if not (binary.is_file() and os.access(binary, os.X_OK)):
        die(f"no executable ugv-sim at {binary} (build it: cargo build --release -p ugv-sim, or pass --bin)")
    if not PAPER.is_file():
        die(f"no {PAPER}")
    out = pathlib.Path(args.out).resolve()
    if args.what in ("instructions", "all"):
        instructions(args, binary, out)
    if args.what in ("rtf", "all"):
        rtf(args, binary, out)
    print("\nCommands run:\n")
    for c in COMMANDS:
        print(f"    {c}")


if __name__ == "__main__":
    main()
