/* Sanitizer harness for the C firmware (built with -fsanitize=address,undefined by
 * tests/test_firmware_fuzz.py): garbage of every length 0..2047 bytes into the COBS decoder, the frame
 * decoder, the byte stream decoder and the board itself (behind a stub hardware interface), and
 * good frames cut and corrupted at every byte, and random CAN frames of every length on every id into a
 * board on the CAN link, and into a board on the CAN link whose HAL has no send_can (every Configure
 * refused and counted, the coil never driven). The hardware's encoder edges are random too (any
 * time, any direction byte): every Sample the board sends is decoded again and its edge fields
 * checked (an edge without a direction is sent as "none", only the two direction bits are used).
 * Exit 0 and "ok ..." when every bad frame was counted and nothing good came out of garbage longer
 * than a frame. */
#include <stdio.h>
#include <string.h>

#include "sashil_board.h"
#include "sashil_frame.h"

static unsigned long rng = 17ul;
static unsigned long sent_bytes;

static uint8_t next_byte(void) {
    rng = rng * 1103515245ul + 12345ul;
    return (uint8_t)(rng >> 16);
}

static void read_encoders(void *ctx, int32_t *arm, int32_t *road) {
    (void)ctx;
    *arm = 123;
    *road = -45;
}
static int16_t read_current(void *ctx) {
    (void)ctx;
    return 7;
}
static void set_coil(void *ctx, uint16_t counts) { (void)ctx; (void)counts; }
static void set_road_speed(void *ctx, int32_t s) { (void)ctx; (void)s; }
static uint8_t sensor_flags(void *ctx) {
    (void)ctx;
    return 0;
}
static sashil_edge last_arm, last_road; /* what read_edges gave for the sample being sent */
static unsigned long bad_samples, samples_checked;

static void read_edges(void *ctx, sashil_edge *arm, sashil_edge *road) {
    (void)ctx;
    arm->time_us = (uint32_t)next_byte() << 24 | (uint32_t)next_byte() << 8 | next_byte();
    arm->dir = (int8_t)(next_byte() % 3u) - 1;
    road->time_us = (uint32_t)next_byte() << 16 | next_byte();
    road->dir = (int8_t)next_byte(); /* any byte: a HAL that reports a direction of 77 */
    last_arm = *arm;
    last_road = *road;
}

static void check_sample(const uint8_t *p, uint8_t len) {
    uint16_t arm_age = (uint16_t)(p[15] | p[16] << 8), road_age = (uint16_t)(p[17] | p[18] << 8);
    samples_checked++;
    if (len != 20u || (p[19] & ~0x03u) != 0u) bad_samples++;
    if ((last_arm.dir == 0 && arm_age != SASHIL_EDGE_AGE_NONE) || (last_road.dir == 0 && road_age != SASHIL_EDGE_AGE_NONE))
        bad_samples++;
    if (((p[19] & SASHIL_EDGE_ARM_UP) != 0u) != (last_arm.dir > 0) || ((p[19] & SASHIL_EDGE_ROAD_UP) != 0u) != (last_road.dir > 0))
        bad_samples++;
}

static void send(void *ctx, const uint8_t *bytes, size_t n) {
    size_t i;
    uint8_t type, len, payload[SASHIL_MAX_PAYLOAD];
    uint16_t seq;
    (void)ctx;
    for (i = 0; i < n; i++) sent_bytes += bytes[i] != 0xA5u; /* touch every byte (ASan checks the reads) */
    if (n > 1u && sashil_frame_decode(bytes, n - 1u, &type, &seq, payload, &len) == SASHIL_FRAME_OK && type == 1u)
        check_sample(payload, len);
}

static unsigned long driven; /* non-zero coil setpoints of the board without CAN: must stay 0 */
static void set_coil_counted(void *ctx, uint16_t counts) { (void)ctx; driven += counts != 0u; }

static unsigned long can_sent;
static void send_can(void *ctx, uint16_t id, const uint8_t *data, uint8_t len) {
    uint8_t i;
    (void)ctx;
    if (len > 8u || id > 0x7FFu) can_sent += 1000000ul; /* a frame no CAN controller could send */
    for (i = 0; i < len; i++) can_sent += data[i] != 0xA5u;
    if (id == SASHIL_CAN_SAMPLE_EDGES && (len != 5u || (data[4] & ~0x03u) != 0u)) bad_samples++;
}

