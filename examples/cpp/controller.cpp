// A golf car controller of one's own on ugv-sim's wires (docs/wire-contract.md) in C++17: NMEA with
// termios, laser frames through ugv_laser.h (iceoryx2 0.10 behind a C ABI, laser-c/), SocketCAN raw
// sockets with golf_car.dbc's signals, E2E counter and CRC by hand; arcs round obstacles; README.md
#include <fcntl.h>
#include <linux/can.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <poll.h>
#include <sys/socket.h>
#include <termios.h>
#include <unistd.h>
#include <array>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <map>
#include <string>
#include <vector>
#include "laser-c/ugv_laser.h"
static_assert(sizeof(ugv_laser_frame_v1) == 8696 && alignof(ugv_laser_frame_v1) == 8,
              "ugv_hil::LaserFrame::v1 is 8696 bytes, 8-aligned (docs/wire-contract.md)");
#define SAY(...) (std::fprintf(stderr, "ugv-example-cpp: " __VA_ARGS__), std::fputc('\n', stderr))

namespace {
using Ms = std::chrono::milliseconds;
using Strings = std::vector<std::string>;
constexpr double SPEED = 1.8, LOOK = 8.0;  // cruise (m/s), length of the arcs scored (m)
constexpr double CLEAR = 1.6;  // rear-axle line to a laser point, at least, m (half width + margin)
constexpr int ARCS = 15;       // curvatures scored, -max to +max
constexpr double PI = 3.14159265358979323846, RAD = PI / 180;
volatile std::sig_atomic_t stopped = 0;
[[noreturn]] void die(const std::string &what) {
  SAY("%s: %s", what.c_str(), std::strerror(errno)), std::exit(1);
}

// ---- CAN: golf_car.dbc's signals (little-endian) by hand, the E2E counter and CRC
using Data = std::array<uint8_t, 8>;
enum Id : uint16_t { HEARTBEAT = 0x080, STEERING_CMD = 0x100, STEERING_REPORT = 0x101,
                     THROTTLE_CMD = 0x110, THROTTLE_REPORT = 0x111, FAULT_REPORT = 0x0F0 };
// CRC-8/SAE-J1850: polynomial 0x1D, initial value 0xFF, no reflection, final XOR 0xFF.
template <class T> constexpr uint8_t crc8(const T *p, size_t n, uint8_t crc = 0xFF) {
  for (size_t i = 0; i < 8 * n; ++i) {
    if (i % 8 == 0) crc ^= uint8_t(p[i / 8]);
    crc = uint8_t(crc & 0x80 ? crc << 1 ^ 0x1D : crc << 1);
  }
  return crc ^ 0xFF;
}
static_assert(crc8("123456789", 9) == 0x4B, "CRC-8/SAE-J1850's check value");
constexpr uint8_t e2e_crc(uint16_t id, const Data &d) {  // the ID (2 bytes, big-endian), bytes 0-6
  const uint8_t b[] = {uint8_t(id >> 8), uint8_t(id), d[0], d[1], d[2], d[3], d[4], d[5], d[6]};
  return crc8(b, 9);
}
// d with a signal of `length` bits from bit `start`: value / scale, rounded, two's complement.
constexpr Data put(Data d, int start, int length, double value, double scale) {
  long raw = long(value / scale + (value < 0 ? -0.5 : 0.5));
  for (int i = 0; i < length; ++i) d[(start + i) / 8] |= uint8_t((raw >> i & 1) << (start + i) % 8);
  return d;
}
constexpr Data heartbeat(int state) { return {uint8_t(state)}; }  // 0 idle, 1 auto, 2 estop
constexpr Data steering_cmd(bool enable, double angle_deg, double max_rate) {  // 0.01°, 0.1°/s
  return put(put({enable}, 16, 16, angle_deg, 0.01), 32, 16, max_rate, 0.1);
}
constexpr Data throttle_cmd(bool enable, int gear, double brake_pct, double speed, double accel) {
  Data d = put({uint8_t(enable | gear << 2)}, 8, 8, brake_pct, 0.5);  // Brake 0.5 %
  return put(put(d, 16, 16, speed, 0.01), 32, 8, accel, 0.02);  // 0.01 m/s, 0.02 m/s^2
}
constexpr Data sealed(uint16_t id, Data d, int counter) {  // byte 6: counter; byte 7: CRC
  return d[6] = uint8_t(counter & 0x0F), d[7] = e2e_crc(id, d), d;
}
// Two of the contract's frames, 100#0100E20458020368 and 110#0500960032000033, by their CRC.
static_assert(sealed(STEERING_CMD, steering_cmd(true, 12.5, 60), 3)[7] == 0x68);
static_assert(sealed(THROTTLE_CMD, throttle_cmd(true, 1, 0, 1.5, 1), 0)[7] == 0x33);
struct Can {
  int fd = socket(PF_CAN, SOCK_RAW, CAN_RAW);
  std::map<int, uint8_t> counter, last;  // sent per ID; received per stream (ID, and Source)
  long sent = 0, failed = 0, rejected = 0;
  explicit Can(const std::string &iface) {
    sockaddr_can at{AF_CAN, int(if_nametoindex(iface.c_str())), {}};
    if (fd < 0 || at.can_ifindex == 0) die("CAN interface " + iface);
    const canid_t mask = CAN_SFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG;  // standard data frames only
    can_filter reports[] = {{STEERING_REPORT, mask}, {THROTTLE_REPORT, mask}, {FAULT_REPORT, mask}};
    if (setsockopt(fd, SOL_CAN_RAW, CAN_RAW_FILTER, reports, sizeof reports) < 0 ||
        bind(fd, reinterpret_cast<sockaddr *>(&at), sizeof at) < 0 ||
        fcntl(fd, F_SETFL, O_NONBLOCK) < 0)
      die("CAN socket on " + iface);
  }
  void send(uint16_t id, const Data &d) {  // a failed write uses its counter too: never reuse one
    can_frame f{};
    Data s = sealed(id, d, counter[id]++);
    f.can_id = id, f.can_dlc = 8, std::memcpy(f.data, s.data(), 8);
    write(fd, &f, sizeof f) == sizeof f ? ++sent : ++failed;
  }
  bool receive(uint16_t &id, Data &d) {  // the next frame that passes the E2E checks
    for (can_frame f{}; read(fd, &f, sizeof f) == sizeof f; ++rejected) {  // but `return`: rejected
      id = uint16_t(f.can_id), std::memcpy(d.data(), f.data, 8);
      if (f.can_dlc != 8 || d[7] != e2e_crc(id, d)) continue;
      int stream = id << 4 | (id == FAULT_REPORT ? d[0] & 0x0F : 0), c = d[6] & 0x0F;
      bool next = !last.count(stream) || c == (last[stream] + 1) % 16;
      last[stream] = c;  // repeated or skipped: dropped; a skip resynchronises on it
      if (next) return true;
    }
    return false;
  }
};

// ---- GPS: NMEA 0183 on a raw serial line
int open_gps(const std::string &path, long baud) {
  int fd = open(path.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK);
  termios t{};
  if (fd < 0 || tcgetattr(fd, &t) < 0) die("serial port " + path);
  cfmakeraw(&t);  // 8N1, no echo, no line editing: CR LF as sent
  t.c_cflag |= CLOCAL | CREAD, t.c_cc[VMIN] = t.c_cc[VTIME] = 0;  // reads return what is there
  if (cfsetspeed(&t, speed_t(baud)) < 0 || tcsetattr(fd, TCSANOW, &t) < 0)  // glibc: 115200 too
    die("termios of " + path);
  return fd;
}
Strings nmea(const std::string &line) {  // the fields of a sentence with a good checksum
  size_t star = line.rfind('*');
  if (line.rfind('$', 0) != 0 || star == std::string::npos || line.size() < star + 3) return {};
  unsigned sum = 0;
  Strings fields{""};
  for (size_t i = 1; i < star; ++i)
    sum ^= uint8_t(line[i]), line[i] == ',' ? fields.push_back("") : void(fields.back() += line[i]);
  return std::strtoul(line.c_str() + star + 1, nullptr, 16) == sum ? fields : Strings{};
}
bool read_sentences(int fd, std::string &buf, std::vector<Strings> &out) {  // false: line closed
  pollfd p{fd, POLLIN, 0};  // a raw pty whose master closed reads 0 bytes, as an idle one does
  if (poll(&p, 1, 0) <= 0) return true;
  char b[4096];
  ssize_t n = p.revents & (POLLHUP | POLLERR | POLLNVAL) ? 0 : read(fd, b, sizeof b);
  if (n == 0 || (n < 0 && errno != EAGAIN && errno != EINTR)) return false;
  buf.append(b, n > 0 ? size_t(n) : 0);
  for (size_t end; (end = buf.find('\n')) != std::string::npos; buf.erase(0, end + 1))
    out.push_back(nmea(buf.substr(0, end)));
  return true;
}
// GGA's position as east/north at the datum, flat, with the WGS-84 radii of curvature there
// (docs/wire-contract.md: 0.08 mm from the exact conversion at (30, 15), 12 mm at (300, 300)).
std::array<double, 2> enu(const Strings &gga, double lat0, double lon0) {
  auto deg = [&](size_t i, size_t w) {  // (d)ddmm.mmmmmmm, N/S or E/W
    double v = std::atof(gga[i].substr(0, w).c_str()) + std::atof(gga[i].c_str() + w) / 60;
    return (gga[i + 1] == "S" || gga[i + 1] == "W" ? -v : v) * RAD;
  };
  double e2 = 6.69437999014e-3, s = std::sin(lat0 * RAD), w = 1 - e2 * s * s;
  double n = 6378137.0 / std::sqrt(w), meridian = n * (1 - e2) / w;  // radii of curvature
  return {(deg(4, 3) - lon0 * RAD) * std::cos(lat0 * RAD) * n, (deg(2, 2) - lat0 * RAD) * meridian};
}

// ---- the run's files: wires.json (one flat object) and mission.toml ([table] key = number)
std::string json_value(const std::string &text, const std::string &key) {
  size_t at = text.find("\"" + key + "\"");
  if (at == std::string::npos) return "";
  at = text.find_first_not_of(" \t\r\n", text.find(':', at) + 1);
  if (text[at] == '"') return text.substr(at + 1, text.find('"', at + 1) - at - 1);
  return text.substr(at, text.find_first_of(",}\r\n", at) - at);
}
std::map<std::string, double> read_toml(const std::string &path) {  // {"table.key": value}
  std::map<std::string, double> m;
  std::ifstream in(path);
  for (std::string line, table; std::getline(in, line);)
    if (line.rfind('[', 0) == 0) table = line.substr(1, line.find(']') - 1) + ".";
    else if (size_t eq = line.find(" = "); eq != std::string::npos)
      m[table + line.substr(0, eq)] = std::atof(line.c_str() + eq + 3);
  return m;
}

// ---- the controller
struct Pose { double x, y, th; };  // the rear axle, east/north at the datum (m), theta (rad)
struct Arc { double k, clear; bool found; };
using Points = std::vector<std::array<double, 2>>;  // laser points in the car's frame (x forward)
Arc plan(Pose p, const Points &points, std::map<std::string, double> &m) {
  double gx = m["goal.x"], gy = m["goal.y"], least = INFINITY;
  double kmax = std::tan(std::fmin(m["vehicle.max_steer_deg"], 30) * RAD) / m["vehicle.wheelbase"];
  double look = std::fmax(2, std::fmin(LOOK, std::hypot(gx - p.x, gy - p.y)));
  Arc best{0, 0, false};
  if (std::hypot(gx - p.x, gy - p.y) < m["goal.tolerance"]) return best;  // there
  for (int i = 0; i < ARCS; ++i) {
    double k = kmax * (2.0 * i / (ARCS - 1) - 1), r = std::abs(k) < 1e-6 ? 1e6 : 1 / k;
    double clear = INFINITY;  // how far the points along the arc are off it
    for (auto [px, py] : points)
      if (double s = std::atan2(px / r, (r - py) / r) * r; s > -0.5 && s < look)
        clear = std::fmin(clear, std::abs(std::hypot(px, py - r) - std::abs(r)));
    double ex = std::sin(look / r) * r, ey = (1 - std::cos(look / r)) * r;
    double wx = p.x + ex * std::cos(p.th) - ey * std::sin(p.th);
    double wy = p.y + ex * std::sin(p.th) + ey * std::cos(p.th);
    double cost = std::abs(std::remainder(std::atan2(gy - wy, gx - wx) - p.th - look / r, 2 * PI));
    if (clear >= CLEAR && cost < least) least = cost, best = {k, clear, true};
  }
  return best;
}
enum State { WAIT, AUTO, EDGE, DRIVE };  // the enable sequence (docs/wire-contract.md)
const char *const NAMES[] = {"wait", "auto", "edge", "drive"};
}  // namespace

