/*
 * The reference hardware layer of the interface board on an STM32F405/F407 (register addresses and
 * bits from RM0090 rev 19; the registers are declared here, no vendor headers).
 *
 * Assumptions, to adapt to a board: an 8 MHz crystal (HSE), SYSCLK 168 MHz from the PLL (M 8, N 336,
 * P 2, Q 7), APB1 42 MHz (timer clock 84 MHz), APB2 84 MHz (timer clock 168 MHz), 5 flash wait states
 * (RM0090 6.3.2, 3.5.1).
 *   arm encoder   TIM2 (32 bit) encoder mode, both edges: PA15 = CH1, PB3 = CH2 (AF1)  (RM0090 18.3.16);
 *                 PA15 and PB3 are JTDI and JTDO after reset: taking them leaves SWD (PA13/PA14) to debug
 *   road encoder  TIM5 (32 bit) encoder mode, both edges: PA0 = CH1, PA1 = CH2 (AF2)
 *   coil driver   TIM1 CH1 PWM at 20 kHz on PA8 (AF1) into the coil's half bridge; current sense on
 *                 ADC1 channel 10 (PC0), SENSE_MV_PER_A mV per ampere (1.2 V/A: 2.75 A at the 3.3 V
 *                 full scale, so the 2.5 A trip below reads on the ADC). Closed loop: a
 *                 proportional-integral current loop at 10 kHz (TIM6 interrupt) sets the duty so the
 *                 measured current follows the setpoint (integrator clamped to the duty range: no
 *                 wind-up); above OVERCURRENT_COUNTS the drive is cut and the overcurrent flag raised.
 *                 The gains are placeholders for a first bench test, to be tuned on the coil's L and R.
 *   road motor    TIM8 CH1 PWM at 20 kHz on PC6 (AF3), direction on PC7; a proportional-integral speed
 *                 loop at 1 kHz on the road encoder's counts.
 *   host link     USART1 at 1 Mbit/s, 8N1: PA9 = TX, PA10 = RX (AF7); received bytes go to a ring buffer
 *                 in the receive interrupt; frames to send go to a ring emptied by the transmit interrupt
 *                 (TXE), so the board's logic never waits for the wire: a 28-byte sample frame takes
 *                 280 us on the wire, which caps device pacing at about 3.6 kHz on this link.
 *   clock         the core's cycles accumulated into microseconds: DWT CYCCNT where it counts, else
 *                 SysTick on the core clock (hal_now_us).
 * CAN: hal_can_stm32f4.c (make cortex-m4-can) adds bxCAN CAN1 on PB8/PB9 as the board's send_can.
 *
 * SASHIL_QEMU (make cortex-m4-qemu, for QEMU's netduinoplus2, an STM32F405): QEMU 7.2 models no RCC
 * (its ready bits read 0), its USART raises no TXE interrupt, its TIM2..5 count time rather than
 * encoder edges, and it has no TIM6 (no current loop). With the macro the clock start-up runs as on
 * the hardware and meets what a dead crystal looks like: it times out (10 ms there) and the board
 * reports the fallback in every Status; hal_send writes each byte when TXE is set, the encoders read a
 * rig at rest (0 counts from reset) and the measured current is the setpoint. Everything else (vector
 * table, start-up, SysTick clock, receive interrupt and ring, board logic) is the hardware build's.
 * QEMU's SysTick runs on its fixed 168 MHz system clock, the hardware's count.
 */
#include "hal_stm32f4.h"

#define REG(addr) (*(volatile uint32_t *)(addr))

/* RCC (RM0090 7.3) */
#define RCC 0x40023800u
#define RCC_CR REG(RCC + 0x00u)
#define RCC_PLLCFGR REG(RCC + 0x04u)
#define RCC_CFGR REG(RCC + 0x08u)
#define RCC_AHB1ENR REG(RCC + 0x30u)
#define RCC_APB1ENR REG(RCC + 0x40u)
#define RCC_APB2ENR REG(RCC + 0x44u)
#define FLASH_ACR REG(0x40023C00u)

/* GPIO (RM0090 8.4) */
#define GPIOA 0x40020000u
#define GPIOB 0x40020400u
#define GPIOC 0x40020800u
#define GPIO_MODER(p) REG((p) + 0x00u)
#define GPIO_OSPEEDR(p) REG((p) + 0x08u)
#define GPIO_BSRR(p) REG((p) + 0x18u)
#define GPIO_AFR(p, n) REG((p) + 0x20u + 4u * (n))

