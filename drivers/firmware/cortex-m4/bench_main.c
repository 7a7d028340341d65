/*
 * Per-sample cost of the board's logic on the Cortex-M4 image, for QEMU with -icount shift=0 (make
 * cortex-m4-bench, run by tools/bench_firmware.py). In place of main.c: a device-paced session at
 * 1 kHz on the serial link in which each period the board decodes one Command frame and encodes one
 * Sample frame, through the reference HAL's callbacks (send: a copy into a buffer, as into the
 * transmit ring). With -icount shift=0 QEMU's virtual time advances 1 ns per instruction and SysTick
 * counts that time, so the board's microsecond clock measures thousands of instructions: QEMU counts
 * instructions, not cycles. Two session lengths are timed, so the start-up and the clock reads cancel
 * in the difference; the result goes out on USART1 as one text line:
 *   bench samples A us T_A samples B us T_B
 */
#include "hal_stm32f4.h"
#include "sashil_board.h"

#define SHORT_RUN 2000u
#define LONG_RUN 12000u

static uint8_t tx_copy[SASHIL_MAX_FRAME];
static uint32_t sent;

static void send_copy(void *ctx, const uint8_t *bytes, size_t n)
{
    (void)ctx;
    for (size_t i = 0; i < n && i < sizeof tx_copy; i++) {
        tx_copy[i] = bytes[i];
    }
    sent += (uint32_t)n;
}

static uint64_t session(uint32_t samples)
{
    static sashil_board board;
    static const sashil_hal hal = {
        0, hal_read_encoders_timed, hal_read_current, hal_set_coil, hal_set_road_speed, hal_sensor_flags, send_copy, 0,
        hal_read_edges,
    };
    static const uint8_t configure[5] = {0xE8u, 0x03u, 50u, 0u, 0u}; /* 1 kHz, 50 ms, device pacing */
    static const uint8_t command[3] = {0xD0u, 0x07u, 1u};          /* 1.0 A, ENABLE */
    uint8_t frame[SASHIL_MAX_FRAME], cmd[SASHIL_MAX_FRAME];
    uint64_t now = 0;
    sashil_board_init(&board, &hal, 4096u, 4000u, 0u);
    size_t n = sashil_frame_encode(0x07u, 1u, configure, 5u, frame, sizeof frame);
    sashil_board_receive(&board, frame, n, now);
    size_t cmd_len = sashil_frame_encode(0x02u, 2u, command, 3u, cmd, sizeof cmd);
    uint64_t start = hal_now_us();
    for (uint32_t k = 0; k < samples; k++) {
        sashil_board_receive(&board, cmd, cmd_len, now + 500u);
        now += 1000u;
        sashil_board_tick(&board, now);
    }
    return hal_now_us() - start;
}

static void put_text(const char *s)
{
    size_t n = 0;
    while (s[n] != '\0') {
        n++;
    }
    hal_send(0, (const uint8_t *)s, n);
}

static void put_number(uint32_t v) /* 32 bits: -nostdlib has no 64-bit division helper */
{
    char digits[11];
    int i = 10;
    digits[i] = '\0';
    do {
        digits[--i] = (char)('0' + (int)(v % 10u));
        v /= 10u;
    } while (v != 0u);
    put_text(&digits[i]);
}

int main(void)
{
    hal_init();
    uint32_t short_us = (uint32_t)session(SHORT_RUN), long_us = (uint32_t)session(LONG_RUN);
    put_text("bench samples ");
    put_number(SHORT_RUN);
    put_text(" us ");
    put_number(short_us);
    put_text(" samples ");
    put_number(LONG_RUN);
    put_text(" us ");
    put_number(long_us);
    put_text(sent > 0u ? "\n" : " nothing sent\n");
    for (;;) {
    }
}
