/* Reset for the Cortex-M4F: enable the FPU (CPACR: full access to CP10/CP11) before any
 * float instruction, copy .data from flash, zero .bss, run main. A fault ends the QEMU run
 * through semihosting with a nonzero exit status instead of hanging. */
#include <stdint.h>

extern uint32_t _sidata, _sdata, _edata, _sbss, _ebss, _estack;
int main(void);

#define CPACR (*(volatile uint32_t *)0xE000ED88u)

static void semihost_exit_error(void)
{
    /* SYS_EXIT (0x18) with ADP_Stopped_RunTimeErrorUnknown (0x20023) */
    register uint32_t op __asm__("r0") = 0x18u;
    register uint32_t reason __asm__("r1") = 0x20023u;
    __asm__ volatile("bkpt 0xAB" : : "r"(op), "r"(reason) : "memory");
    for (;;) {
    }
}

void Reset_Handler(void)
{
    CPACR |= 0xFu << 20;
    __asm__ volatile("dsb\n\tisb" : : : "memory");
    for (uint32_t *src = &_sidata, *dst = &_sdata; dst < &_edata;)
        *dst++ = *src++;
    for (uint32_t *dst = &_sbss; dst < &_ebss;)
        *dst++ = 0;
    main();
    semihost_exit_error();
}

void Fault_Handler(void)
{
    semihost_exit_error();
}

__attribute__((section(".isr_vector"), used)) static void (*const vectors[16])(void) = {
    (void (*)(void))(&_estack), Reset_Handler,
    Fault_Handler, Fault_Handler, Fault_Handler, Fault_Handler, Fault_Handler,
    0, 0, 0, 0,
    Fault_Handler, Fault_Handler, 0, Fault_Handler, Fault_Handler,
};