/* timers (RM0090 17.4, 18.4, 20.4) */
#define TIM1 0x40010000u
#define TIM2 0x40000000u
#define TIM5 0x40000C00u
#define TIM6 0x40001000u
#define TIM8 0x40010400u
#define TIM_CR1(t) REG((t) + 0x00u)
#define TIM_SMCR(t) REG((t) + 0x08u)
#define TIM_DIER(t) REG((t) + 0x0Cu)
#define TIM_SR(t) REG((t) + 0x10u)
#define TIM_EGR(t) REG((t) + 0x14u)
#define TIM_CCMR1(t) REG((t) + 0x18u)
#define TIM_CCER(t) REG((t) + 0x20u)
#define TIM_CNT(t) REG((t) + 0x24u)
#define TIM_PSC(t) REG((t) + 0x28u)
#define TIM_ARR(t) REG((t) + 0x2Cu)
#define TIM_CCR1(t) REG((t) + 0x34u)
#define TIM_BDTR(t) REG((t) + 0x44u)

/* ADC1 (RM0090 13.13) */
#define ADC1 0x40012000u
#define ADC_SR REG(ADC1 + 0x00u)
#define ADC_CR2 REG(ADC1 + 0x08u)
#define ADC_SMPR1 REG(ADC1 + 0x0Cu)
#define ADC_SQR3 REG(ADC1 + 0x34u)
#define ADC_DR REG(ADC1 + 0x4Cu)
#define ADC_CCR REG(0x40012304u)

/* USART1 (RM0090 30.6) */
#define USART1 0x40011000u
#define USART_SR REG(USART1 + 0x00u)
#define USART_DR REG(USART1 + 0x04u)
#define USART_BRR REG(USART1 + 0x08u)
#define USART_CR1 REG(USART1 + 0x0Cu)

/* core: NVIC (PM0214 4.3), DWT cycle counter (ARMv7-M C1.8) */
#define NVIC_ISER(n) REG(0xE000E100u + 4u * (n))
#define DEMCR REG(0xE000EDFCu)
#define DWT_CTRL REG(0xE0001000u)
#define DWT_CYCCNT REG(0xE0001004u)
/* SysTick (PM0214 4.5) */
#define SYST_CSR REG(0xE000E010u)
#define SYST_RVR REG(0xE000E014u)
#define SYST_CVR REG(0xE000E018u)
#define SYST_MASK 0x00FFFFFFu

#define SYSCLK_MHZ 168u
#define HSI_MHZ 16u                      /* the internal oscillator, the core clock after reset */
#define HSE_TIMEOUT_CYCLES 1600000u      /* 100 ms at HSI: a crystal starts within a few ms */
#define PLL_TIMEOUT_CYCLES 160000u       /* 10 ms: the PLL locks within 0.2 ms */
#define PWM_PERIOD 8400u                 /* 168 MHz / 20 kHz */
#define SENSE_MV_PER_A 1200u             /* the current-sense amplifier's gain */
#define ADC_MV_FULL 3300u                /* 12-bit ADC, 3.3 V reference */
#define OVERCURRENT_COUNTS 5000          /* 2.5 A in 0.5 mA counts */
#define ENCODER_COUNTS_PER_REV 4096.0f   /* the road encoder, for the speed loop */
#define FLAG_OVERCURRENT 0x08u           /* drivers/protocol.md, sample flags bit 3 */
#define RX_RING 256u                     /* a power of two */
#define TX_RING 512u                     /* a power of two: twenty sample frames */

static volatile uint8_t rx_ring[RX_RING];
static volatile uint32_t rx_head, rx_tail;
static volatile uint8_t tx_ring[TX_RING];
static volatile uint32_t tx_head, tx_tail;
static volatile uint16_t coil_setpoint;  /* 0.5 mA counts */
static volatile int16_t coil_measured;   /* 0.5 mA counts */
static volatile uint8_t overcurrent;
static volatile int32_t road_setpoint;   /* urad/s */
static float coil_integral, road_integral;
static uint32_t road_last_counts;
static uint32_t ticks;
static int clock_is_dwt; /* the clock counts DWT cycles (1) or SysTick's (0) */
static uint32_t core_mhz = HSI_MHZ; /* the core clock, and so the cycles per microsecond */
static int clock_fallback; /* the crystal did not start (or the PLL did not lock) */

