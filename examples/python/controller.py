#!/usr/bin/env python3
"""A golf car controller of its own, on ugv-sim's wires (docs/wire-contract.md).

GPS: NMEA 0183 with pyserial. Laser: iceoryx2 frames. CAN: python-can and cantools
with the E2E counter and CRC done here. It drives to the mission's goal, steering
round what the laser sees: each GPS epoch it scores arcs of constant curvature by
their clearance to the laser's points and by the heading towards the goal at their end.

    python controller.py RESULTS_DIR   # the --results of `ugv-sim run --wait-for-controller`
"""
import argparse, ctypes, json, math, os, signal, sys, time, tomllib

import can, cantools, serial
import iceoryx2 as iox2

DBC = os.path.join(os.path.dirname(os.path.abspath(__file__)), "../../can-dbc/golf_car.dbc")
MAX_BEAMS = 1081
SPEED = 1.8          # cruise, m/s
LOOK = 8.0           # length of the arcs scored, m
CLEAR = 1.6          # rear-axle line to a laser point, at least, m (half width 0.6 m + margin)
ARCS = 15            # curvatures scored, -max to +max
MISTAKE = os.environ.get("UGV_EXAMPLE_ENABLE_MISTAKE") == "1"  # for a test: no enable edge


class LaserFrame(ctypes.Structure):
    """ugv_hil::LaserFrame::v1: 8696 bytes, alignment 8 (the Rust #[repr(C)] struct)."""
    _fields_ = [("version", ctypes.c_uint32), ("count", ctypes.c_uint32),
                ("sequence", ctypes.c_uint64), ("stamp_ns", ctypes.c_uint64),
                ("angle_min", ctypes.c_float), ("angle_increment", ctypes.c_float),
                ("time_increment", ctypes.c_float), ("scan_time", ctypes.c_float),
                ("range_min", ctypes.c_float), ("range_max", ctypes.c_float),
                ("ranges", ctypes.c_float * MAX_BEAMS),
                ("intensities", ctypes.c_float * MAX_BEAMS)]

    @staticmethod
    def type_name():
        return "ugv_hil::LaserFrame::v1"


def crc8(data):
    """CRC-8/SAE-J1850: poly 0x1D, init 0xFF, xor-out 0xFF (check value 0x4B)."""
    crc = 0xFF
    for b in data:
        crc ^= b
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1D) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc ^ 0xFF


class Can:
    """The bus with E2E: one counter per ID sent, CRC and counter checked on receipt."""

    def __init__(self, iface):
        self.db = cantools.database.load_file(DBC)
        ids = [0x101, 0x111, 0x0F0]
        self.bus = can.Bus(interface="socketcan", channel=iface,
                           can_filters=[{"can_id": i, "can_mask": 0x7FF} for i in ids])
        self.counter, self.last, self.rejected, self.sent = {}, {}, 0, 0

    def send(self, name, **signals):
        msg = self.db.get_message_by_name(name)
        c = self.counter.get(msg.frame_id, 0)
        data = bytearray(msg.encode(dict(signals, Counter=c, Crc=0)))
        data[7] = crc8(msg.frame_id.to_bytes(2, "big") + bytes(data[:7]))
        self.bus.send(can.Message(arbitration_id=msg.frame_id, data=data, is_extended_id=False))
        self.counter[msg.frame_id] = (c + 1) % 16
        self.sent += 1

    def receive(self):
        """Every frame waiting, E2E-checked and decoded: [(name, signals)]."""
        out = []
        while (m := self.bus.recv(0)) is not None:
            d = bytes(m.data)
            if len(d) != 8 or d[7] != crc8(m.arbitration_id.to_bytes(2, "big") + d[:7]):
                self.rejected += 1
                continue
            key = (m.arbitration_id, d[0] & 0x0F if m.arbitration_id == 0x0F0 else 0)
            last = self.last.get(key)
            self.last[key] = d[6] & 0x0F
            if last is not None and d[6] & 0x0F != (last + 1) % 16:
                self.rejected += 1      # repeated or skipped; resynchronised on it
                continue
            msg = self.db.get_message_by_frame_id(m.arbitration_id)
            out.append((msg.name, msg.decode(d, decode_choices=False)))
        return out


def ecef(lat, lon, h):
    a, f = 6378137.0, 1 / 298.257223563
    e2 = f * (2 - f)
    lat, lon = math.radians(lat), math.radians(lon)
    n = a / math.sqrt(1 - e2 * math.sin(lat) ** 2)
    return ((n + h) * math.cos(lat) * math.cos(lon), (n + h) * math.cos(lat) * math.sin(lon),
            (n * (1 - e2) + h) * math.sin(lat))


def enu(datum, lat, lon, h):
    """WGS-84 to east/north at the datum (exact, through ECEF)."""
    la, lo = math.radians(datum["latitude"]), math.radians(datum["longitude"])
    p, p0 = ecef(lat, lon, h), ecef(datum["latitude"], datum["longitude"], datum["altitude"])
    dx, dy, dz = (p[i] - p0[i] for i in range(3))
    e = -math.sin(lo) * dx + math.cos(lo) * dy
    n = -math.sin(la) * math.cos(lo) * dx - math.sin(la) * math.sin(lo) * dy + math.cos(la) * dz
    return e, n


