/* Reset and vector table for an eha-hil image: enable the FPU, copy .data, zero .bss, run
 * main (which sets up and waits for interrupts). TIM2_IRQHandler is the 5 kHz cycle. */
#include <stdint.h>

extern uint32_t _sidata, _sdata, _edata, _sbss, _ebss, _estack;
int main(void);
void TIM2_IRQHandler(void);

#define CPACR (*(volatile uint32_t *)0xE000ED88u)

void Reset_Handler(void)
{
    CPACR |= 0xFu << 20; /* CP10/CP11 full access: the FPU */
    __asm__ volatile("dsb\n\tisb" : : : "memory");
    for (uint32_t *src = &_sidata, *dst = &_sdata; dst < &_edata;)
        *dst++ = *src++;
    for (uint32_t *dst = &_sbss; dst < &_ebss;)
        *dst++ = 0;
    main();
    for (;;)
        __asm__ volatile("wfi");
}

void Default_Handler(void)
{
    for (;;) {
    }
}

#define D Default_Handler
__attribute__((section(".isr_vector"), used)) static void (*const vectors[16 + 29])(void) = {
    (void (*)(void))(&_estack), Reset_Handler,
    D, D, D, D, D, 0, 0, 0, 0, D, D, 0, D, D,            /* NMI .. SysTick */
    D, D, D, D, D, D, D, D, D, D, D, D, D, D, D, D,      /* IRQ 0..15 */
    D, D, D, D, D, D, D, D, D, D, D, D,                  /* IRQ 16..27 */
    TIM2_IRQHandler,                                     /* IRQ 28: TIM2 */
};