static void clock_source_init(void);

static void pin_af(uint32_t port, unsigned pin, unsigned af)
{
    GPIO_MODER(port) = (GPIO_MODER(port) & ~(3u << (2u * pin))) | (2u << (2u * pin));
    GPIO_OSPEEDR(port) |= 3u << (2u * pin);
    GPIO_AFR(port, pin / 8u) = (GPIO_AFR(port, pin / 8u) & ~(0xFu << (4u * (pin % 8u)))) | (af << (4u * (pin % 8u)));
}

/* Wait for (reg & mask) == want for at most timeout_cycles of SysTick (free-running on the core clock
 * since hal_init started it); 1 when it came. Below 2^24 cycles: the count wraps once every 2^24. */
static int wait_for(volatile uint32_t *reg, uint32_t mask, uint32_t want, uint32_t timeout_cycles)
{
    uint32_t start = SYST_CVR;
    while ((*reg & mask) != want) {
        if (((start - SYST_CVR) & SYST_MASK) > timeout_cycles) {
            return 0;
        }
    }
    return 1;
}

/* SYSCLK 168 MHz from the PLL, fed by the crystal (HSE) when it starts within HSE_TIMEOUT_CYCLES, else
 * by the internal 16 MHz oscillator (HSI, +-1 %): the same 168 MHz, so every rate below holds, only
 * less exactly, and clock_fallback says so (the host hears it in every Status). A PLL that does not
 * lock leaves the core on HSI at 16 MHz: the clock and the host link follow core_mhz, the PWM and
 * the current and speed loops run at 16/168 of their rates. */
static void clock_init(void)
{
    uint32_t source;
    RCC_CR |= 1u << 16; /* HSEON */
    if (wait_for(&RCC_CR, 1u << 17, 1u << 17, HSE_TIMEOUT_CYCLES)) {
        source = 8u | (1u << 22); /* PLLM 8 from the 8 MHz crystal, PLLSRC HSE */
    } else {
        RCC_CR &= ~(1u << 16); /* a dead or missing crystal: stop trying */
        clock_fallback = 1;
        source = 16u; /* PLLM 16 from the 16 MHz HSI, PLLSRC HSI */
    }
    /* PLLN 336, PLLP 2 (bits 00), PLLQ 7; the reserved bits keep their reset value */
    RCC_PLLCFGR = (RCC_PLLCFGR & 0xF0BC8000u) | source | (336u << 6) | (0u << 16) | (7u << 24);
    RCC_CR |= 1u << 24; /* PLLON */
    if (!wait_for(&RCC_CR, 1u << 25, 1u << 25, PLL_TIMEOUT_CYCLES)) {
        clock_fallback = 1;
        return; /* on HSI at 16 MHz */
    }
    FLASH_ACR = 5u | (1u << 8) | (1u << 9) | (1u << 10); /* 5 wait states, prefetch, I- and D-cache */
    RCC_CFGR = (5u << 10) | (4u << 13);                  /* APB1 /4, APB2 /2 before the switch */
    RCC_CFGR |= 2u;                                      /* SYSCLK = PLL */
    if (wait_for(&RCC_CFGR, 3u << 2, 2u << 2, PLL_TIMEOUT_CYCLES)) {
        core_mhz = SYSCLK_MHZ;
    } else {
        clock_fallback = 1;
    }
}

int hal_clock_fallback(void) { return clock_fallback; }

uint32_t hal_apb1_mhz(void) { return core_mhz == SYSCLK_MHZ ? SYSCLK_MHZ / 4u : HSI_MHZ; }

static void encoder_init(uint32_t tim)
{
    TIM_ARR(tim) = 0xFFFFFFFFu;
    /* CC1S = TI1, CC2S = TI2; input filters IC1F = IC2F = 3 (8 samples at the timer clock, ~95 ns) */
    TIM_CCMR1(tim) = 1u | (3u << 4) | (1u << 8) | (3u << 12);
    TIM_SMCR(tim) = 3u;              /* encoder mode 3: count on both edges of both inputs */
    TIM_CNT(tim) = 0u;
    TIM_CR1(tim) = 1u;
}

