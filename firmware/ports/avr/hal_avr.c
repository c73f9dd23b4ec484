/* hal_avr.c - the HAL (pfw_hal.h) on an ATmega2560 at 16 MHz; pin map and choices in hal_avr.h. */
#include "hal_avr.h"

#include <avr/eeprom.h>
#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/sleep.h>
#include <avr/wdt.h>
#include <util/atomic.h>

#include "boot_id.h"

#define UART_BAUD 57600UL
#define UBRR_VALUE ((F_CPU + 4UL * UART_BAUD) / (8UL * UART_BAUD) - 1UL) /* U2X0 = 1: 34 at 16 MHz */
#define RX_SIZE 128u  /* a power of two: 22 ms of the XBee line at 57600 baud */
#define TX_SIZE 128u  /* a power of two; the core keeps what does not fit (pfw_app.out, pfw_fw.tx) */
#define SERVO_TOP 39999u /* Timer1 at 16 MHz / 8 = 2 MHz: 40000 counts = 20 ms, 0.5 us per count */
#define ENTROPY_ADC 32u
#define ENTROPY_WDT 8u
#define BOOT_COUNTER_ADDRESS ((uint32_t *)0) /* EEPROM: the power-up counter (erased cells read 0xFFFFFFFF) */

static volatile uint32_t clock_ms;
static volatile uint8_t rx_buf[RX_SIZE], tx_buf[TX_SIZE];
static volatile uint8_t rx_head, rx_tail, tx_head, tx_tail;
static volatile uint16_t rx_overflows;
static volatile uint16_t servo_counts[2] = {2u * 1500u, 2u * 1500u}; /* the widths the next frame starts with */
static uint32_t boot_random;

/* Start-up code (stack paint, watchdog off after a watchdog reset): hal_avr_init.S. */

ISR(TIMER0_COMPA_vect)
{
    clock_ms++;
}

/* Timer1 reached TOP: the next 20 ms frame starts. The new widths go into OCR1A/B here, at the frame's start,
 * as the ATmega2560's own double buffering of OCR1x in the PWM modes would load them. Done by hand because simavr
 * 1.6 applies an OCR1x write at once: a width lowered below the counter mid-pulse missed its compare there and
 * stretched that pulse to 21 ms (a servo would jump). On the chip the result is the same either way. */
ISR(TIMER1_OVF_vect)
{
    OCR1A = servo_counts[0];
    OCR1B = servo_counts[1];
}

ISR(USART0_RX_vect)
{
    uint8_t status = UCSR0A, byte = UDR0, next = (uint8_t)((rx_head + 1u) & (RX_SIZE - 1u));
    if (status & (_BV(FE0) | _BV(DOR0)))
        rx_overflows++; /* a framing error or a byte the hardware lost: the frame's checksum drops it */
    if (next == rx_tail) {
        rx_overflows++;
        return;
    }
    rx_buf[rx_head] = byte;
    rx_head = next;
}

ISR(USART0_UDRE_vect)
{
    if (tx_tail == tx_head) {
        UCSR0B &= (uint8_t)~_BV(UDRIE0);
        return;
    }
    UDR0 = tx_buf[tx_tail];
    tx_tail = (uint8_t)((tx_tail + 1u) & (TX_SIZE - 1u));
}

static uint32_t hal_millis(void *ctx)
{
    uint32_t now;
    (void)ctx;
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) { now = clock_ms; }
    return now;
}

static size_t hal_uart_read(void *ctx, uint8_t *buf, size_t max)
{
    size_t n = 0;
    (void)ctx;
    while (n < max && rx_tail != rx_head) { /* rx_head is one byte: read atomically */
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
    if (n)
        UCSR0B |= _BV(UDRIE0);
    return n;
}

uint16_t hal_avr_pulse_us(float angle_rad)
{
    float us = SERVO_CENTRE_US + (angle_rad - 1.5707963f) * SERVO_US_PER_RAD;
    if (!(us >= (float)SERVO_PULSE_MIN_US)) /* also catches NaN */
        return SERVO_PULSE_MIN_US;
    if (us > (float)SERVO_PULSE_MAX_US)
        return SERVO_PULSE_MAX_US;
    return (uint16_t)(us + 0.5f);
}

static void hal_servo_write(void *ctx, uint8_t fin, float angle_rad)
{
    uint16_t counts = (uint16_t)(2u * hal_avr_pulse_us(angle_rad)); /* 0.5 us per count */
    (void)ctx;
    /* The 16-bit store must not be torn by the frame-start interrupt that reads it. */
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) { servo_counts[fin ? 1 : 0] = counts; }
}

