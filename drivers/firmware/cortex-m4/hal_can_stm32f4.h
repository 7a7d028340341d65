/* The CAN link of the reference hardware layer: bxCAN CAN1 at 1 Mbit/s (see hal_can_stm32f4.c). */
#ifndef SASHIL_HAL_CAN_STM32F4_H
#define SASHIL_HAL_CAN_STM32F4_H

#include <stdint.h>

/* CAN1 on PB8/PB9 at 1 Mbit/s from an APB1 clock of apb1_mhz (42, or 16 on the internal oscillator
 * without the PLL), the host ids' filter, both interrupts; 0 when the controller does not leave
 * initialisation (no transceiver, or CAN_RX held dominant). */
int hal_can_init(uint32_t apb1_mhz);

/* The board's send_can (sashil_hal): queues the frame; the transmit interrupt puts it on the bus. */
void hal_can_send(void *ctx, uint16_t id, const uint8_t *data, uint8_t len);

/* The next frame the receive interrupt took off the bus: 1 and id, data, len, or 0 when none. */
int hal_can_take(uint16_t *id, uint8_t data[8], uint8_t *len);

#endif