static void pwm_init(uint32_t tim)
{
    TIM_PSC(tim) = 0u;
    TIM_ARR(tim) = PWM_PERIOD - 1u;
    TIM_CCMR1(tim) = (6u << 4) | (1u << 3); /* PWM mode 1, preload */
    TIM_CCR1(tim) = 0u;
    TIM_CCER(tim) = 1u;       /* CC1E */
    TIM_BDTR(tim) = 1u << 15; /* MOE: advanced timers drive their outputs only with it */
    TIM_EGR(tim) = 1u;
    TIM_CR1(tim) = 1u | (1u << 7);
}

void hal_init(void)
{
    SYST_RVR = SYST_MASK; /* SysTick free-running on the core clock: clock_init's timeouts, then the clock */
    SYST_CVR = 0u;
    SYST_CSR = (1u << 2) | 1u; /* CLKSOURCE = the core clock, ENABLE; no interrupt */
    clock_init();
#ifdef SASHIL_QEMU
    /* QEMU models no RCC (reads 0: clock_init above times out as on a dead crystal and flags it) and
     * runs SysTick on its fixed 168 MHz system clock */
    core_mhz = SYSCLK_MHZ;
#endif
    RCC_AHB1ENR |= 7u;                                            /* GPIOA, GPIOB, GPIOC */
    RCC_APB1ENR |= (1u << 0) | (1u << 3) | (1u << 4);             /* TIM2, TIM5, TIM6 */
    RCC_APB2ENR |= (1u << 0) | (1u << 1) | (1u << 4) | (1u << 8); /* TIM1, TIM8, USART1, ADC1 */

    pin_af(GPIOA, 15u, 1u); /* TIM2 CH1 */
    pin_af(GPIOB, 3u, 1u);  /* TIM2 CH2 */
    pin_af(GPIOA, 0u, 2u);  /* TIM5 CH1 */
    pin_af(GPIOA, 1u, 2u);  /* TIM5 CH2 */
    encoder_init(TIM2);
    encoder_init(TIM5);

    pin_af(GPIOA, 8u, 1u); /* TIM1 CH1: coil */
    pin_af(GPIOC, 6u, 3u); /* TIM8 CH1: road motor */
    GPIO_MODER(GPIOC) = (GPIO_MODER(GPIOC) & ~(3u << 14)) | (1u << 14); /* PC7 output: direction */
    pwm_init(TIM1);
    pwm_init(TIM8);

    GPIO_MODER(GPIOC) |= 3u;     /* PC0 analog: current sense */
    ADC_CCR = 1u << 16;          /* ADCCLK = PCLK2 / 4 = 21 MHz */
    ADC_SMPR1 = 3u;              /* channel 10: 56 cycles */
    ADC_SQR3 = 10u;
    ADC_CR2 = 1u;                /* ADON */

    pin_af(GPIOA, 9u, 7u);
    pin_af(GPIOA, 10u, 7u);
    /* 1 Mbit/s, oversampling by 16: BRR = f_APB2 / 1 MHz (84: 5 + 4/16 at 84 MHz; APB2 = HSI without PLL) */
    USART_BRR = core_mhz == SYSCLK_MHZ ? SYSCLK_MHZ / 2u : HSI_MHZ;
    USART_CR1 = (1u << 13) | (1u << 5) | (1u << 3) | (1u << 2); /* UE, RXNEIE, TE, RE */
    NVIC_ISER(37u / 32u) = 1u << (37u % 32u);

    TIM_PSC(TIM6) = 0u;
    TIM_ARR(TIM6) = 8399u;       /* 84 MHz / 8400 = 10 kHz */
    TIM_DIER(TIM6) = 1u;
    TIM_CR1(TIM6) = 1u;
    NVIC_ISER(54u / 32u) = 1u << (54u % 32u);

    clock_source_init();
}

/* DWT CYCCNT if it counts (a part may lack it, and QEMU models none: it reads 0 there), else SysTick
 * (PM0214 4.5), free-running on the core clock since hal_init. */
static void clock_source_init(void)
{
    DEMCR |= 1u << 24; /* TRCENA */
    DWT_CYCCNT = 0u;
    DWT_CTRL |= 1u;
    uint32_t first = DWT_CYCCNT;
    for (volatile int spin = 0; spin < 16; spin++) {
    }
    clock_is_dwt = DWT_CYCCNT != first;
}

#define USART_TXEIE (1u << 7)

