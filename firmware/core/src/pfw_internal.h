/* Internal helpers shared by the core's files (not part of the public API). */
#ifndef PFW_INTERNAL_H
#define PFW_INTERNAL_H

#include <stdint.h>

#include "pfw.h"

#define PFW_PI 3.14159265358979f

/* Turning points within this of an advance's end latch at the start of the next one (stepping.advance_one's
 * 1e-12 s tie, widened to the float32 error of a turning-point time: a few ulps of a 3.4 s duration in ms). */
#define PFW_TIE_MS 1e-3f
/* A time within this below a whole ms counts as that ms (firmware.py's uptime_ms guard, 1 us). */
#define PFW_MS_GUARD 1e-3f

/* Round half to even (Python's round()) of 0 <= x < 2^22, exactly. */
float pfw_round_even(float x);
void pfw_advance(pfw_fw *fw, uint32_t now_ms);
void pfw_apply(pfw_fw *fw);
void pfw_fin_rest(pfw_fin *fin, float angle);
/* Queue the STATUS answering ack (pfw_output.c). */
void pfw_status(pfw_fw *fw, const pfw_msg *ack, uint32_t now_ms);
/* The LATCH report of fin's latch at clock ms + frac (sent while running, for half-strokes that move). */
void pfw_latch_report(pfw_fw *fw, unsigned fin, uint32_t ms, float frac);

#endif