int main(void) {
    static uint8_t data[2048], out[64];
    sashil_stream stream;
    static sashil_board board;
    sashil_hal hal = {NULL, read_encoders, read_current, set_coil, set_road_speed, sensor_flags, send, send_can,
                      read_edges};
    static sashil_board can_board;
    static const uint16_t can_ids[] = {0x100u, 0x110u, 0x111u, 0x112u, 0x120u, 0x180u, 0x1F0u, 0x1F1u, 0x1F2u, 0x7FFu};
    uint8_t type, payload[SASHIL_MAX_PAYLOAD], len, frame[SASHIL_MAX_FRAME];
    uint16_t seq;
    size_t n, i, cap, out_len, flen;
    unsigned long good = 0, bad = 0, ends = 0;
    uint64_t now = 0;

    static const uint8_t hello[1] = {2u}, configure[5] = {0xE8u, 0x03u, 50u, 0u, 0u}, command[3] = {100u, 0u, 1u};
    uint8_t session[3 * SASHIL_MAX_FRAME];
    size_t session_len = 0;

    sashil_stream_init(&stream);
    sashil_board_init(&board, &hal, 4096u, 2000u, 0u);
    /* Hello, Configure (1 kHz, 50 ms watchdog, device pacing), Command: a live session to disturb */
    session_len += sashil_frame_encode(0x05u, 1u, hello, 1u, session, sizeof session);
    session_len += sashil_frame_encode(0x07u, 2u, configure, 5u, session + session_len, sizeof session - session_len);
    session_len += sashil_frame_encode(0x02u, 3u, command, 3u, session + session_len, sizeof session - session_len);
    for (n = 0; n < sizeof data; n++) {
        for (i = 0; i < n; i++) data[i] = next_byte();
        for (cap = 0; cap <= sizeof out; cap += 16) (void)sashil_cobs_decode(data, n, out, cap, &out_len);
        if (sashil_frame_decode(data, n, &type, &seq, payload, &len) == SASHIL_FRAME_OK && len > SASHIL_MAX_PAYLOAD)
            return 2;
        for (i = 0; i <= n; i++) {
            int r = sashil_stream_feed(&stream, i < n ? data[i] : 0u, &type, &seq, payload, &len);
            if (r == 1) good++;
            if (r < 0) bad++;
            if (i == n) ends++;
        }
        now += 1000u;
        if (n % 64u == 0u) sashil_board_receive(&board, session, session_len, now);
        sashil_board_receive(&board, data, n, now);
        sashil_board_tick(&board, now);
    }
    /* a good frame cut and corrupted at every byte, into the stream decoder and the board */
    memset(payload, 0, sizeof payload);
    flen = sashil_frame_encode(0x02u, 7u, payload, 3u, frame, sizeof frame);
    if (flen == 0) return 3;
    for (i = 0; i < flen; i++) {
        uint8_t b;
        for (b = 1; b != 0; b++) {
            uint8_t bent[SASHIL_MAX_FRAME];
            size_t k;
            memcpy(bent, frame, flen);
            bent[i] ^= b;
            for (k = 0; k <= flen; k++) {
                int r = sashil_stream_feed(&stream, k < flen ? bent[k] : 0u, &type, &seq, payload, &len);
                if (r == 1) good++;
                if (r < 0) bad++;
            }
            now += 100u;
            sashil_board_receive(&board, bent, i + 1u, now);
            sashil_board_receive(&board, bent, flen, now);
            sashil_board_tick(&board, now);
        }
    }
    /* CAN: every host id (and others) with every length 0..8 and random data, into a live session */
    sashil_board_init(&can_board, &hal, 4096u, 2000u, 0u);
    sashil_board_set_link(&can_board, SASHIL_LINK_CAN);
    {
        static const uint8_t can_configure[5] = {0xE8u, 0x03u, 50u, 0u, 0u};
        unsigned long wrong = 0;
        sashil_board_receive_can(&can_board, 0x1F0u, can_configure, 5u, now);
        for (n = 0; n < 20000u; n++) {
            uint8_t d[8], l = (uint8_t)(next_byte() % 9u);
            uint16_t id = can_ids[next_byte() % (sizeof can_ids / sizeof can_ids[0])];
            for (i = 0; i < 8u; i++) d[i] = next_byte();
            wrong += (id == 0x100u && l != 5u) || (id == 0x120u && l != 4u) || (id == 0x1F0u && l != 5u) ||
                     (id == 0x1F1u && l != 1u);
            now += 50u;
            sashil_board_receive_can(&can_board, id, d, l, now);
            sashil_board_tick(&can_board, now);
        }
        if (sashil_board_bad_frames(&can_board) != wrong) return 6; /* every wrong length counted, no other */
        if (can_sent == 0u || can_sent >= 1000000ul) return 7;
    }
    /* CAN on a board whose HAL has no send_can: every Configure refused and counted, nothing driven,
     * nothing called through the missing pointer (ASan/UBSan would stop on a call through NULL) */
    {
        static sashil_board no_can;
        sashil_hal bare = {NULL, read_encoders, read_current, set_coil_counted, set_road_speed, sensor_flags, send, NULL, read_edges};
        unsigned long configures = 0;
        sashil_board_init(&no_can, &bare, 4096u, 2000u, 0u);
        sashil_board_set_link(&no_can, SASHIL_LINK_CAN);
        for (n = 0; n < 20000u; n++) {
            uint8_t d[8], l = (uint8_t)(next_byte() % 9u);
            uint16_t id = can_ids[next_byte() % (sizeof can_ids / sizeof can_ids[0])];
            for (i = 0; i < 8u; i++) d[i] = next_byte();
            if (n % 16u == 0u) id = 0x1F0u, l = 5u; /* a well-formed Configure, often */
            configures += id == 0x1F0u && l == 5u;
            now += 50u;
            sashil_board_receive_can(&no_can, id, d, l, now);
            sashil_board_tick(&no_can, now);
        }
        if (sashil_board_sessions(&no_can) != 0u || sashil_board_refusals(&no_can) != (uint16_t)configures) return 8;
        if (driven != 0u) return 9;
    }
    if (stream.frames != good || stream.bad_frames != bad) return 4;
    if (sent_bytes == 0u) return 5; /* the session was answered between the garbage */
    if (samples_checked == 0u || bad_samples != 0u) return 8; /* samples went out, their edge fields sound */
    printf("ok frames=%lu bad=%lu sent=%lu ends=%lu\n", good, bad, sent_bytes, ends);
    return 0;
}