void USART1_IRQHandler(void)
{
    uint32_t sr = USART_SR;
    if ((sr & (1u << 7)) && (USART_CR1 & USART_TXEIE)) { /* TXE: the next byte to send */
        if (tx_tail != tx_head) {
            USART_DR = tx_ring[tx_tail];
            tx_tail = (tx_tail + 1u) & (TX_RING - 1u);
        } else {
            USART_CR1 &= ~USART_TXEIE; /* nothing left: quiet until hal_send */
        }
    }
    if (sr & ((1u << 5) | (1u << 3))) { /* RXNE, or an overrun (reading DR clears it) */
        uint8_t byte = (uint8_t)USART_DR;
        uint32_t next = (rx_head + 1u) & (RX_RING - 1u);
        if (next != rx_tail) { /* full: the byte is lost and the frame's CRC will say so */
            rx_ring[rx_head] = byte;
            rx_head = next;
        }
    }
}

static float clamp(float x, float lo, float hi)
{
    return x < lo ? lo : (x > hi ? hi : x);
}

static uint32_t clamp_duty(float duty)
{
    if (duty <= 0.0f) {
        return 0u;
    }
    return duty >= (float)PWM_PERIOD ? PWM_PERIOD : (uint32_t)duty;
}

/* 10 kHz: the coil's current loop; every 10th tick the road motor's speed loop */
void TIM6_DAC_IRQHandler(void)
{
    TIM_SR(TIM6) = 0u;
    ADC_CR2 |= 1u << 30; /* SWSTART */
    while (!(ADC_SR & 2u)) {
    }
    uint32_t mv = (ADC_DR & 0xFFFu) * ADC_MV_FULL / 4095u;
    int32_t counts = (int32_t)(mv * 2000u / SENSE_MV_PER_A); /* 0.5 mA counts */
    coil_measured = (int16_t)counts;
    if (counts > OVERCURRENT_COUNTS) {
        overcurrent = 1u;
    }
    if (overcurrent || coil_setpoint == 0u) {
        coil_integral = 0.0f;
        TIM_CCR1(TIM1) = 0u;
    } else {
        float error = (float)coil_setpoint - (float)counts;
        coil_integral = clamp(coil_integral + 0.02f * error, 0.0f, (float)PWM_PERIOD);
        TIM_CCR1(TIM1) = clamp_duty(2.0f * error + coil_integral);
    }
    if (++ticks % 10u == 0u) {
        uint32_t now = TIM_CNT(TIM5);
        int32_t step = (int32_t)(now - road_last_counts); /* modulo 2^32: right across the counter's wrap */
        float speed = (float)step * (6.2831853f / ENCODER_COUNTS_PER_REV) * 1000.0f; /* rad/s */
        road_last_counts = now;
        float error = (float)road_setpoint * 1e-6f - speed;
        road_integral =
            road_setpoint == 0 ? 0.0f : clamp(road_integral + 5.0f * error, -(float)PWM_PERIOD, (float)PWM_PERIOD);
        float drive = 800.0f * error + road_integral;
        if (drive < 0.0f) {
            GPIO_BSRR(GPIOC) = 1u << (7u + 16u);
            drive = -drive;
        } else {
            GPIO_BSRR(GPIOC) = 1u << 7u;
        }
        TIM_CCR1(TIM8) = road_setpoint == 0 && speed == 0.0f ? 0u : clamp_duty(drive);
    }
}

void hal_read_encoders(void *ctx, int32_t *arm_counts, int32_t *road_counts)
{
    (void)ctx;
#ifdef SASHIL_QEMU
    /* QEMU's TIM2 and TIM5 model no encoder mode: they count time at 1 GHz, which would read as an arm
     * swung by thousands of degrees. The image reads a rig at rest instead, both encoders at their reset
     * position 0: the physics is the emulator's, QEMU checks the image's protocol, timing and safety. */
    *arm_counts = 0;
    *road_counts = 0;
#else
    *arm_counts = (int32_t)TIM_CNT(TIM2);
    *road_counts = (int32_t)TIM_CNT(TIM5);
#endif
}

int16_t hal_read_current(void *ctx)
{
    (void)ctx;
#ifdef SASHIL_QEMU
    /* QEMU models no TIM6 and so runs no current loop: the image reports an ideal coil, its current the
     * setpoint, so a sample shows what the board drives (and the watchdog's 0 A) */
    return (int16_t)coil_setpoint;
#else
    return coil_measured;
#endif
}

