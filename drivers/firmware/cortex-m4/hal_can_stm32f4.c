/*
 * The CAN link of the reference hardware layer (make cortex-m4-can, SASHIL_CAN): bxCAN CAN1 of the
 * STM32F405/F407 at 1 Mbit/s (registers from RM0090 rev 19, chapter 32), on PB8 = CAN1_RX and
 * PB9 = CAN1_TX (AF9) to a CAN transceiver (e.g. a TJA1051).
 *
 * Bit timing: APB1 at 42 MHz, prescaler 3 -> 14 time quanta of 71.4 ns per bit: sync 1 + BS1 11 +
 * BS2 2 (sample point 85.7 %, CiA 301's 87.5 % +- 2.5 %), SJW 1. On the internal oscillator without
 * the PLL (APB1 16 MHz): prescaler 1, 16 quanta, BS1 13 + BS2 2 (87.5 %).
 * Receive: filter bank 0 in 16-bit list mode passes exactly the four host ids of drivers/sashil.dbc
 * (Command 0x100, RoadSpeed 0x120, Configure 0x1F0, Hello 0x1F1) into FIFO 0; its interrupt (FMPIE0)
 * moves each frame into a ring that the main loop drains (hal_can_take). Transmit: frames go into the
 * three mailboxes in the order they were sent (TXFP: by request order, so SampleA leaves before its
 * SampleB); when all three are busy they wait in a ring that the transmit interrupt (TMEIE) empties,
 * so the board's logic never waits for the bus. Bus-off recovers by itself (ABOM).
 */
#include "hal_can_stm32f4.h"

#include "bxcan_frame.h"

#define REG(addr) (*(volatile uint32_t *)(addr))

#define RCC_AHB1ENR REG(0x40023830u)
#define RCC_APB1ENR REG(0x40023840u)
#define GPIOB 0x40020400u
#define GPIO_MODER(p) REG((p) + 0x00u)
#define GPIO_AFR(p, n) REG((p) + 0x20u + 4u * (n))

#define CAN1 0x40006400u
#define CAN_MCR REG(CAN1 + 0x000u)
#define CAN_MSR REG(CAN1 + 0x004u)
#define CAN_TSR REG(CAN1 + 0x008u)
#define CAN_RF0R REG(CAN1 + 0x00Cu)
#define CAN_IER REG(CAN1 + 0x014u)
#define CAN_BTR REG(CAN1 + 0x01Cu)
#define CAN_TIR(n) REG(CAN1 + 0x180u + 0x10u * (n))
#define CAN_TDTR(n) REG(CAN1 + 0x184u + 0x10u * (n))
#define CAN_TDLR(n) REG(CAN1 + 0x188u + 0x10u * (n))
#define CAN_TDHR(n) REG(CAN1 + 0x18Cu + 0x10u * (n))
#define CAN_RI0R REG(CAN1 + 0x1B0u)
#define CAN_RDT0R REG(CAN1 + 0x1B4u)
#define CAN_RDL0R REG(CAN1 + 0x1B8u)
#define CAN_RDH0R REG(CAN1 + 0x1BCu)
#define CAN_FMR REG(CAN1 + 0x200u)
#define CAN_FM1R REG(CAN1 + 0x204u)
#define CAN_FS1R REG(CAN1 + 0x20Cu)
#define CAN_FFA1R REG(CAN1 + 0x214u)
#define CAN_FA1R REG(CAN1 + 0x21Cu)
#define CAN_F0R1 REG(CAN1 + 0x240u)
#define CAN_F0R2 REG(CAN1 + 0x244u)

#define NVIC_ISER(n) REG(0xE000E100u + 4u * (n))
#define NVIC_ISPR(n) REG(0xE000E200u + 4u * (n))
#define CAN1_TX_IRQ 19u
#define CAN1_RX0_IRQ 20u

#define MCR_INRQ 0x01u
#define MCR_SLEEP 0x02u
#define MCR_TXFP 0x04u
#define MCR_ABOM 0x40u
#define MSR_INAK 0x01u
#define TSR_TME_SHIFT 26u /* TME0..2: mailbox n empty */
#define TSR_RQCP_ALL 0x00010101u
#define RF0R_FMP0 0x03u
#define RF0R_FOVR0 0x10u
#define RF0R_RFOM0 0x20u
#define IER_TMEIE 0x01u
#define IER_FMPIE0 0x02u
#define INIT_SPINS 100000u /* INAK follows INRQ within 11 recessive bits; bound the wait anyway */

#define RING 32u /* frames, a power of two */

typedef struct {
    uint16_t id;
    uint8_t len;
    uint8_t data[8];
} can_frame;

static volatile can_frame rx_ring[RING], tx_ring[RING];
static volatile uint32_t rx_head, rx_tail, tx_head, tx_tail;
static volatile uint32_t rx_lost, tx_lost;

/* the host ids of drivers/sashil.dbc: Command, RoadSpeed, Configure, Hello */
static const uint16_t host_ids[4] = {0x100u, 0x120u, 0x1F0u, 0x1F1u};

static int wait_msr(uint32_t mask, uint32_t want)
{
    for (uint32_t n = 0; n < INIT_SPINS; n++) {
        if ((CAN_MSR & mask) == want) {
            return 1;
        }
    }
    return 0;
}