def nmea(line):
    """The fields of a sentence with a good checksum, or None."""
    if not line.startswith("$") or "*" not in line:
        return None
    body, _, given = line[1:].partition("*")
    sum_ = 0
    for ch in body.encode():
        sum_ ^= ch
    return body.split(",") if given[:2].upper() == f"{sum_:02X}" else None


def deg(ddmm, hemi, width):
    v = float(ddmm[:width]) + float(ddmm[width:]) / 60
    return -v if hemi in "SW" else v


def wrap(a):
    return (a + math.pi) % (2 * math.pi) - math.pi


def open_laser(service):
    """Open (never create) the simulator's frame and event services, then subscribe."""
    iox2.set_log_level_from_env_or(iox2.LogLevel.Error)
    node = iox2.NodeBuilder.new().signal_handling_mode(
        iox2.SignalHandlingMode.Disabled).create(iox2.ServiceType.Ipc)
    name = iox2.ServiceName.new(service)
    frames = (node.service_builder(name).publish_subscribe(LaserFrame).history_size(1)
              .subscriber_max_buffer_size(16).max_subscribers(8).enable_safe_overflow(True)
              .open())
    node.service_builder(name).event().open()
    return node, frames.subscriber_builder().buffer_size(16).create()


def plan(pose, points, goal, veh):
    """The curvature to drive and the clearance it keeps (None: every arc is blocked)."""
    x, y, th = pose
    kmax = math.tan(math.radians(min(veh["max_steer_deg"], 30.0))) / veh["wheelbase"]
    look = max(2.0, min(LOOK, math.hypot(goal[0] - x, goal[1] - y)))
    best = None
    for i in range(ARCS):
        k = -kmax + 2 * kmax * i / (ARCS - 1)
        clear = math.inf
        for px, py in points:
            if abs(k) < 1e-6:
                s, d = px, abs(py)
            else:
                r = 1 / k
                s = math.atan2(px / r, -(py - r) / r) / k
                d = abs(math.hypot(px, py - r) - abs(r))
            if -0.5 < s < look:
                clear = min(clear, d)
        if clear < CLEAR:
            continue
        if abs(k) < 1e-6:
            ex, ey = look, 0.0
        else:
            ex, ey = math.sin(k * look) / k, (1 - math.cos(k * look)) / k
        wx = x + ex * math.cos(th) - ey * math.sin(th)
        wy = y + ex * math.sin(th) + ey * math.cos(th)
        cost = abs(wrap(math.atan2(goal[1] - wy, goal[0] - wx) - (th + k * look)))
        if best is None or cost < best[0]:
            best = (cost, k, clear)
    return (best[1], best[2]) if best else (None, 0.0)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("results", help="ugv-sim's --results directory (wires.json, mission.toml)")
    args = ap.parse_args()
    last = os.path.join(args.results, "controller.toml")
    for _ in range(600):                      # written after wires.json and mission.toml
        if os.path.exists(last):
            break
        time.sleep(0.1)
    with open(os.path.join(args.results, "wires.json")) as f:
        wires = json.load(f)
    with open(os.path.join(args.results, "mission.toml"), "rb") as f:
        mission = tomllib.load(f)
    if wires.get("version") != 1 or mission.get("version") != 1:
        sys.exit("controller: wires.json and mission.toml of version 1 expected")
    veh, goal = mission["vehicle"], (mission["goal"]["x"], mission["goal"]["y"])
    gps = serial.Serial(wires["gps_link"], wires["gps_baud"], timeout=0)
    _node, laser = open_laser(wires["laser_service"])
    bus = Can(wires["can"])
    print(f"controller: wires {wires}", file=sys.stderr, flush=True)
    stop = []
    signal.signal(signal.SIGINT, lambda *_: stop.append("signal"))
    signal.signal(signal.SIGTERM, lambda *_: stop.append("signal"))

    pose, gga, points = None, None, None
    reports, last_report = {}, None
    state, since, tries = "wait", time.monotonic(), 0
    k, speed, tick, buf, end = 0.0, 0.0, 0, b"", None
    next_tick = time.monotonic()
    while end is None:
        now = time.monotonic()
        try:                                   # GPS: whole lines, GGA and HDT
            buf += gps.read(4096)
        except (serial.SerialException, OSError) as e:
            end = f"the GPS line closed ({e.__class__.__name__})"
            break
        new_fix = False
        *lines, buf = buf.split(b"\n")
        for raw in lines:                      # an epoch: GGA, RMC, VTG, GST, HDT, ZDA
            f = nmea(raw.decode("ascii", "replace").strip())
            if f and f[0].endswith("GGA"):
                gga = f if int(f[6] or 0) > 0 else None     # quality 0: no fix
            elif f and f[0].endswith("HDT") and f[1] and gga:
                th = math.radians(90.0 - float(f[1]))       # theta = 90 deg - HDT
                ax, ay = enu(mission["datum"], deg(gga[2], gga[3], 2), deg(gga[4], gga[5], 3),
                             float(gga[9]) + float(gga[11]))
                c, s = math.cos(th), math.sin(th)           # GGA is the antenna
                pose = (ax - c * veh["antenna_x"] + s * veh["antenna_y"],
                        ay - s * veh["antenna_x"] - c * veh["antenna_y"], th)
                new_fix, gga = True, None
        scan = None                            # laser: the newest frame, copied out; each
        while (sample := laser.receive()) is not None:   # sample goes back before the next
            fr = sample.payload().contents     # is taken (a subscriber may hold only 2)
            scan = (fr.count, fr.angle_min, fr.angle_increment, fr.range_min, fr.ranges[:fr.count])
            del fr, sample
        if scan is not None:
            n, a0, da, rmin, ranges = scan
            yaw = math.radians(veh["laser_yaw_deg"])
            points = [(veh["laser_x"] + r * math.cos(a0 + i * da + yaw),
                       veh["laser_y"] + r * math.sin(a0 + i * da + yaw))
                      for i in range(0, n, 2) for r in (ranges[i],) if rmin <= r < 10.0]
        for name, sig in bus.receive():        # CAN: the ECUs' reports
            reports[name] = sig
            if name in ("STEERING_REPORT", "THROTTLE_REPORT"):
                last_report = now
            elif name == "FAULT_REPORT":
                print(f"controller: FAULT_REPORT {sig}", file=sys.stderr, flush=True)
        if last_report is not None and now - last_report > 0.5:
            end = "the ECUs' reports stopped"
        if stop:
            end = "stopped by a signal"
        enabled = [reports.get(r, {}).get("Enabled") == 1
                   for r in ("STEERING_REPORT", "THROTTLE_REPORT")]
        # The enable sequence (docs/wire-contract.md): idle until every wire is there,
        # then auto, then at least one auto heartbeat later the Enable 0 -> 1 edge.
        if state == "wait" and pose and points is not None and "STEERING_REPORT" in reports \
                and "THROTTLE_REPORT" in reports:
            state, since = "auto", now
        elif state == "auto" and now - since > 0.06:
            state, since = "edge", now
        elif state == "edge" and all(enabled):
            state = "drive"
            print("controller: both ECUs enabled, driving", file=sys.stderr, flush=True)
        elif state == "edge" and now - since > 1.0 or state == "drive" and not all(enabled):
            tries += 1
            faults = [reports.get(r, {}).get("Fault") for r in ("STEERING_REPORT", "THROTTLE_REPORT")]
            print(f"controller: ECUs not enabled (faults {faults}), enabling again",
                  file=sys.stderr, flush=True)
            state, since = ("auto", now) if tries < 5 else ("stop", now)
        if state == "drive" and new_fix:
            k, clear = plan(pose, points or [], goal, veh)
            near = math.hypot(goal[0] - pose[0], goal[1] - pose[1]) < mission["goal"]["tolerance"]
            speed = 0.0 if k is None or near else (SPEED if clear > 2.5 else 1.0)
            k = k or 0.0
        if now >= next_tick:                    # commands every 10 ms, heartbeat every 20 ms
            on = state in ("edge", "drive") or MISTAKE   # MISTAKE: Enable = 1 from the start
            if tick % 2 == 0:
                bus.send("CONTROLLER_HEARTBEAT", State=1 if state in ("auto", "edge", "drive") else 0)
            steer = math.degrees(math.atan(k * veh["wheelbase"])) if state == "drive" else 0.0
            bus.send("STEERING_CMD", Enable=int(on), TargetAngle=round(steer, 2), MaxRate=0)
            v = speed if state == "drive" else 0.0
            bus.send("THROTTLE_CMD", Enable=int(on), Gear=1, TargetSpeed=round(v, 2),
                     Brake=0 if v > 0 else 100, AccelLimit=0)
            tick += 1
            next_tick = max(next_tick + 0.01, now - 0.05)
            if tick % 100 == 0 and pose:
                print(f"controller: {state} x={pose[0]:6.2f} y={pose[1]:6.2f} "
                      f"hdg={math.degrees(pose[2]):6.1f} steer={steer:5.1f} v={v:.1f}",
                      file=sys.stderr, flush=True)
        time.sleep(max(0.0, min(0.005, next_tick - time.monotonic())))
    print(f"controller: run over: {end}; last pose {pose}; sent {bus.sent} frames, "
          f"rejected {bus.rejected}", file=sys.stderr, flush=True)
    if end == "stopped by a signal":            # leave the ECUs disabled, braking
        for _ in range(3):
            bus.send("CONTROLLER_HEARTBEAT", State=0)
            bus.send("STEERING_CMD", Enable=0, TargetAngle=0, MaxRate=0)
            bus.send("THROTTLE_CMD", Enable=0, Gear=1, TargetSpeed=0, Brake=100, AccelLimit=0)
            time.sleep(0.01)
    bus.bus.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
