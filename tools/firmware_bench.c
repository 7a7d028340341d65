/* Per-sample work of the board's C logic on the host (tools/bench_firmware.py builds and runs it):
 * a live device-paced session at 1 kHz on the serial link in which each period the board receives
 * one Command frame from the host and sends one Sample frame. argv[1]: samples; prints the
 * nanoseconds per sample (CLOCK_MONOTONIC over the whole run) and a checksum of what was sent. */
#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

#include "sashil_board.h"

static unsigned long sink;
static int32_t arm;

static void read_encoders(void *ctx, int32_t *a, int32_t *r) { (void)ctx; *a = arm++; *r = -arm / 3; }
static int16_t read_current(void *ctx) { (void)ctx; return 1234; }
static void set_coil(void *ctx, uint16_t c) { (void)ctx; sink += c; }
static void set_road_speed(void *ctx, int32_t s) { (void)ctx; sink += (unsigned long)s; }
static uint8_t sensor_flags(void *ctx) { (void)ctx; return 0; }
static void send(void *ctx, const uint8_t *b, size_t n) { size_t i; (void)ctx; for (i = 0; i < n; i++) sink += b[i]; }
static void read_edges(void *ctx, sashil_edge *a, sashil_edge *r) { (void)ctx; a->time_us = (uint32_t)arm; a->dir = 1; r->time_us = 0; r->dir = 0; }

int main(int argc, char **argv)
{
    static sashil_board board;
    sashil_hal hal = {NULL, read_encoders, read_current, set_coil, set_road_speed, sensor_flags, send, NULL, read_edges};
    static const uint8_t configure[5] = {0xE8u, 0x03u, 50u, 0u, 0u};
    uint8_t frame[SASHIL_MAX_FRAME], payload[3] = {0xD0u, 0x07u, 1u}; /* 1.0 A, ENABLE */
    long samples = argc > 1 ? atol(argv[1]) : 1000000L, k;
    struct timespec t0, t1;
    uint64_t now = 0;
    size_t n;

    sashil_board_init(&board, &hal, 4096u, 4000u, 0u);
    n = sashil_frame_encode(0x07u, 1u, configure, 5u, frame, sizeof frame);
    sashil_board_receive(&board, frame, n, now);
    clock_gettime(CLOCK_MONOTONIC, &t0);
    for (k = 0; k < samples; k++) {
        n = sashil_frame_encode(0x02u, (uint16_t)k, payload, 3u, frame, sizeof frame);
        sashil_board_receive(&board, frame, n, now + 500u);
        now += 1000u;
        sashil_board_tick(&board, now);
    }
    clock_gettime(CLOCK_MONOTONIC, &t1);
    printf("%.1f %lu\n", ((t1.tv_sec - t0.tv_sec) * 1e9 + (t1.tv_nsec - t0.tv_nsec)) / (double)samples, sink);
    return 0;
}