int hal_can_init(uint32_t apb1_mhz)
{
    uint32_t fr1, fr2;
    RCC_AHB1ENR |= 1u << 1;  /* GPIOB */
    RCC_APB1ENR |= 1u << 25; /* CAN1 */
    for (unsigned pin = 8u; pin <= 9u; pin++) {
        GPIO_MODER(GPIOB) = (GPIO_MODER(GPIOB) & ~(3u << (2u * pin))) | (2u << (2u * pin));
        GPIO_AFR(GPIOB, 1u) = (GPIO_AFR(GPIOB, 1u) & ~(0xFu << (4u * (pin - 8u)))) | (9u << (4u * (pin - 8u)));
    }
    CAN_MCR = MCR_INRQ; /* leave sleep, enter initialisation */
    if (!wait_msr(MSR_INAK, MSR_INAK)) {
        return 0;
    }
    CAN_MCR = MCR_INRQ | MCR_TXFP | MCR_ABOM;
    /* BTR: SJW - 1 in 25:24, BS2 - 1 in 22:20, BS1 - 1 in 19:16, BRP - 1 in 9:0 */
    CAN_BTR = apb1_mhz == 42u ? (1u << 20) | (10u << 16) | 2u : (1u << 20) | (12u << 16) | (apb1_mhz / 16u - 1u);

    CAN_FMR |= 1u; /* FINIT: filters in initialisation */
    bxcan_filter_list16(host_ids, &fr1, &fr2);
    CAN_FA1R &= ~1u;
    CAN_FM1R |= 1u;   /* bank 0: identifier list */
    CAN_FS1R &= ~1u;  /* dual 16-bit */
    CAN_FFA1R &= ~1u; /* into FIFO 0 */
    CAN_F0R1 = fr1;
    CAN_F0R2 = fr2;
    CAN_FA1R |= 1u;
    CAN_FMR &= ~1u;

    CAN_IER = IER_FMPIE0 | IER_TMEIE;
    NVIC_ISER(CAN1_TX_IRQ / 32u) = 1u << (CAN1_TX_IRQ % 32u);
    NVIC_ISER(CAN1_RX0_IRQ / 32u) = 1u << (CAN1_RX0_IRQ % 32u);
    CAN_MCR &= ~MCR_INRQ; /* on the bus after 11 recessive bits */
    return wait_msr(MSR_INAK, 0u);
}

/* the first empty transmit mailbox, or 3 */
static uint32_t free_mailbox(void)
{
    uint32_t tsr = CAN_TSR;
    for (uint32_t n = 0; n < 3u; n++) {
        if (tsr & (1u << (TSR_TME_SHIFT + n))) {
            return n;
        }
    }
    return 3u;
}

static void load(uint32_t box, const bxcan_mailbox *m)
{
    CAN_TDTR(box) = m->tdtr;
    CAN_TDLR(box) = m->tdlr;
    CAN_TDHR(box) = m->tdhr;
    CAN_TIR(box) = m->tir; /* TXRQ last: the request */
}

void hal_can_send(void *ctx, uint16_t id, const uint8_t *data, uint8_t len)
{
    (void)ctx;
    uint32_t head = tx_head;
    if (((head + 1u) & (RING - 1u)) == tx_tail) {
        tx_lost++; /* the bus is behind by a whole ring: the host counts a missing sample */
        return;
    }
    tx_ring[head].id = id;
    tx_ring[head].len = len > 8u ? 8u : len;
    for (uint8_t i = 0; i < tx_ring[head].len; i++) {
        tx_ring[head].data[i] = data[i];
    }
    tx_head = (head + 1u) & (RING - 1u);
    /* the transmit interrupt loads the mailboxes in ring order; raising it here covers a ring that was
     * empty when the last mailbox emptied */
    NVIC_ISPR(CAN1_TX_IRQ / 32u) = 1u << (CAN1_TX_IRQ % 32u);
}

void CAN1_TX_IRQHandler(void)
{
    CAN_TSR = TSR_RQCP_ALL; /* acknowledge the finished requests (write 1 to clear) */
    uint32_t box;
    while (tx_tail != tx_head && (box = free_mailbox()) < 3u) {
        bxcan_mailbox m;
        uint8_t bytes[8];
        const volatile can_frame *f = &tx_ring[tx_tail];
        for (uint8_t i = 0; i < 8u; i++) {
            bytes[i] = f->data[i];
        }
        if (bxcan_pack(f->id, bytes, f->len, &m)) {
            load(box, &m);
        }
        tx_tail = (tx_tail + 1u) & (RING - 1u);
    }
}

void CAN1_RX0_IRQHandler(void)
{
    while (CAN_RF0R & RF0R_FMP0) {
        uint16_t id;
        uint8_t data[8], len;
        if (bxcan_unpack(CAN_RI0R, CAN_RDT0R, CAN_RDL0R, CAN_RDH0R, &id, data, &len)) {
            uint32_t next = (rx_head + 1u) & (RING - 1u);
            if (next != rx_tail) {
                volatile can_frame *f = &rx_ring[rx_head];
                f->id = id;
                f->len = len;
                for (uint8_t i = 0; i < 8u; i++) {
                    f->data[i] = data[i];
                }
                rx_head = next;
            } else {
                rx_lost++;
            }
        }
        CAN_RF0R = RF0R_RFOM0; /* release the FIFO slot */
    }
    if (CAN_RF0R & RF0R_FOVR0) {
        rx_lost++;
        CAN_RF0R = RF0R_FOVR0; /* three frames came faster than this interrupt: one was lost */
    }
}

int hal_can_take(uint16_t *id, uint8_t data[8], uint8_t *len)
{
    if (rx_tail == rx_head) {
        return 0;
    }
    const volatile can_frame *f = &rx_ring[rx_tail];
    *id = f->id;
    *len = f->len;
    for (uint8_t i = 0; i < 8u; i++) {
        data[i] = f->data[i];
    }
    rx_tail = (rx_tail + 1u) & (RING - 1u);
    return 1;
}
