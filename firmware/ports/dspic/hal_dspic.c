/* hal_dspic.c - the HAL (pfw_hal.h) on the dsPIC30F6014 with XC16; pin map, clock and choices in hal_dspic.h.
 *
 * Built with XC16 (make -C firmware dspic). Without XC16, make -C firmware dspic-check compiles this file with the
 * host's gcc against check/xc.h and check/libpic30.h (register stubs) and runs check/check_dspic.c on it: the C is
 * checked and the port's arithmetic (baud, timer periods, pulse widths, rings) is tested, the register semantics
 * are not (they are the datasheet's). */
#include "hal_dspic.h"

#include <libpic30.h>
#include <xc.h>

#include "boot_id.h"

#ifndef PFW_ISR /* the host check defines it empty */
#define PFW_ISR __attribute__((interrupt, no_auto_psv))
#endif
#ifndef PFW_EEDATA
#define PFW_EEDATA __attribute__((space(eedata), aligned(_EE_WORD)))
#endif

#define RX_SIZE 128u /* a power of two: 22 ms of the XBee line at 57600 baud */
#define TX_SIZE 128u
#define ENTROPY_ADC 32u
#define ENTROPY_RC 8u

static volatile uint32_t clock_ms;
static volatile uint8_t rx_buf[RX_SIZE], tx_buf[TX_SIZE];
static volatile uint8_t rx_head, rx_tail, tx_head, tx_tail;
static volatile uint16_t rx_overflows;
static uint32_t boot_random;

/* The power-up counter in data EEPROM (2 words, low first; erased cells read 0xFFFF). */
static int boot_counter_ee[2] PFW_EEDATA = {-1, -1};

void PFW_ISR _T1Interrupt(void)
{
    clock_ms++;
    IFS0bits.T1IF = 0;
}

void PFW_ISR _U2RXInterrupt(void)
{
    IFS1bits.U2RXIF = 0;
    if (U2STAbits.OERR) {
        U2STAbits.OERR = 0; /* the receiver stops after an overrun until OERR is cleared */
        rx_overflows++;
    }
    while (U2STAbits.URXDA) { /* the 4-deep receive FIFO */
        uint8_t byte = (uint8_t)U2RXREG, next = (uint8_t)((rx_head + 1u) & (RX_SIZE - 1u));
        if (next == rx_tail) {
            rx_overflows++;
            continue;
        }
        rx_buf[rx_head] = byte;
        rx_head = next;
    }
}

void PFW_ISR _U2TXInterrupt(void)
{
    IFS1bits.U2TXIF = 0;
    while (!U2STAbits.UTXBF && tx_tail != tx_head) { /* fill the transmit FIFO */
        U2TXREG = tx_buf[tx_tail];
        tx_tail = (uint8_t)((tx_tail + 1u) & (TX_SIZE - 1u));
    }
    if (tx_tail == tx_head)
        IEC1bits.U2TXIE = 0;
}

static uint32_t hal_millis(void *ctx)
{
    uint32_t a, b;
    (void)ctx;
    do { /* a 32-bit read is two 16-bit reads on this core: repeat if the interrupt came in between */
        a = clock_ms;
        b = clock_ms;
    } while (a != b);
    return a;
}

static size_t hal_uart_read(void *ctx, uint8_t *buf, size_t max)
{
    size_t n = 0;
    (void)ctx;
    while (n < max && rx_tail != rx_head) {
        buf[n++] = rx_buf[rx_tail];
        rx_tail = (uint8_t)((rx_tail + 1u) & (RX_SIZE - 1u));
    }
    return n;
}

static size_t hal_uart_write(void *ctx, const uint8_t *buf, size_t len)
{
    size_t n = 0;
    (void)ctx;
    while (n < len) {
        uint8_t next = (uint8_t)((tx_head + 1u) & (TX_SIZE - 1u));
        if (next == tx_tail)
            break; /* full: the core offers the rest again at the next step */
        tx_buf[tx_head] = buf[n++];
        tx_head = next;
    }
    if (n) {
        IEC1bits.U2TXIE = 1;
        IFS1bits.U2TXIF = 1; /* a flag set by software requests the interrupt: it starts the transmission */
    }
    return n;
}

uint16_t hal_dspic_pulse_counts(float angle_rad)
{
    float us = SERVO_CENTRE_US + (angle_rad - 1.5707963f) * SERVO_US_PER_RAD;
    if (!(us >= (float)SERVO_PULSE_MIN_US)) /* also catches NaN */
        us = (float)SERVO_PULSE_MIN_US;
    if (us > (float)SERVO_PULSE_MAX_US)
        us = (float)SERVO_PULSE_MAX_US;
    return (uint16_t)(us * ((float)DSPIC_SERVO_TIMER_HZ * 1e-6f) + 0.5f);
}

static void hal_servo_write(void *ctx, uint8_t fin, float angle_rad)
{
    uint16_t counts = hal_dspic_pulse_counts(angle_rad);
    (void)ctx;
    /* In PWM mode OCxRS is loaded into OCxR at the next Timer2 period match: a width never changes mid-pulse.
     * The width is never 0 (errata of the 30F601xA: loading a 0 % duty cycle glitches). */
    if (fin == 0u)
        OC1RS = counts;
    else
        OC2RS = counts;
}

static uint32_t hal_random32(void *ctx)
{
    (void)ctx;
    return boot_random;
}

