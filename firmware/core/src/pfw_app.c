/* The board's main loop over the HAL (pfw_hal.h): UART in, a tick every PFW_TICK_MS, servos, UART out. */
#include <string.h>

#include "pfw.h"

#define READ_CHUNK 32u /* bytes read per step: bounds one step's work */

int pfw_app_init(pfw_app *app, const pfw_hal *hal, const pfw_config *cfg)
{
    uint32_t boot = hal->random32(hal->ctx);
    uint32_t now = hal->millis(hal->ctx);
    if (boot == 0u) {
        boot = 1u; /* nonzero: 0 means "no deadline" in a SET_FINS */
    }
    memset(app, 0, sizeof *app);
    app->hal = *hal;
    if (pfw_init(&app->fw, cfg, boot, now) != 0) {
        return -1;
    }
    app->last_tick_ms = now;
    app->hal.servo_write(app->hal.ctx, 0u, pfw_fin_angle(&app->fw, 0u));
    app->hal.servo_write(app->hal.ctx, 1u, pfw_fin_angle(&app->fw, 1u));
    return 0;
}

void pfw_app_step(pfw_app *app)
{
    uint8_t in[READ_CHUNK];
    size_t n = app->hal.uart_read(app->hal.ctx, in, sizeof in);
    uint32_t now = app->hal.millis(app->hal.ctx);
    if (n > 0u) {
        pfw_receive(&app->fw, in, n, now);
    }
    if ((uint32_t)(now - app->last_tick_ms) >= PFW_TICK_MS) {
        app->last_tick_ms = now;
        pfw_tick(&app->fw, now);
        app->hal.servo_write(app->hal.ctx, 0u, pfw_fin_angle(&app->fw, 0u));
        app->hal.servo_write(app->hal.ctx, 1u, pfw_fin_angle(&app->fw, 1u));
    }
    if (app->out_pos == app->out_len) {
        app->out_len = pfw_tx_take(&app->fw, app->out, sizeof app->out);
        app->out_pos = 0;
    }
    if (app->out_pos < app->out_len) {
        app->out_pos += app->hal.uart_write(app->hal.ctx, app->out + app->out_pos, app->out_len - app->out_pos);
    }
}
