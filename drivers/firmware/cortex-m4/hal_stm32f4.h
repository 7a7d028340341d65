/* The reference hardware layer of the interface board on an STM32F405/F407: see hal_stm32f4.c. */
#ifndef SASHIL_HAL_STM32F4_H
#define SASHIL_HAL_STM32F4_H

#include <stddef.h>
#include <stdint.h>

#include "sashil_board.h"

void hal_init(void);

/* 1 when the crystal did not start within its timeout and the board runs on the internal oscillator */
int hal_clock_fallback(void);

/* the APB1 bus clock in MHz: 42 from the PLL, 16 when the PLL did not lock (bxCAN's bit timing) */
uint32_t hal_apb1_mhz(void);

/* the sashil_hal callbacks (sashil_board.h), in the wire's units */
void hal_read_encoders(void *ctx, int32_t *arm_counts, int32_t *road_counts);
int16_t hal_read_current(void *ctx);
void hal_set_coil(void *ctx, uint16_t counts);
void hal_set_road_speed(void *ctx, int32_t urad_s);
uint8_t hal_sensor_flags(void *ctx);
void hal_send(void *ctx, const uint8_t *bytes, size_t n);

/* the microsecond clock (64 bits: never wraps); call at least every 25 s (the main loop does) */
uint64_t hal_now_us(void);

/* bytes received by the UART since the last call (at most cap); from the receive interrupt's ring */
size_t hal_uart_take(uint8_t *out, size_t cap);

/* encoder edge times (a 100 kHz poll of the counters, TIM7; see hal_stm32f4.c): start the poll after
 * hal_init; hal_read_encoders_timed reads the counts with their edges (the board's read_encoders),
 * hal_read_edges hands those edges to the board (its read_edges) */
void hal_edges_init(void);
void hal_read_encoders_timed(void *ctx, int32_t *arm_counts, int32_t *road_counts);
void hal_read_edges(void *ctx, sashil_edge *arm, sashil_edge *road);

#endif
