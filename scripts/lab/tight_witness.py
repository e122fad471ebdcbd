#!/usr/bin/env python3
"""Check that a scenario is geometrically possible for the car: drive the manoeuvre
written in the file's `# witness:` comment lines (a hand-made path, not the controller's)
with the car's exact rectangle and report its closest approach to every obstacle.

    scripts/lab/tight_witness.py FILE.toml [FILE.toml ...] [--plot OUT.svg]

The witness is a list of segments separated by `|`, continued over several
`# witness:` lines, driven from the scenario's start (the rear axle):

    F 12.5       forward 12.5 m straight        R 3.0     reverse 3.0 m straight
    FL 90        forward at full left lock through 90 degrees of heading
    FR 45        forward, full right lock       RL 30 / RR 30   reverse, wheels left / right
    FL 90 r=4    the same on a circle of radius 4 m at the rear axle (r >= the minimum)
    TO x y       forward straight to the point (x, y) (turn first so it lies ahead)

The car is the scenario's [vehicle] (default the seed paper's golf car: 2.4 m x 1.2 m,
wheelbase 1.65 m, rear overhang 0.375 m, 35 degrees of lock: 2.36 m radius at the rear
axle). Obstacles are the world's: circles, boxes, and walls as one box per segment
(flat ends) with a post of the thickness at each inner joint. It prints the witness's
length, its cusps, the least clearance and where, and the end pose against the goal.
"""

import math
import pathlib
import sys
import tomllib

LENGTH, WIDTH, WHEELBASE, OVERHANG, MAX_STEER = 2.4, 1.2, 1.65, 0.375, 35.0
STEP = 0.02


def box_poly(cx, cy, length, width, heading):
    c, s = math.cos(heading), math.sin(heading)
    pts = []
    for lx, ly in ((length / 2, width / 2), (-length / 2, width / 2), (-length / 2, -width / 2), (length / 2, -width / 2)):
        pts.append((cx + c * lx - s * ly, cy + s * lx + c * ly))
    return pts


def obstacles(sc):
    out = []
    for i, o in enumerate(sc.get("obstacles", [])):
        k = o["kind"]
        if k == "circle":
            out.append((i, "circle", (o["x"], o["y"], o["radius"])))
        elif k == "box":
            out.append((i, "poly", box_poly(o["x"], o["y"], o["length"], o["width"], math.radians(o.get("heading_deg", 0.0)))))
        elif k == "wall":
            p, t = o["points"], o["thickness"]
            for a, b in zip(p, p[1:]):
                dx, dy = b[0] - a[0], b[1] - a[1]
                out.append((i, "poly", box_poly((a[0] + b[0]) / 2, (a[1] + b[1]) / 2, math.hypot(dx, dy), t, math.atan2(dy, dx))))
            for q in p[1:-1]:
                out.append((i, "circle", (q[0], q[1], t / 2)))
    return out


def seg_point(p, a, b):
    ax, ay = a
    bx, by = b
    dx, dy = bx - ax, by - ay
    L2 = dx * dx + dy * dy
    t = 0.0 if L2 == 0 else max(0.0, min(1.0, ((p[0] - ax) * dx + (p[1] - ay) * dy) / L2))
    return math.hypot(p[0] - ax - t * dx, p[1] - ay - t * dy)


def inside(p, poly):
    # Convex polygon, either winding.
    sign = 0
    for a, b in zip(poly, poly[1:] + poly[:1]):
        cr = (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])
        if cr != 0:
            if sign == 0:
                sign = 1 if cr > 0 else -1
            elif (cr > 0) != (sign > 0):
                return False
    return True


def seg_seg(a, b, c, d):
    def cross(o, p, q):
        return (p[0] - o[0]) * (q[1] - o[1]) - (p[1] - o[1]) * (q[0] - o[0])

    d1, d2, d3, d4 = cross(c, d, a), cross(c, d, b), cross(a, b, c), cross(a, b, d)
    if ((d1 > 0) != (d2 > 0)) and ((d3 > 0) != (d4 > 0)):
        return 0.0
    return min(seg_point(a, c, d), seg_point(b, c, d), seg_point(c, a, b), seg_point(d, a, b))