static uint32_t hal_random32(void *ctx)
{
    (void)ctx;
    return boot_random;
}

/* Entropy for the boot id: the low bits of ADC conversions of a floating input (thermal and supply noise), and
 * how many loop iterations the crystal-clocked CPU makes in one period of the watchdog's own 128 kHz RC
 * oscillator (the two clocks drift against each other with temperature and voltage), mixed with a power-up
 * counter in EEPROM that makes consecutive power-ups differ even if both noise sources failed. */
static uint32_t gather_boot_id(void)
{
    uint16_t samples[ENTROPY_ADC + ENTROPY_WDT];
    uint32_t counter = eeprom_read_dword(BOOT_COUNTER_ADDRESS) + 1u;
    uint8_t i;
    eeprom_update_dword(BOOT_COUNTER_ADDRESS, counter);
    ADMUX = _BV(REFS0);                                     /* AVCC reference, ADC0 */
    ADCSRA = _BV(ADEN) | _BV(ADPS2) | _BV(ADPS1) | _BV(ADPS0); /* 16 MHz / 128 = 125 kHz */
    for (i = 0; i < ENTROPY_ADC; i++) {
        ADCSRA |= _BV(ADSC);
        while (ADCSRA & _BV(ADSC)) {
        }
        samples[i] = ADC;
    }
    ADCSRA = 0; /* ADC off */
    for (i = 0; i < ENTROPY_WDT; i++) {
        uint16_t count = 0;
        ATOMIC_BLOCK(ATOMIC_RESTORESTATE)
        {
            wdt_reset();
            WDTCSR = _BV(WDCE) | _BV(WDE);
            WDTCSR = _BV(WDIF) | _BV(WDIE); /* interrupt mode (flag only: interrupts are off), 16 ms */
        }
        while (!(WDTCSR & _BV(WDIF)) && count != 0xFFFFu) /* bounded: ~33 ms if the flag never comes */
            count++;
        samples[ENTROPY_ADC + i] = count;
    }
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) { wdt_disable(); }
    return boot_id_mix(counter, samples, ENTROPY_ADC + ENTROPY_WDT);
}

void hal_avr_init(pfw_hal *hal)
{
    DDRA |= _BV(PA0) | _BV(PA1); /* probes, low */
    PORTA &= (uint8_t)~(_BV(PA0) | _BV(PA1));

    boot_random = gather_boot_id(); /* before the watchdog is armed: it takes ~130 ms */

    /* Timer0: CTC, 16 MHz / 64 / 250 = 1 kHz */
    TCCR0A = _BV(WGM01);
    TCCR0B = _BV(CS01) | _BV(CS00);
    OCR0A = 249;
    TIMSK0 = _BV(OCIE0A);

    /* Timer1: fast PWM, TOP = ICR1 (mode 14), clear OC1A/OC1B on compare match, 16 MHz / 8 */
    OCR1A = 2u * 1500u;
    OCR1B = 2u * 1500u;
    ICR1 = SERVO_TOP;
    TCCR1A = _BV(COM1A1) | _BV(COM1B1) | _BV(WGM11);
    TCCR1B = _BV(WGM13) | _BV(WGM12) | _BV(CS11);
    TIMSK1 = _BV(TOIE1); /* frame start: load the widths (TIMER1_OVF_vect) */
    DDRB |= _BV(PB5) | _BV(PB6);

    /* USART0: 57600 baud (double speed), 8N1, receive interrupt; the transmit interrupt runs while bytes wait */
    UBRR0 = (uint16_t)UBRR_VALUE;
    UCSR0A = _BV(U2X0);
    UCSR0C = _BV(UCSZ01) | _BV(UCSZ00);
    UCSR0B = _BV(RXEN0) | _BV(TXEN0) | _BV(RXCIE0);

    hal->ctx = 0;
    hal->millis = hal_millis;
    hal->uart_read = hal_uart_read;
    hal->uart_write = hal_uart_write;
    hal->servo_write = hal_servo_write;
    hal->random32 = hal_random32;

    wdt_enable(WDTO_120MS); /* a main loop stuck for 120 ms resets the MCU: power-up again, IDLE, fins to rest */
    sei();
}

void hal_avr_idle(void)
{
    set_sleep_mode(SLEEP_MODE_IDLE);
    sleep_mode();
}

void hal_avr_kick(void)
{
    wdt_reset();
}

uint16_t hal_avr_rx_overflows(void)
{
    uint16_t n;
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) { n = rx_overflows; }
    return n;
}
