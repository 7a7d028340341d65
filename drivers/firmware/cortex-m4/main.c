/*
 * The interface board's firmware on an STM32F405/F407: the portable board logic (sashil_board.c,
 * protocol v2 of drivers/protocol.md) behind the reference hardware layer (hal_stm32f4.c). The main
 * loop hands the bytes the UART received to the board and lets the board's timer run: samples in
 * device pacing, the watchdog that rests coil and road when the host falls silent.
 */
#include "hal_stm32f4.h"
#include "sashil_board.h"

#define COUNTS_PER_REV 4096u
#define CURRENT_MAX_COUNTS 4000u /* 2 A in 0.5 mA counts: the coil driver's limit */

static sashil_board board;

int main(void)
{
    static const sashil_hal hal = {
        0, hal_read_encoders_timed, hal_read_current, hal_set_coil, hal_set_road_speed, hal_sensor_flags, hal_send, 0,
        hal_read_edges,
    };
    uint8_t bytes[64];
    hal_init();
    hal_edges_init();
    sashil_board_init(&board, &hal, COUNTS_PER_REV, CURRENT_MAX_COUNTS, 0u);
    for (;;) {
        uint64_t now = hal_now_us();
        size_t n = hal_uart_take(bytes, sizeof bytes);
        if (n > 0u) {
            sashil_board_receive(&board, bytes, n, now);
        }
        sashil_board_tick(&board, now);
    }
}