def poly_dist(P, Q):
    if inside(P[0], Q) or inside(Q[0], P):
        return 0.0
    best = math.inf
    for a, b in zip(P, P[1:] + P[:1]):
        for c, d in zip(Q, Q[1:] + Q[:1]):
            best = min(best, seg_seg(a, b, c, d))
    return best


def clearance(car, shape):
    kind, g = shape
    if kind == "circle":
        cx, cy, r = g
        if inside((cx, cy), car):
            return 0.0
        return max(0.0, min(seg_point((cx, cy), a, b) for a, b in zip(car, car[1:] + car[:1])) - r)
    return poly_dist(car, g)


def car_poly(x, y, th, car):
    length, width, overhang = car
    cx = x + math.cos(th) * (length / 2 - overhang)
    cy = y + math.sin(th) * (length / 2 - overhang)
    return box_poly(cx, cy, length, width, th)


def parse_witness(text):
    lines = [l.split("witness:", 1)[1] for l in text.splitlines() if l.startswith("#") and "witness:" in l]
    return [s.split() for s in " ".join(lines).split("|") if s.strip()]


def drive(start, segs, rmin):
    """Poses (x, y, theta, gear) every STEP metres along the witness."""
    x, y, th = start
    poses = [(x, y, th, 1)]
    cusps = 0
    last_gear = None
    for s in segs:
        op = s[0].upper()
        if op == "TO":
            tx, ty = float(s[1]), float(s[2])
            dist = math.hypot(tx - x, ty - y)
            ahead = math.cos(th) * (tx - x) + math.sin(th) * (ty - y)
            if dist > 1e-6 and ahead < 0.999 * dist:
                raise ValueError(f"TO {tx} {ty}: not straight ahead of ({x:.2f}, {y:.2f}, {math.degrees(th):.1f} deg)")
            gear, kappa, length = 1, 0.0, dist
        else:
            gear = 1 if op[0] == "F" else -1
            side = op[1:] if len(op) > 1 else ""
            if side == "":
                kappa, length = 0.0, float(s[1])
            else:
                r = rmin
                for extra in s[2:]:
                    if extra.startswith("r="):
                        r = float(extra[2:])
                if r < rmin - 1e-9:
                    raise ValueError(f"radius {r} below the car's {rmin:.3f} m")
                kappa = (1 if side == "L" else -1) / r
                length = math.radians(float(s[1])) * r
        if last_gear is not None and gear != last_gear and length > 0:
            cusps += 1
        if length > 0:
            last_gear = gear
        n = max(1, int(math.ceil(length / STEP)))
        ds = length / n
        for _ in range(n):
            # Exact arc steps (heading rate = signed speed x curvature).
            dth = gear * ds * kappa
            if kappa == 0.0:
                x += gear * ds * math.cos(th)
                y += gear * ds * math.sin(th)
            else:
                r = 1.0 / kappa
                x += r * (math.sin(th + dth) - math.sin(th))
                y += -r * (math.cos(th + dth) - math.cos(th))
            th += dth
            poses.append((x, y, th, gear))
    return poses, cusps


