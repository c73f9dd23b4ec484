; hal_avr_init.S - start-up code of the ATmega2560 port, in the C runtime's .init sections (no stack frame).
#include <avr/io.h>

; .init1 (before the stack pointer and r1 are set up): paint the free RAM, from the end of .bss (_end) to the top
; of the stack (__stack), with 0xC5, so the stack's high-water mark can be read later (the simulator harness
; does; on the robot a debugger can).
    .section .init1,"ax",@progbits
    ldi r30, lo8(_end)
    ldi r31, hi8(_end)
    ldi r24, 0xC5
    ldi r25, hi8(__stack)
    rjmp 2f
1:  st Z+, r24
2:  cpi r30, lo8(__stack)
    cpc r31, r25
    brlo 1b
    breq 1b

; .init3 (r1 = 0, interrupts off): a watchdog reset leaves the watchdog running at its shortest timeout;
; clear the reset flags and switch it off before the C runtime clears .bss (avr-libc's wdt_disable sequence).
    .section .init3,"ax",@progbits
    out _SFR_IO_ADDR(MCUSR), r1
    wdr
    lds r24, _SFR_MEM_ADDR(WDTCSR)
    ori r24, (1 << WDCE) | (1 << WDE)
    sts _SFR_MEM_ADDR(WDTCSR), r24
    sts _SFR_MEM_ADDR(WDTCSR), r1
