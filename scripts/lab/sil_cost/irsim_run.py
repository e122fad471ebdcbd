#!/usr/bin/env python3
"""Run the IR-SIM counterpart of the paper scenario headless for a fixed simulated
duration (scripts/lab/sil-cost.sh). Usage: irsim_run.py WORLD.yaml SECONDS.

Steps the world SECONDS / step_time times whatever the robot does (arrival or
contact do not end the run: the lidar is scanned at every step either way), then
prints one line: steps, simulated seconds, wall seconds, real-time factor, whether
the robot arrived, and the beams of the last scan."""

import sys
import time


def main():
    if len(sys.argv) != 3:
        sys.exit("usage: irsim_run.py WORLD.yaml SECONDS")
    world, seconds = sys.argv[1], float(sys.argv[2])
    import irsim

    t0 = time.perf_counter()
    env = irsim.make(world, display=False, headless=True, log_level="WARNING")
    dt = env.step_time
    steps = round(seconds / dt)
    t1 = time.perf_counter()
    for _ in range(steps):
        env.step()
    wall = time.perf_counter() - t1
    setup = t1 - t0
    robot = env.robot
    beams = len(robot.get_lidar_scan()["ranges"])
    print(
        f"irsim {irsim.__version__ if hasattr(irsim, '__version__') else '?'}: {steps} steps of {dt} s = "
        f"{steps * dt:.3f} s simulated in {wall:.3f} s wall of stepping (RTF {steps * dt / wall:.1f}; "
        f"make {setup:.2f} s), "
        f"arrived {robot.arrive}, collision {robot.collision}, {beams} beams"
    )
    env.end(0)


if __name__ == "__main__":
    main()
