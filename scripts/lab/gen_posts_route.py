#!/usr/bin/env python3
"""Write a straight route lined with posts, for how SIL's cost grows with obstacles
(issue 37: instructions per simulated second against the posts in the world and
against those within the laser's reach).

    scripts/lab/gen_posts_route.py POSTS [--length 100] [--out FILE]

The car drives from (0, 0) east to (LENGTH, 0). The posts (radius 0.15 m) stand in
two rows 4 m either side of the line, alternately left and right, evenly from x = 5 m
to LENGTH - 5 m: clear of the car's way (it drives straight), all in the laser's
view as it passes. So, at a fixed length, more posts are more posts within reach; at a
fixed spacing (posts per metre), a longer route is more posts in the world with the
same number within reach. Prints the file's path.
"""

import argparse
import pathlib

SIDE = 4.0  # metres either side of the route's line
RADIUS = 0.15
MARGIN = 5.0  # no post within this of the start or the goal, along the line


def scenario(posts: int, length: float) -> str:
    lines = [
        f'name = "posts-route-{posts}-{int(length)}m"',
        f'description = "A straight {length:.0f} m route between two rows of {posts} posts in all, '
        f'{SIDE:.0f} m either side (scripts/lab/gen_posts_route.py)"',
        "",
        "[start]\nx = 0.0\ny = 0.0\nheading_deg = 0.0",
        "",
        f"[goal]\nx = {length:.1f}\ny = 0.0",
        "",
        f"[sim]\ntime_limit_s = {length / 1.0 + 30.0:.1f}",
        "",
        "[success]\nreach_goal = true\nmin_clearance = 0.3",
    ]
    span = length - 2 * MARGIN
    for k in range(posts):
        x = MARGIN + (span * k / (posts - 1) if posts > 1 else span / 2)
        y = SIDE if k % 2 == 0 else -SIDE
        lines += ["", "[[obstacles]]", 'kind = "circle"', f"x = {x:.3f}", f"y = {y:.1f}",
                  f"radius = {RADIUS}"]
    return "\n".join(lines) + "\n"


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("posts", type=int)
    p.add_argument("--length", type=float, default=100.0, help="route length, metres (default 100)")
    p.add_argument("--out", help="file to write (default posts-route-POSTS-LENGTHm.toml here)")
    a = p.parse_args()
    if a.posts < 1 or a.length <= 2 * MARGIN:
        p.error(f"need POSTS >= 1 and --length > {2 * MARGIN:.0f} m")
    out = pathlib.Path(a.out or f"posts-route-{a.posts}-{int(a.length)}m.toml")
    out.write_text(scenario(a.posts, a.length))
    print(out)


if __name__ == "__main__":
    main()
