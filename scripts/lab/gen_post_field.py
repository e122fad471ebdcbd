#!/usr/bin/env python3
"""Write the post-field scenario (sim/scenarios/suite/68-post-field.toml): posts of
radius 0.21 m on a 0.42 m lattice (touching, so a run of them is a wall, as in BARN,
whose cylinders sit on a lattice and pack into walls), in three fences across a
walled field with BARN-like gaps (2.10 and 2.52 m: 5 and 6 missing posts), offset
from one another, and two short walls between them.

    scripts/lab/gen_post_field.py [--out sim/scenarios/suite/68-post-field.toml]

Deterministic (no randomness): the layout is written out below in lattice cells
(x = 0.42 i, y = 0.42 j).
"""

import argparse
import math
import pathlib

ROOT = pathlib.Path(__file__).resolve().parent.parent.parent
CELL = 0.42
RADIUS = 0.21

# Fences across the field: (column i, [(j_from, j_to) of the posts]).
FENCES = [
    # x = 6.72: a 2.52 m gap centred at y = 0.63 (posts at j = -2 and 5), and a 2.10 m one
    # at y = -3.78 (posts at j = -12 and -6).
    (16, [(-15, -12), (-6, -2), (5, 15)]),
    # x = 14.28: a 2.10 m gap centred at y = -1.26 (posts at j = -6 and 0).
    (34, [(-15, -6), (0, 15)]),
    # x = 21.84: a 2.52 m gap centred at y = 1.05 (posts at j = -1 and 6).
    (52, [(-15, -1), (6, 15)]),
]
# Short walls along the field: (row j, i_from, i_to).
RUNS = [(6, 20, 28), (-8, 38, 46)]
# The field's sides (j = -16 and 16: faces 6.51 m off the line) and the pen behind the start.
SIDES = (-16, 16, -5, 70)
PEN = -5

WITNESS = [
    "F 1 | FL 26.37 r=3 | FR 26.37 r=3 | F 3.63",
    "FR 46.72 r=3 | FL 46.72 r=3 | F 3.40",
    "FL 56.25 r=2.6 | FR 56.25 r=2.6 | TO 26 1.05",
]


def posts():
    out = set()
    for i, spans in FENCES:
        for a, b in spans:
            for j in range(a, b + 1):
                out.add((i, j))
    for j, a, b in RUNS:
        for i in range(a, b + 1):
            out.add((i, j))
    lo, hi, i0, i1 = SIDES
    for i in range(i0, i1 + 1):
        out.add((i, lo))
        out.add((i, hi))
    for j in range(lo, hi + 1):
        out.add((PEN, j))
    return sorted(out)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default=str(ROOT / "sim/scenarios/suite/68-post-field.toml"))
    args = ap.parse_args()
    ps = posts()
    lines = [
        'name = "post-field"',
        f'description = "A BARN-like field of {len(ps)} posts (radius 0.21 m on a 0.42 m lattice, touching, so that runs of them are walls) between post walls 13 m apart: three fences across it 7.56 m apart with gaps of 2.52, 2.10 and 2.52 m (0.66, 0.45 and 0.66 m either side of the car square in them), offset by 1.9 and 2.3 m from one another, a decoy 2.10 m gap in the first, and two short walls between the fences. The car threads the gaps to the goal 26 m ahead without contact (BARN counts any contact a failure; here at least 0.1 m)"',
        "",
        "# Written by scripts/lab/gen_post_field.py: edit that, not this file.",
        "# Witness (scripts/lab/tight_witness.py): S-bends of 3 and 2.6 m radius between the",
        "# fences, square through each gap: least clearance 0.45 m (the 2.10 m gap).",
    ]
    for k, w in enumerate(WITNESS):
        lines.append("# witness: " + w + (" |" if k + 1 < len(WITNESS) else ""))
    lines += [
        "",
        "[start]",
        "x = 0.0",
        "y = 0.0",
        "heading_deg = 0.0",
        "",
        "[goal]",
        "x = 26.0",
        "y = 1.0",
        "tolerance = 1.0",
        "",
        "[sim]",
        "time_limit_s = 120.0",
        "",
        "[success]",
        "reach_goal = true",
        "min_clearance = 0.1",
    ]
    for i, j in ps:
        lines += [
            "",
            "[[obstacles]]",
            'kind = "circle"',
            f"x = {round(i * CELL, 2)}",
            f"y = {round(j * CELL, 2)}",
            f"radius = {RADIUS}",
        ]
    pathlib.Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"{args.out}: {len(ps)} posts")


if __name__ == "__main__":
    main()
