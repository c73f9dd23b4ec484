/* Servo limits: clip_beats, slew_at_latch, stretch_transition (firmware.py), one fin's pattern at a time.
 * Patterns are (bias [rad], amplitude [rad], period [ms], ratio [-]). */
#include <math.h>

#include "pfw.h"
#include "pfw_internal.h"

static float clampf(float x, float lo, float hi)
{
    /* np.clip: min(max(x, lo), hi) */
    return fminf(fmaxf(x, lo), hi);
}

float pfw_round_even(float x)
{
    float r = floorf(x + 0.5f); /* exact for x < 2^22: 0.5 is a multiple of x's ulp */
    if (r - x == 0.5f && fmodf(r, 2.0f) != 0.0f) {
        r -= 1.0f;
    }
    return r;
}

int pfw_clip(const pfw_config *cfg, float beat[4])
{
    float in[4], half_range, slow;
    unsigned j;
    int changed = 0;
    for (j = 0; j < 4u; j++) {
        in[j] = beat[j];
    }
    half_range = 0.5f * (cfg->angle_max - cfg->angle_min);
    beat[PFW_AMPLITUDE] = clampf(beat[PFW_AMPLITUDE], 0.0f, half_range);
    beat[PFW_BIAS] = clampf(beat[PFW_BIAS], cfg->angle_min + beat[PFW_AMPLITUDE],
                            cfg->angle_max - beat[PFW_AMPLITUDE]);
    beat[PFW_PERIOD] = clampf(beat[PFW_PERIOD], cfg->period_min_ms, cfg->period_max_ms);
    beat[PFW_RATIO] = clampf(beat[PFW_RATIO], cfg->ratio_min, cfg->ratio_max);
    /* servo_period: the faster half-stroke peaks at pi A (zeta + 1) / (T_p min(1, zeta)), eq. 21 */
    slow = PFW_PI * beat[PFW_AMPLITUDE] * (beat[PFW_RATIO] + 1.0f) /
           (cfg->max_speed * fminf(1.0f, beat[PFW_RATIO])) * 1000.0f;
    beat[PFW_PERIOD] = fmaxf(beat[PFW_PERIOD], slow);
    for (j = 0; j < 4u; j++) {
        /* clip_beats' 1e-12 in SI units; the period is in ms */
        if (fabsf(beat[j] - in[j]) > (j == PFW_PERIOD ? 1e-9f : 1e-12f)) {
            changed = 1;
        }
    }
    return changed;
}

void pfw_slew_at_latch(const pfw_config *cfg, float beat[4], const float ran[4], float duration_ms, int still)
{
    unsigned j;
    float d_s = fmaxf(duration_ms, 0.0f) * 0.001f, step, diff;
    if (!still) {
        for (j = 0; j < 4u; j++) {
            /* the period moves in ms: max_rate [s/s] times the duration in ms */
            step = j == PFW_PERIOD ? cfg->max_rate[j] * fmaxf(duration_ms, 0.0f) : cfg->max_rate[j] * d_s;
            diff = beat[j] - ran[j];
            if (!(fabsf(diff) <= step)) { /* within reach: the command itself, bit for bit */
                beat[j] = ran[j] + clampf(diff, -step, step);
            }
        }
    }
    (void)pfw_clip(cfg, beat);
}

void pfw_stretch_transition(const pfw_config *cfg, float beat[4], float turn, int next_power)
{
    float to = next_power ? beat[PFW_BIAS] + beat[PFW_AMPLITUDE] : beat[PFW_BIAS] - beat[PFW_AMPLITUDE];
    float share = (next_power ? 1.0f : beat[PFW_RATIO]) / (beat[PFW_RATIO] + 1.0f);
    float need = PFW_PI * fabsf(to - turn) / (2.0f * cfg->max_speed * share) * 1000.0f;
    beat[PFW_PERIOD] = fminf(fmaxf(beat[PFW_PERIOD], need), cfg->period_max_ms);
}
