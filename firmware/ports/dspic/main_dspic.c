/* main_dspic.c - the robot firmware on the dsPIC30F6014 (hal_dspic.h): the core's main loop over the HAL. */
#include <xc.h>

#include "hal_dspic.h"
#include "pfw.h"

static pfw_app app; /* all of the rules' state: static, so the linker's memory report counts it */

int main(void)
{
    pfw_hal hal;
    pfw_config cfg;
    hal_dspic_init(&hal);
    pfw_config_default(&cfg);
    if (pfw_app_init(&app, &hal, &cfg) != 0) {
        for (;;) {
            hal_dspic_idle(); /* a bad configuration is a build error; the watchdog resets, the fins stay still */
        }
    }
    for (;;) {
        LATDbits.LATD2 = 1; /* probe: the step's length, for a logic analyser */
        pfw_app_step(&app);
        LATDbits.LATD2 = 0;
        hal_dspic_kick();
        hal_dspic_idle(); /* until the next byte or millisecond */
    }
}
