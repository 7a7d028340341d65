/* CAN frames and bxCAN mailbox words: see bxcan_frame.h. */
#include "bxcan_frame.h"

#define TIR_TXRQ 0x1u
#define RIR_RTR 0x2u
#define RIR_IDE 0x4u

static uint32_t word(const uint8_t *bytes, uint8_t from, uint8_t len)
{
    uint32_t w = 0;
    for (uint8_t i = 0; i < 4u && (uint8_t)(from + i) < len; i++) {
        w |= (uint32_t)bytes[from + i] << (8u * i);
    }
    return w;
}

int bxcan_pack(uint16_t id, const uint8_t *data, uint8_t len, bxcan_mailbox *out)
{
    if (id > 0x7FFu || len > 8u) {
        return 0;
    }
    out->tir = ((uint32_t)id << 21) | TIR_TXRQ; /* standard id, data frame, transmit request */
    out->tdtr = len;
    out->tdlr = word(data, 0u, len);
    out->tdhr = word(data, 4u, len);
    return 1;
}

int bxcan_unpack(uint32_t rir, uint32_t rdtr, uint32_t rdlr, uint32_t rdhr, uint16_t *id, uint8_t data[8], uint8_t *len)
{
    if (rir & (RIR_IDE | RIR_RTR)) {
        return 0;
    }
    uint8_t dlc = (uint8_t)(rdtr & 0xFu);
    *id = (uint16_t)(rir >> 21);
    *len = dlc > 8u ? 8u : dlc; /* a DLC of 9..15 still carries 8 bytes (ISO 11898-1) */
    for (uint8_t i = 0; i < 4u; i++) {
        data[i] = (uint8_t)(rdlr >> (8u * i));
        data[4u + i] = (uint8_t)(rdhr >> (8u * i));
    }
    return 1;
}

void bxcan_filter_list16(const uint16_t ids[4], uint32_t *fr1, uint32_t *fr2)
{
    /* each 16-bit slot: STID[10:0] in bits 15:5, RTR bit 4 = 0, IDE bit 3 = 0, EXID[17:15] = 0 */
    *fr1 = ((uint32_t)(ids[1] & 0x7FFu) << 21) | ((uint32_t)(ids[0] & 0x7FFu) << 5);
    *fr2 = ((uint32_t)(ids[3] & 0x7FFu) << 21) | ((uint32_t)(ids[2] & 0x7FFu) << 5);
}
