/*
 * pfw_hal.h - the one interface between the robot's rules (firmware/core) and a board.
 *
 * Contract (every port implements these five functions and fills a pfw_hal; the core calls them only from
 * pfw_app_init() and pfw_app_step(), never from an interrupt; none may block for long):
 *
 *   millis(ctx)            free-running millisecond clock, uint32_t, wraps after 2^32 ms (49.7 days); the core
 *                          compares times wrap-safe. Must be monotonic (+1 per ms, any tick source).
 *   uart_read(ctx, b, n)   copy up to n bytes the XBee sent (API mode 2, escaped frames) into b; return how many
 *                          (0 if none). Non-blocking: the port buffers received bytes (e.g. an RX interrupt ring).
 *   uart_write(ctx, b, n)  queue up to n bytes for the XBee; return how many were taken (0..n). Non-blocking:
 *                          the core keeps the rest and offers it again at the next step.
 *   servo_write(ctx, fin, angle)
 *                          command fin 0 (right) or 1 (left) to angle [rad, float], already inside the configured
 *                          [angle_min, angle_max]; called at every tick (10 ms) for both fins; the port maps the
 *                          angle to its pulse width (its calibration, not the rules').
 *   random32(ctx)          a 32-bit value from a hardware random source (or a free-running timer sampled at an
 *                          unpredictable moment); called once at power-up for the boot id (0 is replaced by 1).
 *
 * ctx is the port's own pointer, handed back unchanged. All state of the rules lives in the caller-allocated
 * pfw_app (pfw.h); the core uses no dynamic memory and no libc beyond <stdint.h>, <stddef.h>, <string.h> and
 * <math.h> (single-precision float functions only).
 */
#ifndef PFW_HAL_H
#define PFW_HAL_H

#include <stddef.h>
#include <stdint.h>

typedef struct pfw_hal {
    void *ctx;
    uint32_t (*millis)(void *ctx);
    size_t (*uart_read)(void *ctx, uint8_t *buf, size_t max);
    size_t (*uart_write)(void *ctx, const uint8_t *buf, size_t len);
    void (*servo_write)(void *ctx, uint8_t fin, float angle_rad);
    uint32_t (*random32)(void *ctx);
} pfw_hal;

/* The main loop: pfw_app_init() once at power-up, then pfw_app_step() as often as the board can (at least every
 * millisecond or two; it reads the UART, ticks the rules every PFW_TICK_MS and writes the servos and the UART).
 * Declared in pfw.h with the pfw_app struct. */
#define PFW_TICK_MS 10u

#endif /* PFW_HAL_H */
