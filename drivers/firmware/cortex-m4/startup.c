/*
 * Start-up of the interface board on an STM32F405/F407-class Cortex-M4F: the vector table and the
 * reset handler. The core reads the initial stack pointer and the reset vector from the first two
 * words of flash (ARMv7-M Architecture Reference Manual B1.5.3); the device's interrupt numbers are
 * those of RM0090 table 61 ("Vector table for STM32F405xx/07xx"). Reset_Handler copies .data from
 * flash, zeroes .bss, grants the FPU full access (CPACR, PM0214 section 4.6.1) and calls main.
 */
#include <stdint.h>

extern uint32_t _sidata, _sdata, _edata, _sbss, _ebss, _estack;
int main(void);

void Reset_Handler(void);
void Default_Handler(void);
void USART1_IRQHandler(void);
void TIM6_DAC_IRQHandler(void);
#ifdef SASHIL_CAN
void CAN1_TX_IRQHandler(void);
void CAN1_RX0_IRQHandler(void);
#endif
void TIM7_IRQHandler(void);

void Default_Handler(void)
{
    for (;;) {
        /* an exception nobody handles: stop here (the coil driver's own enable falls with the PWM) */
    }
}

#define IRQ_COUNT 82u
#define USART1_IRQ 37u
#define TIM6_DAC_IRQ 54u
#define CAN1_TX_IRQ 19u
#define CAN1_RX0_IRQ 20u
#define TIM7_IRQ 55u

typedef void (*vector)(void);

/* 16 system vectors, then the device interrupts; everything unused goes to Default_Handler */
__attribute__((section(".isr_vector"), used)) const vector vectors[16u + IRQ_COUNT] = {
    [0] = (vector)(uintptr_t)&_estack,
    [1] = Reset_Handler,
    [2] = Default_Handler,  /* NMI */
    [3] = Default_Handler,  /* HardFault */
    [4] = Default_Handler,  /* MemManage */
    [5] = Default_Handler,  /* BusFault */
    [6] = Default_Handler,  /* UsageFault */
    [11] = Default_Handler, /* SVCall */
    [12] = Default_Handler, /* DebugMonitor */
    [14] = Default_Handler, /* PendSV */
    [15] = Default_Handler, /* SysTick */
    [16u + USART1_IRQ] = USART1_IRQHandler,
    [16u + TIM6_DAC_IRQ] = TIM6_DAC_IRQHandler,
#ifdef SASHIL_CAN
    [16u + CAN1_TX_IRQ] = CAN1_TX_IRQHandler,
    [16u + CAN1_RX0_IRQ] = CAN1_RX0_IRQHandler,
#endif
    [16u + TIM7_IRQ] = TIM7_IRQHandler,
};

#define SCB_CPACR (*(volatile uint32_t *)0xE000ED88u)

void Reset_Handler(void)
{
    uint32_t *src = &_sidata, *dst = &_sdata;
    while (dst < &_edata) {
        *dst++ = *src++;
    }
    for (dst = &_sbss; dst < &_ebss; dst++) {
        *dst = 0u;
    }
    SCB_CPACR |= 0xFu << 20; /* CP10 and CP11: full access to the FPU */
    __asm__ volatile("dsb\n\tisb" ::: "memory");
    (void)main();
    Default_Handler();
}
