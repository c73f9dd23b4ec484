/* main_avr.c - the robot firmware on the ATmega2560 (hal_avr.h): the core's main loop over the HAL. */
#include <avr/io.h>

#include "hal_avr.h"
#include "pfw.h"

static pfw_app app; /* all of the rules' state: static, so avr-size counts it (no heap, no large stack frame) */

int main(void)
{
    pfw_hal hal;
    pfw_config cfg;
    hal_avr_init(&hal);
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
        hal_avr_kick();
        hal_avr_idle(); /* until the next byte or millisecond */
    }
}