static uint32_t next_boot_counter(void)
{
    _prog_addressT ee;
    int words[2];
    uint32_t counter;
    _init_prog_address(ee, boot_counter_ee);
    _memcpy_p2d16(words, ee, sizeof words);
    counter = ((uint32_t)(uint16_t)words[1] << 16 | (uint16_t)words[0]) + 1u;
    _erase_eedata(ee, _EE_WORD); /* word by word: nothing else in the EEPROM is touched */
    _wait_eedata();
    _write_eedata_word(ee, (int)(counter & 0xFFFFu));
    _wait_eedata();
    _erase_eedata(ee + 2, _EE_WORD);
    _wait_eedata();
    _write_eedata_word(ee + 2, (int)(counter >> 16));
    _wait_eedata();
    return counter;
}

/* Entropy for the boot id (docs/protocol.md, section 5): 12-bit conversions of the floating input AN15 (thermal
 * and supply noise in the low bits), each conversion clocked by the ADC's own RC oscillator and timed in Fcy
 * cycles by Timer3 (two independent oscillators: the count jitters), mixed with a power-up counter in data EEPROM
 * that makes consecutive power-ups differ even if both noise sources failed (ports/common/boot_id.h). */
static uint32_t gather_boot_id(void)
{
    uint16_t samples[ENTROPY_ADC + ENTROPY_RC];
    uint32_t counter = next_boot_counter();
    unsigned i;
    T3CON = 0;
    TMR3 = 0;
    PR3 = 0xFFFFu;
    T3CONbits.TON = 1;
    ADPCFG = (uint16_t)~(1u << 15); /* AN15 analog, the rest digital */
    ADCHS = 15u;                    /* CH0 positive input AN15 */
    ADCON1 = 0;                     /* manual sampling, conversion when SAMP is cleared, integer result */
    ADCON2 = 0;                     /* AVdd/AVss references */
    ADCON3 = 0;
    ADCON3bits.ADRC = 1; /* the ADC's internal RC clock, independent of the FRC and the PLL */
    ADCON1bits.ADON = 1;
    for (i = 0; i < ENTROPY_ADC + ENTROPY_RC; i++) {
        uint16_t start;
        ADCON1bits.SAMP = 1;
        for (start = TMR3; (uint16_t)(TMR3 - start) < 300u;) { /* sample ~10 us */
        }
        start = TMR3;
        ADCON1bits.SAMP = 0; /* convert */
        while (!ADCON1bits.DONE) {
        }
        samples[i] = i < ENTROPY_ADC ? (uint16_t)ADCBUF0 : (uint16_t)(TMR3 - start);
    }
    ADCON1bits.ADON = 0;
    T3CONbits.TON = 0;
    ADPCFG = 0xFFFFu;
    return boot_id_mix(counter, samples, ENTROPY_ADC + ENTROPY_RC);
}

void hal_dspic_init(pfw_hal *hal)
{
    TRISDbits.TRISD2 = 0; /* the probe, low */
    LATDbits.LATD2 = 0;

    boot_random = gather_boot_id();

    /* Timer1: the 1 ms clock */
    T1CON = 0;
    TMR1 = 0;
    PR1 = (uint16_t)DSPIC_PR1;
    IPC0bits.T1IP = 5;
    IFS0bits.T1IF = 0;
    IEC0bits.T1IE = 1;
    T1CONbits.TON = 1;

    /* Timer2 and OC1/OC2 in PWM mode (OCM = 110, no fault input): 50 Hz frames, 1500 us to start with */
    T2CON = 0;
    T2CONbits.TCKPS = 2; /* 1:64 */
    TMR2 = 0;
    PR2 = (uint16_t)DSPIC_PR2;
    OC1R = OC1RS = hal_dspic_pulse_counts(1.5707963f);
    OC2R = OC2RS = hal_dspic_pulse_counts(1.5707963f);
    OC1CON = 0;
    OC2CON = 0;
    OC1CONbits.OCTSEL = 0; /* Timer2 */
    OC2CONbits.OCTSEL = 0;
    OC1CONbits.OCM = 6;
    OC2CONbits.OCM = 6;
    T2CONbits.TON = 1;

    /* UART2: 57600 baud 8N1; receive interrupt per byte, transmit interrupt while bytes wait */
    U2MODE = 0;
    U2BRG = (uint16_t)DSPIC_U2BRG;
    U2STA = 0; /* UTXISEL = 0: interrupt when a byte moves on from the transmit buffer; URXISEL = 0: per byte */
    IPC6bits.U2RXIP = 6; /* the highest of ours: a byte arrives every 174 us, the FIFO holds 4 */
    IPC6bits.U2TXIP = 4;
    IFS1bits.U2RXIF = 0;
    IEC1bits.U2RXIE = 1;
    U2MODEbits.UARTEN = 1;
    U2STAbits.UTXEN = 1;

    hal->ctx = 0;
    hal->millis = hal_millis;
    hal->uart_read = hal_uart_read;
    hal->uart_write = hal_uart_write;
    hal->servo_write = hal_servo_write;
    hal->random32 = hal_random32;
}

void hal_dspic_idle(void)
{
    Idle(); /* pwrsav #1; not Sleep, which the 30F601xA errata warn against */
}

void hal_dspic_kick(void)
{
    ClrWdt();
}

uint16_t hal_dspic_rx_overflows(void)
{
    return rx_overflows; /* 16 bits: one read on this core */
}