void hal_set_coil(void *ctx, uint16_t counts)
{
    (void)ctx;
    coil_setpoint = counts;
    if (counts == 0u) {
        overcurrent = 0u; /* the host's 0 A re-arms the driver */
    }
}

void hal_set_road_speed(void *ctx, int32_t urad_s)
{
    (void)ctx;
    road_setpoint = urad_s;
}

uint8_t hal_sensor_flags(void *ctx)
{
    (void)ctx;
    return overcurrent ? FLAG_OVERCURRENT : 0u;
}

void hal_send(void *ctx, const uint8_t *bytes, size_t n)
{
    (void)ctx;
#ifdef SASHIL_QEMU
    for (size_t i = 0; i < n; i++) {
        while (!(USART_SR & (1u << 7))) { /* TXE */
        }
        USART_DR = bytes[i];
    }
    return;
#endif
    uint32_t head = tx_head, free_bytes = (tx_tail - head - 1u) & (TX_RING - 1u);
    if (n > free_bytes) {
        return; /* the wire is behind by a whole ring: drop the frame whole (the host counts a missed sample) */
    }
    for (size_t i = 0; i < n; i++) {
        tx_ring[head] = bytes[i];
        head = (head + 1u) & (TX_RING - 1u);
    }
    tx_head = head;
    USART_CR1 |= USART_TXEIE;
}

/* The microsecond clock: the core's cycles, counted by DWT CYCCNT where the part has it running, else
 * by SysTick (24 bits, counting down at the core clock, which every Cortex-M4 has and QEMU models).
 * Either count is accumulated into microseconds with the spare cycles carried, so no time is lost
 * between calls; SysTick wraps every 2^24 cycles (0.1 s at 168 MHz), hence "call often enough". */
uint64_t hal_now_us(void)
{
    static uint32_t last_count, spare_cycles;
    static uint64_t us;
    uint32_t count, elapsed;
    if (clock_is_dwt) {
        count = DWT_CYCCNT;
        elapsed = count - last_count + spare_cycles; /* modulo 2^32: one wrap between calls */
    } else {
        count = SYST_CVR;
        elapsed = ((last_count - count) & SYST_MASK) + spare_cycles; /* counts down, modulo 2^24 */
    }
    last_count = count;
    us += elapsed / core_mhz;
    spare_cycles = elapsed % core_mhz;
    return us;
}

size_t hal_uart_take(uint8_t *out, size_t cap)
{
    size_t n = 0;
    while (n < cap && rx_tail != rx_head) {
        out[n++] = rx_ring[rx_tail];
        rx_tail = (rx_tail + 1u) & (RX_RING - 1u);
    }
    return n;
}

/* --- encoder edge times ------------------------------------------------------------------------
 * TIM7 interrupts at EDGE_POLL_HZ (100 kHz) and reads both encoder counters; a count that differs from
 * the last poll is an edge at that poll, with the direction of the difference. Why a poll and not input
 * capture: the encoder pins already feed TIM2/TIM5 in encoder mode, whose captures latch counts, not
 * times (a capture timer would need the A/B lines wired to a second timer's pins), and a capture
 * interrupt per edge costs 2 x 4096 x 10 = 82 k interrupts/s at the top speed against a poll's fixed
 * 100 k/s that also sees each edge on its own: at 4096 counts x 10 rev/s an edge comes every 24.4 us,
 * more than two poll periods.
 * ISR budget: entry and exit about 24 cycles, the body (two counter reads on APB1, two compares, the
 * stores) about 40: ~64 cycles x 100 kHz = 6.4 M cycles/s, 3.8 % of the 168 MHz core, whatever the
 * encoder speed. It preempts the 10 kHz current loop (whose ADC wait is ~3 us) and the UART, so an edge
 * is stamped within one poll: the time is the middle of the poll period it fell in, off by at most
 * +-5 us (drivers/protocol.md "Encoder edges").
 * The counts of a sample and its edges are taken together with the poll masked
 * (hal_read_encoders_timed), so the edge of a count the poll has not seen yet is the one since the last
 * poll, never the edge before it. */
#define TIM7 0x40001400u
#define TIM7_IRQ 55u
#define EDGE_POLL_HZ 100000u
#define EDGE_POLL_US (1000000u / EDGE_POLL_HZ)
#define TIMER_MHZ 84u /* APB1 timer clock */
#define NVIC_ICER(n) REG(0xE000E180u + 4u * (n))
#define NVIC_IPR(irq) (*(volatile uint8_t *)(0xE000E400u + (irq)))

