/*
 * The interface board's logic, protocol v2 (drivers/protocol.md "Session", "Pacing"), behind a small
 * hardware interface. Portable C99: no allocation; integers in the wire's units (coil current in
 * 0.5 mA counts, road speed in 1 urad/s counts), times in microseconds. The same behaviour as the
 * Python board (drivers/emulator/device.py): Hello -> Version; Configure -> Status (fault 1 when it
 * cannot be honoured, 3 when the CAN link has no send_can); Command drives the coil (ENABLE bit,
 * clamped to i_max) and feeds the watchdog, and in host pacing is answered by a Sample; RoadSpeed
 * sets the road motor; in device pacing one Sample per period, on an exact grid of 1e6/rate us. Watchdog: no valid Command for watchdog_ms -> coil and road to 0, the watchdog
 * flag, a Status; the next valid Command clears it.
 */
#ifndef SASHIL_BOARD_H
#define SASHIL_BOARD_H

#include <stddef.h>
#include <stdint.h>

#include "sashil_frame.h"

#define SASHIL_PROTOCOL_VERSION 2u
#define SASHIL_MAX_RATE_HZ 20000u /* the protocol's highest sample rate */
#define SASHIL_FLAG_WATCHDOG 0x01u
#define SASHIL_FAULT_NONE 0u
#define SASHIL_FAULT_BAD_CONFIGURE 1u
#define SASHIL_FAULT_NO_CAN 3u /* a Configure on the CAN link of a board whose HAL has no send_can */
/* Status flag set by the hardware layer (sashil_board_set_status_flags): the crystal did not start
 * and the board runs on its internal oscillator */
#define SASHIL_STATUS_CLOCK_FALLBACK 0x10u
#define SASHIL_PACING_DEVICE 0u
#define SASHIL_PACING_HOST 1u
#define SASHIL_LINK_SERIAL 0u /* sashil serial frames (COBS + CRC-16) through hal.send */
#define SASHIL_LINK_CAN 1u    /* the DBC's CAN frames (drivers/sashil.dbc) through hal.send_can */

/* CAN identifiers (11-bit) of drivers/sashil.dbc */
#define SASHIL_CAN_COMMAND 0x100u
#define SASHIL_CAN_SAMPLE_A 0x110u
#define SASHIL_CAN_SAMPLE_B 0x111u
#define SASHIL_CAN_SAMPLE_EDGES 0x112u

/* A Sample's edge age that means "no count change in the last 65.534 ms" (or none since boot), and
 * its direction bits (set: the count went up at that change). */
#define SASHIL_EDGE_AGE_NONE 0xFFFFu
#define SASHIL_EDGE_ARM_UP 0x01u
#define SASHIL_EDGE_ROAD_UP 0x02u

/* One encoder's last count change as the hardware timestamped it: the time (low 32 bits of the
 * clock the board is given as now_us) and the direction, +1 up, -1 down, 0 no change since boot. */
typedef struct {
    uint32_t time_us;
    int8_t dir;
} sashil_edge;
#define SASHIL_CAN_ROAD_SPEED 0x120u
#define SASHIL_CAN_STATUS 0x180u
#define SASHIL_CAN_CONFIGURE 0x1F0u
#define SASHIL_CAN_HELLO 0x1F1u
#define SASHIL_CAN_VERSION 0x1F2u

typedef struct {
    void *ctx;
    void (*read_encoders)(void *ctx, int32_t *arm_counts, int32_t *road_counts);
    int16_t (*read_current)(void *ctx);          /* measured coil current, 0.5 mA counts */
    void (*set_coil)(void *ctx, uint16_t counts); /* coil current setpoint, 0.5 mA counts */
    void (*set_road_speed)(void *ctx, int32_t urad_s);
    uint8_t (*sensor_flags)(void *ctx);           /* flags the hardware adds (held, overcurrent, ...) */
    void (*send)(void *ctx, const uint8_t *bytes, size_t n);               /* one whole serial frame */
    void (*send_can)(void *ctx, uint16_t id, const uint8_t *data, uint8_t len); /* one CAN frame */
    /* The encoders' last count changes (timer input capture or a fast counter poll); read right
     * after read_encoders for the same sample. NULL: a board without edge timing (ages say none). */
    void (*read_edges)(void *ctx, sashil_edge *arm, sashil_edge *road);
} sashil_hal;

typedef struct {
    sashil_hal hal;
    uint32_t counts_per_rev;
    uint16_t current_max_counts;
    uint16_t fixed_rate_hz; /* 0: any rate 1..max_rate_hz */
    uint16_t max_rate_hz;   /* the highest rate its link carries (20000 unless set) */
    /* session */
    int configured;
    uint16_t rate_hz, watchdog_ms;
    uint8_t pacing, link;
    uint16_t sessions; /* Configures honoured since boot */
    uint16_t refusals; /* Configures refused since boot */
    uint8_t status_flags; /* the hardware layer's, in every Status */
    uint32_t can_bad_frames; /* CAN frames with a known id and the wrong length */
    uint64_t boot_us, next_sample_us;
    uint32_t period_rem; /* the sample period's remainder carried, in 1/rate_hz us */
    int booted, commanded, watchdog_tripped;
    uint64_t last_cmd_us;
    uint16_t drive_counts;
    int32_t road_urad_s;
    uint16_t tx_seq, sample_seq, watchdog_trips;
    uint32_t overruns;
    sashil_stream rx;
} sashil_board;

void sashil_board_init(sashil_board *b, const sashil_hal *hal, uint32_t counts_per_rev, uint16_t current_max_counts,
                       uint16_t fixed_rate_hz);

/* Bytes from the host (any pieces); replies go out through hal.send. */
void sashil_board_receive(sashil_board *b, const uint8_t *bytes, size_t n, uint64_t now_us);

/* The board's timer: watchdog, and in device pacing the sample that is due. */
void sashil_board_tick(sashil_board *b, uint64_t now_us);

/* The highest sample rate the board's link carries (1..20000; 20000 after init): a Configure above
 * it is refused (fault 1), since the samples could not all leave. */
void sashil_board_set_max_rate(sashil_board *b, uint16_t max_rate_hz);

/* Choose the link (SASHIL_LINK_SERIAL, the default after init, or SASHIL_LINK_CAN). */
void sashil_board_set_link(sashil_board *b, uint8_t link);

/* One CAN frame from the bus (any id: the board takes its host ids, ignores others). */
void sashil_board_receive_can(sashil_board *b, uint16_t id, const uint8_t *data, uint8_t len, uint64_t now_us);

/* When sashil_board_tick next has something to do (sample due, watchdog deadline), or UINT64_MAX:
 * a board may sleep until then or until bytes arrive. */
uint64_t sashil_board_next_event_us(const sashil_board *b);

/* Configures honoured since boot (a new host session each), and refused (with a fault code). */
uint16_t sashil_board_sessions(const sashil_board *b);
uint16_t sashil_board_refusals(const sashil_board *b);

/* Flags the hardware layer reports in every Status (SASHIL_STATUS_CLOCK_FALLBACK). */
void sashil_board_set_status_flags(sashil_board *b, uint8_t flags);

/* Watchdog trips since boot (as Status reports them), and device-paced samples that fell a whole
 * period behind. */
uint16_t sashil_board_watchdog_trips(const sashil_board *b);
uint32_t sashil_board_overruns(const sashil_board *b);

/* Frames from the host that could not be decoded (as Status reports them). */
uint32_t sashil_board_bad_frames(const sashil_board *b);

/* sizeof(sashil_board), for a host that allocates it (the ctypes harness). */
size_t sashil_board_size(void);

#endif
