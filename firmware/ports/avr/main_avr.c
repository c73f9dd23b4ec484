/* main_avr.c - the robot firmware on the ATmega2560 (hal_avr.h): the core's main loop over the HAL. */
#include <avr/io.h>

#include "hal_avr.h"
#include "pfw.h"

static pfw_app app; /* all of the rules' state: static, so avr-size counts it (no heap, no large stack frame) */

#ifdef PFW_AVR_EVENTS
/* The events build (make avr-events), for the emulator only: after every step, the core's fin events (latches,
 * halts) and its state go out on USART1 at 2 Mbaud, 58-byte records starting 0xA5, so that an emulated fish can
 * follow the simulated microcontroller's fins (sim/simavr_core.py). Blocking writes: about 0.3 ms per record. */
static uint8_t reported_state = 0xFF;

static void event_put(const void *data, uint8_t n)
{
    const uint8_t *byte = data;
    while (n--) {
        while (!(UCSR1A & _BV(UDRE1))) {
        }
        UDR1 = *byte++;
    }
}

static void event_record(const pfw_event *ev)
{
    static const uint8_t sync = 0xA5;
    const pfw_fin *fin = &app.fw.fin[ev->fin & 1u];
    event_put(&sync, 1);
    event_put(&ev->kind, 1);
    event_put(&ev->fin, 1);
    event_put(&ev->power, 1);
    event_put(&ev->still, 1);
    event_put(&ev->ms, 4);
    event_put(&ev->frac_ms, 4);
    event_put(&ev->turn, 4);
    event_put(ev->pattern, 16);
    event_put(ev->angles, 8);
    event_put(fin->pending, 16);
    event_put(&app.fw.state, 1);
}

static void report_events(void)
{
    pfw_event ev;
    while (pfw_event_take(&app.fw, &ev))
        event_record(&ev);
    if (app.fw.state != reported_state) { /* kind 0: the state changed; ms carries the boot id */
        pfw_event st = {0};
        st.ms = app.fw.boot;
        event_record(&st);
        reported_state = app.fw.state;
    }
}

static void event_uart_init(void)
{
    UBRR1 = 0;
    UCSR1A = _BV(U2X1); /* 16 MHz / 8 = 2 Mbaud */
    UCSR1C = _BV(UCSZ11) | _BV(UCSZ10);
    UCSR1B = _BV(TXEN1);
}
#else
static void report_events(void) {}
static void event_uart_init(void) {}
#endif

int main(void)
{
    pfw_hal hal;
    pfw_config cfg;
    hal_avr_init(&hal);
    event_uart_init();
    pfw_config_default(&cfg);
    if (pfw_app_init(&app, &hal, &cfg) != 0) {
        for (;;) {
            hal_avr_idle(); /* a bad configuration is a build error; the watchdog resets, the servos get nothing */
        }
    }
    for (;;) {
        PORTA |= _BV(PA0); /* probe: the step's length, for a logic analyser or the simulator harness */
        pfw_app_step(&app);
        PORTA &= (uint8_t)~_BV(PA0);
        report_events();
        hal_avr_kick();
        hal_avr_idle(); /* until the next byte or millisecond */
    }
}
