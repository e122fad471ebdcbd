/* The laser wire for C and C++ (docs/wire-contract.md, "Laser"): a subscriber to the
 * simulator's iceoryx2 service, in libugv_laser_c.a (examples/cpp/laser-c, Rust over
 * firmware-bridge and iceoryx2 0.10). Link it with -lpthread -ldl -lm -lrt. */
#ifndef UGV_LASER_H
#define UGV_LASER_H
#include <stdint.h>
#ifdef __cplusplus
extern "C" {
#endif

#define UGV_LASER_MAX_BEAMS 1081  /* 270 degrees at 0.25 degrees */
#define UGV_LASER_FRAME_VERSION 1u
#define UGV_LASER_TYPE_NAME "ugv_hil::LaserFrame::v1"

/* The frame as it lies in shared memory; sizeof 8696, alignof 8. */
typedef struct {
    uint32_t version;          /*    0: UGV_LASER_FRAME_VERSION */
    uint32_t count;            /*    4: beams in use, 1..=1081; entries past it are zero */
    uint64_t sequence;         /*    8: +1 per scan; a gap is a lost scan */
    uint64_t stamp_ns;         /*   16: first beam's time, ns since the UNIX epoch (simulated time) */
    float angle_min;           /*   24: first beam, rad, counter-clockwise, 0 = the scanner's forward axis */
    float angle_increment;     /*   28: rad between beams (positive: counter-clockwise sweep) */
    float time_increment;      /*   32: s between beams */
    float scan_time;           /*   36: s between scans */
    float range_min;           /*   40: m */
    float range_max;           /*   44: m */
    float ranges[UGV_LASER_MAX_BEAMS];      /*   48: m; +inf = no return, NaN = dropout */
    float intensities[UGV_LASER_MAX_BEAMS]; /* 4372: device units, 0 without a return */
} ugv_laser_frame_v1;

typedef struct ugv_laser ugv_laser; /* a subscriber (opaque) */

/* Open, never create, the service `service` (wires.json's laser_service) and its event
 * service, with the simulator's settings, and subscribe. 0: *out is the subscriber;
 * 1: the service does not exist (yet): try again; -1: an error, written on stderr. */
int ugv_laser_open(const char *service, ugv_laser **out);

/* The newest frame, copied into *frame, without blocking; every sample is given back at
 * once. 1: a frame; 0: none since the last call; -1: an error, written on stderr. */
int ugv_laser_latest(const ugv_laser *laser, ugv_laser_frame_v1 *frame);

/* Close the subscriber (NULL is allowed). */
void ugv_laser_close(ugv_laser *laser);

#ifdef __cplusplus
}
#endif
#endif