int main(int argc, char **argv) {
  std::string dir = argc == 2 ? argv[1] : "";  // RESULTS_DIR, or --config DIR/controller.toml's DIR
  for (int i = 1; i + 1 < argc; ++i)  // (`ugv-sim run --controller`: run --config ... --gps ...)
    if (std::string c = argv[i + 1]; std::string(argv[i]) == "--config")
      dir = c.substr(0, c.rfind('/') + 1) + ".";
  if (dir.empty()) return SAY("usage: ugv-example-cpp RESULTS_DIR (README.md)"), 2;
  for (int i = 0; i < 600 && access((dir + "/controller.toml").c_str(), F_OK) != 0; ++i)
    usleep(100000);  // written after wires.json and mission.toml
  std::ifstream file(dir + "/wires.json");
  std::string wires(std::istreambuf_iterator<char>(file), {}), can_iface = json_value(wires, "can");
  std::string link = json_value(wires, "gps_link"), service = json_value(wires, "laser_service");
  auto m = read_toml(dir + "/mission.toml");
  if (json_value(wires, "version") != "1" || m["version"] != 1)
    return SAY("no wires.json and mission.toml of version 1 in %s", dir.c_str()), 1;
  int gps = open_gps(link, std::atol(json_value(wires, "gps_baud").c_str())), opened, tries = 0;
  ugv_laser *laser = nullptr;  // open, never create: the simulator made it before wires.json
  while ((opened = ugv_laser_open(service.c_str(), &laser)) == 1 && ++tries < 100) usleep(100000);
  if (opened != 0) return SAY("no laser service %s", service.c_str()), 1;
  Can can(can_iface);
  SAY("wires: GPS %s, laser %s, CAN %s", link.c_str(), service.c_str(), can_iface.c_str());
  for (int signal : {SIGINT, SIGTERM}) std::signal(signal, [](int) { stopped = 1; });
  double ax = m["vehicle.antenna_x"], ay = m["vehicle.antenna_y"], lx = m["vehicle.laser_x"];
  double ly = m["vehicle.laser_y"], yaw = m["vehicle.laser_yaw_deg"] * RAD;
  static ugv_laser_frame_v1 frame;  // 8.7 kB
  std::string buf, end;
  Strings gga;
  Pose pose{};
  Points points;
  bool have_pose = false, have_points = false, enabled[2] = {false, false};
  int faults[2] = {-1, -1};  // STEERING_REPORT's and THROTTLE_REPORT's Fault; -1: none came yet
  State state = WAIT;
  double k = 0, speed = 0, ground_speed = 0;
  auto since = std::chrono::steady_clock::now(), next_tick = since, last_report = since;
  auto command = [&](int heartbeat_state, bool enable, double steer, double v) {  // state < 0: none
    if (heartbeat_state >= 0) can.send(HEARTBEAT, heartbeat(heartbeat_state));
    can.send(STEERING_CMD, steering_cmd(enable, steer, 0));
    can.send(THROTTLE_CMD, throttle_cmd(enable, 1, v > 0 ? 0 : 100, v, 0));  // forward; brake at 0
  };
  for (long tick = 0; end.empty(); usleep(2000)) {
    auto now = std::chrono::steady_clock::now();
    std::vector<Strings> sentences;  // an epoch: GGA, RMC, VTG, GST, HDT, ZDA
    bool new_fix = false;
    if (!read_sentences(gps, buf, sentences)) end = "the GPS line closed";
    for (auto &f : sentences) {
      std::string type = f.empty() || f[0].size() != 5 ? "" : f[0].substr(2);  // GNGGA: GGA
      if (type == "GGA" && f.size() > 6) gga = std::atoi(f[6].c_str()) > 0 ? f : Strings{};
      if (type == "RMC" && f.size() > 2 && f[2] != "A") gga.clear();  // status V: no valid fix
      if (type == "VTG" && f.size() > 7) ground_speed = std::atof(f[7].c_str()) / 3.6;
      if (type != "HDT" || f.size() < 2 || f[1].empty() || gga.empty()) continue;
      auto [e, n] = enu(gga, m["datum.latitude"], m["datum.longitude"]);
      double th = (90 - std::atof(f[1].c_str())) * RAD, c = std::cos(th), s = std::sin(th);  // HDT
      pose = {e - c * ax + s * ay, n - s * ax - c * ay, th};  // GGA's is the antenna's position
      have_pose = new_fix = true;
      gga.clear();
    }
    int got = ugv_laser_latest(laser, &frame);  // the newest frame, copied out
    if (got < 0) end = "the laser failed";
    for (uint32_t i = 0; got > 0 && i < frame.count && i < UGV_LASER_MAX_BEAMS; ++i) {
      if (i == 0) points.clear(), have_points = true;
      double r = frame.ranges[i], a = frame.angle_min + i * frame.angle_increment + yaw;
      if (std::isfinite(r) && r >= frame.range_min && r <= frame.range_max && r < 10)  // inf, NaN
        points.push_back({lx + r * std::cos(a), ly + r * std::sin(a)});
    }
    uint16_t id;
    for (Data d; can.receive(id, d);) {  // the reports: Enabled bit 0, Fault bits 4-7
      if (id == FAULT_REPORT) SAY("FAULT_REPORT source %d code %d", d[0] & 15, d[1]);
      else enabled[id == THROTTLE_REPORT] = d[0] & 1, faults[id == THROTTLE_REPORT] = d[0] >> 4,
           last_report = now;
    }
    bool heard = faults[0] >= 0 && faults[1] >= 0, on = enabled[0] && enabled[1];
    if (heard && now - last_report > Ms(500)) end = "the ECUs' reports stopped";
    if (stopped) end = "stopped by a signal";
    // Idle until every wire is there, then auto, then at least one auto heartbeat later the
    // Enable 0 -> 1 edge; the same again if an ECU has not enabled within a second or drops out.
    State next = state == WAIT && have_pose && have_points && heard ? AUTO
               : state == AUTO && now - since > Ms(60)               ? EDGE
               : state == EDGE && on                                 ? DRIVE
               : state >= EDGE && !on && now - since > Ms(1000)      ? AUTO : state;
    if (next == DRIVE && state == EDGE) SAY("both ECUs enabled, driving");
    if (next == AUTO && state >= EDGE)
      SAY("ECUs not enabled (faults %d, %d), enabling again", faults[0], faults[1]);
    if (next != state) state = next, since = now, k = speed = 0;
    if (state == DRIVE && new_fix) {  // no free arc, or at the goal: stop
      Arc arc = plan(pose, points, m);
      k = arc.found ? arc.k : 0, speed = arc.found ? (arc.clear > 2.5 ? SPEED : 1.0) : 0;
    }
    if (now < next_tick) continue;  // commands every 10 ms, the heartbeat every 20 ms
    next_tick = now - next_tick > Ms(50) ? now : next_tick + Ms(10);  // late: no burst to catch up
    double steer = std::atan(k * m["vehicle.wheelbase"]) / RAD;
    command(tick % 2 ? -1 : state != WAIT, state >= EDGE, steer, speed);  // 1: auto, 0: idle
    if (++tick % 100 == 0 && have_pose)
      SAY("%s x=%.2f y=%.2f hdg=%.0f steer=%.1f v=%.1f (GPS %.2f)", NAMES[state], pose.x, pose.y,
          pose.th / RAD, steer, speed, ground_speed);
  }
  for (int i = 0; stopped && i < 3; ++i, usleep(10000)) command(0, false, 0, 0);  // safe: disabled
  ugv_laser_close(laser);
  SAY("run over: %s; last pose (%.2f, %.2f, %.0f deg); sent %ld frames (%ld failed), rejected %ld",
      end.c_str(), pose.x, pose.y, pose.th / RAD, can.sent, can.failed, can.rejected);
  return 0;
}