static volatile uint32_t poll_ticks;                /* polls since hal_edges_init */
static volatile uint32_t arm_seen, road_seen;       /* the counts at the last poll */
static volatile uint32_t arm_edge_tick, road_edge_tick; /* the poll that saw each encoder's last change */
static volatile int8_t arm_edge_dir, road_edge_dir; /* +1 / -1; 0: no change since boot */
static sashil_edge sample_arm, sample_road;         /* the edges of the counts hal_read_encoders_timed read */

void hal_edges_init(void)
{
    RCC_APB1ENR |= 1u << 5; /* TIM7 */
    arm_seen = TIM_CNT(TIM2);
    road_seen = TIM_CNT(TIM5);
    TIM_PSC(TIM7) = 0u;
    TIM_ARR(TIM7) = TIMER_MHZ * EDGE_POLL_US - 1u; /* 84 MHz / 840 = 100 kHz */
    TIM_DIER(TIM7) = 1u;
    TIM_CR1(TIM7) = 1u;
    NVIC_IPR(TIM7_IRQ) = 0x00u; /* the poll preempts the others: its stamp does not wait for them */
    NVIC_IPR(37u) = 0x40u;      /* USART1 */
    NVIC_IPR(54u) = 0x40u;      /* TIM6: the current loop */
    NVIC_ISER(TIM7_IRQ / 32u) = 1u << (TIM7_IRQ % 32u);
}

void TIM7_IRQHandler(void)
{
    TIM_SR(TIM7) = 0u;
    uint32_t tick = poll_ticks + 1u;
    uint32_t arm = TIM_CNT(TIM2), road = TIM_CNT(TIM5);
    poll_ticks = tick;
    if (arm != arm_seen) {
        arm_edge_dir = (int32_t)(arm - arm_seen) > 0 ? 1 : -1; /* modulo 2^32: right across the wrap */
        arm_edge_tick = tick;
        arm_seen = arm;
    }
    if (road != road_seen) {
        road_edge_dir = (int32_t)(road - road_seen) > 0 ? 1 : -1;
        road_edge_tick = tick;
        road_seen = road;
    }
}

/* One encoder's last edge for a sample whose count is `count`, `since_us` after the last poll. */
static sashil_edge edge_of(uint32_t count, uint32_t seen, uint32_t edge_tick, int8_t dir, uint32_t ticks,
                           uint32_t since_us, uint32_t now_us)
{
    sashil_edge edge;
    if (count != seen) { /* a change the poll has not seen: between the last poll and now */
        edge.time_us = now_us - since_us / 2u;
        edge.dir = (int32_t)(count - seen) > 0 ? 1 : -1;
    } else {
        edge.time_us = now_us - since_us - (ticks - edge_tick) * EDGE_POLL_US - EDGE_POLL_US / 2u;
        edge.dir = dir;
    }
    return edge;
}

void hal_read_encoders_timed(void *ctx, int32_t *arm_counts, int32_t *road_counts)
{
    uint32_t now_us = (uint32_t)hal_now_us();
    NVIC_ICER(TIM7_IRQ / 32u) = 1u << (TIM7_IRQ % 32u); /* the poll waits: counts and edges are one snapshot */
    __asm__ volatile("dsb\n\tisb" ::: "memory");
    hal_read_encoders(ctx, arm_counts, road_counts);
    uint32_t ticks = poll_ticks, since_us = TIM_CNT(TIM7) / TIMER_MHZ;
    uint32_t arm = arm_seen, road = road_seen, arm_tick = arm_edge_tick, road_tick = road_edge_tick;
    int8_t arm_dir = arm_edge_dir, road_dir = road_edge_dir;
    NVIC_ISER(TIM7_IRQ / 32u) = 1u << (TIM7_IRQ % 32u);
    sample_arm = edge_of((uint32_t)*arm_counts, arm, arm_tick, arm_dir, ticks, since_us, now_us);
    sample_road = edge_of((uint32_t)*road_counts, road, road_tick, road_dir, ticks, since_us, now_us);
}

void hal_read_edges(void *ctx, sashil_edge *arm, sashil_edge *road)
{
    (void)ctx;
    *arm = sample_arm;
    *road = sample_road;
}
