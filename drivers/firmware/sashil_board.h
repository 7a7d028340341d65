/*
 * The interface board's logic, protocol v1 (drivers/protocol.md "Session", "Pacing"), behind a small
 * hardware interface. Portable C99: no allocation; integers in the wire's units (coil current in
 * 0.5 mA counts, road speed in 1 urad/s counts), times in microseconds. The same behaviour as the
 * Python board (drivers/emulator/device.py): Hello -> Version; Configure -> Status (fault 1 when it
 * cannot be honoured); Command drives the coil (ENABLE bit, clamped to i_max) and feeds the watchdog,
 * and in host pacing is answered by a Sample; RoadSpeed sets the road motor; in device pacing one
 * Sample per period. Watchdog: no valid Command for watchdog_ms -> coil and road to 0, the watchdog
 * flag, a Status; the next valid Command clears it.
 */
#ifndef SASHIL_BOARD_H
#define SASHIL_BOARD_H

#include <stddef.h>
#include <stdint.h>

#include "sashil_frame.h"

#define SASHIL_PROTOCOL_VERSION 1u
#define SASHIL_FLAG_WATCHDOG 0x01u
#define SASHIL_FAULT_NONE 0u
#define SASHIL_FAULT_BAD_CONFIGURE 1u
#define SASHIL_PACING_DEVICE 0u
#define SASHIL_PACING_HOST 1u

typedef struct {
    void *ctx;
    void (*read_encoders)(void *ctx, int32_t *arm_counts, int32_t *road_counts);
    int16_t (*read_current)(void *ctx);          /* measured coil current, 0.5 mA counts */
    void (*set_coil)(void *ctx, uint16_t counts); /* coil current setpoint, 0.5 mA counts */
    void (*set_road_speed)(void *ctx, int32_t urad_s);
    uint8_t (*sensor_flags)(void *ctx);           /* flags the hardware adds (held, overcurrent, ...) */
    void (*send)(void *ctx, const uint8_t *bytes, size_t n);
} sashil_hal;

typedef struct {
    sashil_hal hal;
    uint32_t counts_per_rev;
    uint16_t current_max_counts;
    uint16_t fixed_rate_hz; /* 0: any rate 1..20000 */
    /* session */
    int configured;
    uint16_t rate_hz, watchdog_ms;
    uint8_t pacing;
    uint64_t boot_us, next_sample_us;
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

/* sizeof(sashil_board), for a host that allocates it (the ctypes harness). */
size_t sashil_board_size(void);

#endif
