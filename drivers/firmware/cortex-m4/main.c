/*
 * The interface board's firmware on an STM32F405/F407: the portable board logic (sashil_board.c,
 * protocol v2 of drivers/protocol.md) behind the reference hardware layer (hal_stm32f4.c). The main
 * loop hands the bytes the UART received (and, in the CAN build, the frames CAN1 received) to the
 * board and lets the board's timer run: samples in device pacing, the watchdog that rests coil and
 * road when the host falls silent.
 *
 * SASHIL_CAN (make cortex-m4-can): the board speaks the DBC's CAN frames on CAN1 (hal_can_stm32f4.c)
 * with hal_can_send as its send_can. If CAN1 does not come up (no transceiver, a shorted bus) it
 * stays on the serial link. Without SASHIL_CAN the HAL has no send_can and the board refuses a CAN
 * session (fault 3).
 */
#include "hal_stm32f4.h"
#include "sashil_board.h"
#ifdef SASHIL_CAN
#include "hal_can_stm32f4.h"
#define SEND_CAN hal_can_send
#else
#define SEND_CAN 0
#endif

#define COUNTS_PER_REV 4096u
/* the sample rates the links carry: a 28-byte sample frame is 280 us at 1 Mbit/s (3.57 kHz), a CAN
 * sample three frames (SampleA, SampleEdges, SampleB: up to 375 bits with stuffing, 2.67 kHz) and
 * the host's Command each cycle (2.08 kHz in all, drivers/protocol.md); a little margin below each */
#define SERIAL_MAX_RATE_HZ 3400u
#define CAN_MAX_RATE_HZ 2000u
#define CURRENT_MAX_COUNTS 4000u /* 2 A in 0.5 mA counts: the coil driver's limit */

static sashil_board board;

int main(void)
{
    static const sashil_hal hal = {
        0, hal_read_encoders_timed, hal_read_current, hal_set_coil, hal_set_road_speed, hal_sensor_flags, hal_send, SEND_CAN,
        hal_read_edges,
    };
    uint8_t bytes[64];
    hal_init();
    hal_edges_init();
    sashil_board_init(&board, &hal, COUNTS_PER_REV, CURRENT_MAX_COUNTS, 0u);
    sashil_board_set_status_flags(&board, hal_clock_fallback() ? SASHIL_STATUS_CLOCK_FALLBACK : 0u);
    sashil_board_set_max_rate(&board, SERIAL_MAX_RATE_HZ);
#ifdef SASHIL_CAN
    if (hal_can_init(hal_apb1_mhz())) {
        sashil_board_set_link(&board, SASHIL_LINK_CAN);
        sashil_board_set_max_rate(&board, CAN_MAX_RATE_HZ);
    }
#endif
    for (;;) {
        uint64_t now = hal_now_us();
        size_t n = hal_uart_take(bytes, sizeof bytes);
        if (n > 0u) {
            sashil_board_receive(&board, bytes, n, now);
        }
#ifdef SASHIL_CAN
        uint16_t id;
        uint8_t data[8], len;
        while (hal_can_take(&id, data, &len)) {
            sashil_board_receive_can(&board, id, data, len, now);
        }
#endif
        sashil_board_tick(&board, now);
    }
}
