/*
 * A CAN frame in and out of the STM32F4's bxCAN mailbox registers (RM0090 32.9.3), and the identifier
 * filter of the board's host ids. Pure functions, no register access: the CAN hardware layer
 * (hal_can_stm32f4.c) writes and reads the words, and the host tests them (tests/test_firmware_can_hal.py).
 */
#ifndef SASHIL_BXCAN_FRAME_H
#define SASHIL_BXCAN_FRAME_H

#include <stdint.h>

/* A transmit mailbox's words: CAN_TIxR (standard id in bits 31:21, TXRQ bit 0), CAN_TDTxR (DLC in
 * bits 3:0), CAN_TDLxR (data bytes 0..3, byte 0 lowest) and CAN_TDHxR (bytes 4..7). */
typedef struct {
    uint32_t tir, tdtr, tdlr, tdhr;
} bxcan_mailbox;

/* The mailbox words of a standard data frame (id 11 bits, len 0..8); 0 when id or len is out of range. */
int bxcan_pack(uint16_t id, const uint8_t *data, uint8_t len, bxcan_mailbox *out);

/* A received frame from CAN_RIxR, CAN_RDTxR, CAN_RDLxR, CAN_RDHxR: 1 and id, data, len for a standard
 * data frame; 0 for an extended or remote frame (not the DBC's: ignored). */
int bxcan_unpack(uint32_t rir, uint32_t rdtr, uint32_t rdlr, uint32_t rdhr, uint16_t *id, uint8_t data[8], uint8_t *len);

/* One filter bank in 16-bit identifier list mode passing exactly these four standard ids (data
 * frames only): the words for CAN_FxR1 and CAN_FxR2 (RM0090 32.7.4, figure 342). */
void bxcan_filter_list16(const uint16_t ids[4], uint32_t *fr1, uint32_t *fr2);

#endif