def check(path):
    text = pathlib.Path(path).read_text()
    sc = tomllib.loads(text)
    v = sc.get("vehicle", {})
    car = (v.get("length", LENGTH), v.get("width", WIDTH), v.get("rear_overhang", OVERHANG))
    rmin = v.get("wheelbase", WHEELBASE) / math.tan(math.radians(v.get("max_steer_deg", MAX_STEER)))
    st = sc.get("start", {})
    start = (st.get("x", 0.0), st.get("y", 0.0), math.radians(st.get("heading_deg", 0.0)))
    segs = parse_witness(text)
    if not segs:
        print(f"{path}: no witness")
        return None
    poses, cusps = drive(start, segs, rmin)
    obs = obstacles(sc)
    per = {}
    where = {}
    bbox = {}
    for _, kind, g in obs:
        if kind == "circle":
            bbox[id(g)] = (g[0] - g[2], g[1] - g[2], g[0] + g[2], g[1] + g[2])
        else:
            bbox[id(g)] = (min(p[0] for p in g), min(p[1] for p in g), max(p[0] for p in g), max(p[1] for p in g))
    for x, y, th, _ in poses:
        P = car_poly(x, y, th, car)
        for i, kind, g in obs:
            # Cheap reject: the shape's bounding box more than 4 m from the rear axle
            # (the car reaches 2.1 m from it).
            bx0, by0, bx1, by1 = bbox[id(g)]
            if max(bx0 - x, x - bx1, 0.0) > 4.0 or max(by0 - y, y - by1, 0.0) > 4.0:
                continue
            c = clearance(P, (kind, g))
            if c < per.get(i, math.inf):
                per[i] = c
                where[i] = (x, y, math.degrees(th))
    goal = sc.get("goal", {})
    end = poses[-1]
    length = len(poses) * STEP
    gdist = math.hypot(end[0] - goal.get("x", 30.0), end[1] - goal.get("y", 15.0))
    least = min(per, key=per.get) if per else None
    print(f"{path}: witness {sum(1 for _ in segs)} segments, about {length:.1f} m, {cusps} cusps;"
          f" end ({end[0]:.2f}, {end[1]:.2f}, {math.degrees(end[2]):.1f} deg), {gdist:.2f} m from the goal"
          f" (tolerance {goal.get('tolerance', 1.0)})")
    if least is not None:
        w = where[least]
        print(f"  least clearance {per[least]:.3f} m to obstacle {least} (rear axle at {w[0]:.2f}, {w[1]:.2f}, {w[2]:.1f} deg)")
        tight = sorted(per.items(), key=lambda kv: kv[1])[:5]
        print("  closest five: " + ", ".join(f"#{i} {c:.3f}" for i, c in tight))
    return per[least] if least is not None else math.inf, poses


def main():
    args = sys.argv[1:]
    plot = None
    if "--plot" in args:
        k = args.index("--plot")
        plot = args[k + 1]
        del args[k : k + 2]
    for f in args:
        res = check(f)
        if plot and res:
            write_svg(f, res[1], plot)
    return 0


def write_svg(path, poses, out):
    sc = tomllib.loads(pathlib.Path(path).read_text())
    obs = obstacles(sc)
    xs = [p[0] for p in poses]
    ys = [p[1] for p in poses]
    for _, kind, g in obs:
        if kind == "circle":
            xs.append(g[0]); ys.append(g[1])
        else:
            xs += [p[0] for p in g]; ys += [p[1] for p in g]
    x0, x1, y0, y1 = min(xs) - 2, max(xs) + 2, min(ys) - 2, max(ys) + 2
    s = 800 / max(x1 - x0, y1 - y0)
    X = lambda x: (x - x0) * s
    Y = lambda y: (y1 - y) * s
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{(x1-x0)*s:.0f}" height="{(y1-y0)*s:.0f}">']
    for _, kind, g in obs:
        if kind == "circle":
            parts.append(f'<circle cx="{X(g[0]):.1f}" cy="{Y(g[1]):.1f}" r="{g[2]*s:.1f}" fill="green"/>')
        else:
            pts = " ".join(f"{X(a):.1f},{Y(b):.1f}" for a, b in g)
            parts.append(f'<polygon points="{pts}" fill="gray"/>')
    car = (LENGTH, WIDTH, OVERHANG)
    for k, (x, y, th, gear) in enumerate(poses):
        if k % 25 == 0:
            pts = " ".join(f"{X(a):.1f},{Y(b):.1f}" for a, b in car_poly(x, y, th, car))
            col = "blue" if gear > 0 else "red"
            parts.append(f'<polygon points="{pts}" fill="none" stroke="{col}" stroke-width="0.5"/>')
    parts.append("</svg>")
    pathlib.Path(out).write_text("\n".join(parts))


if __name__ == "__main__":
    sys.exit(main())
