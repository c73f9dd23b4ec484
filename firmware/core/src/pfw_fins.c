/* The fins: eq. 21 half-strokes latched at exact turning points (strokes.py, stepping.advance_one) and the
 * hand-over of finrules.apply_firmware / _hand_over / next_latch. */
#include <math.h>
#include <string.h>

#include "pfw.h"
#include "pfw_internal.h"

#define MAX_SEGMENTS 64u /* per advance: a moving half-stroke lasts >= 57 ms, so 64 cover > 1.8 s between calls */

void pfw_fin_rest(pfw_fin *fin, float angle)
{
    /* FinBeat.rest(angle) through strokes.init_fins: still at angle, finished, next stroke a power stroke */
    memset(fin, 0, sizeof *fin);
    fin->from = fin->to = angle;
    fin->duration_ms = 0.0f;
    fin->power = 0;
    fin->due = 1;
    fin->pattern[PFW_BIAS] = angle;
    fin->pattern[PFW_AMPLITUDE] = 0.0f;
    fin->pattern[PFW_PERIOD] = 1000.0f;
    fin->pattern[PFW_RATIO] = 1.0f;
    memcpy(fin->pending, fin->pattern, sizeof fin->pattern);
}

static int idle(const pfw_fin *fin)
{
    /* strokes.idle: still, and commanded to hold still at the same angle */
    return fin->from == fin->to && fin->pending[PFW_AMPLITUDE] == 0.0f && fin->pending[PFW_BIAS] == fin->to;
}

/* ms from the fin's start to time (base_ms + off_ms); off_ms small. */
static float since_start(const pfw_fin *fin, uint32_t base_ms, float off_ms)
{
    int32_t whole = (int32_t)(base_ms - fin->start_ms);
    if (whole > 600000) {
        whole = 600000; /* a fin idle for minutes: only "long ago" matters */
    }
    return ((float)whole - fin->start_frac_ms) + off_ms;
}

float pfw_fin_elapsed_ms(const pfw_fw *fw, unsigned fin)
{
    const pfw_fin *f = &fw->fin[fin & 1u];
    if (f->due) {
        return f->duration_ms;
    }
    return fminf(since_start(f, fw->fins_ms, 0.0f), f->duration_ms);
}

float pfw_fin_angle(const pfw_fw *fw, unsigned fin)
{
    const pfw_fin *f = &fw->fin[fin & 1u];
    float mid, half, rate;
    if (f->duration_ms <= 0.0f || f->due || f->from == f->to) {
        return f->to;
    }
    mid = 0.5f * (f->from + f->to);
    half = 0.5f * (f->to - f->from);
    rate = PFW_PI / f->duration_ms;
    return mid - half * cosf(rate * pfw_fin_elapsed_ms(fw, fin));
}

static void push_event(pfw_fw *fw, const pfw_event *ev)
{
    unsigned slot;
    if (fw->ev_count == PFW_EVENT_CAPACITY) {
        fw->ev_head = (uint8_t)((fw->ev_head + 1u) % PFW_EVENT_CAPACITY);
        fw->ev_count--;
        fw->counters.events_dropped++;
    }
    slot = (fw->ev_head + fw->ev_count) % PFW_EVENT_CAPACITY;
    fw->events[slot] = *ev;
    fw->ev_count++;
}

int pfw_event_take(pfw_fw *fw, pfw_event *ev)
{
    if (fw->ev_count == 0u) {
        return 0;
    }
    *ev = fw->events[fw->ev_head];
    fw->ev_head = (uint8_t)((fw->ev_head + 1u) % PFW_EVENT_CAPACITY);
    fw->ev_count--;
    return 1;
}

/* strokes.latch: start the next half-stroke of fin f at time base_ms + off_ms with its pending pattern. */
static void latch(pfw_fw *fw, unsigned f, uint32_t base_ms, float off_ms)
{
    pfw_fin *fin = &fw->fin[f];
    const float *p = fin->pending;
    float whole = floorf(off_ms);
    pfw_event ev;
    fin->power = (uint8_t)!fin->power;
    fin->from = fin->to;
    if (fin->power) {
        fin->to = p[PFW_BIAS] + p[PFW_AMPLITUDE];
        fin->duration_ms = p[PFW_PERIOD] / (p[PFW_RATIO] + 1.0f); /* eq. 21, power stroke */
    } else {
        fin->to = p[PFW_BIAS] - p[PFW_AMPLITUDE];
        fin->duration_ms = p[PFW_RATIO] * p[PFW_PERIOD] / (p[PFW_RATIO] + 1.0f); /* recovery */
    }
    memcpy(fin->pattern, p, sizeof fin->pattern);
    fin->start_ms = base_ms + (uint32_t)(int32_t)whole;
    fin->start_frac_ms = off_ms - whole;
    fin->due = 0;
    memset(&ev, 0, sizeof ev);
    ev.kind = PFW_EVENT_LATCH;
    ev.fin = (uint8_t)f;
    ev.power = fin->power;
    ev.still = fin->from == fin->to;
    ev.ms = fin->start_ms;
    ev.frac_ms = fin->start_frac_ms;
    ev.turn = fin->from;
    memcpy(ev.pattern, fin->pattern, sizeof ev.pattern);
    push_event(fw, &ev);
    pfw_latch_report(fw, f, fin->start_ms, fin->start_frac_ms);
}

static void shift_start(pfw_fin *fin, float by_ms)
{
    float frac = fin->start_frac_ms + fminf(by_ms, 1e9f), whole = floorf(frac);
    fin->start_ms += (uint32_t)(int32_t)whole;
    fin->start_frac_ms = frac - whole;
}

void pfw_advance(pfw_fw *fw, uint32_t now_ms)
{
    uint32_t base = fw->fins_ms;
    int32_t span = (int32_t)(now_ms - base);
    float t_left, off = 0.0f, rem[2], seg;
    unsigned f, n;
    int idl[2];
    if (!fw->fins_started || span < 0) {
        fw->fins_started = 1; /* the fins' time starts at the first call (power_up_ms may lie in the past) */
        fw->fins_ms = now_ms;
        return;
    }
    if (span == 0) {
        return;
    }
    if (span > 0x40000000) {
        span = 0x40000000; /* calls 12 days apart: the fins are idle anyway; keeps every float -> int exact */
    }
    t_left = (float)span;
    for (n = 0; n < MAX_SEGMENTS && t_left > 0.0f; n++) {
        for (f = 0; f < 2u; f++) {
            idl[f] = idle(&fw->fin[f]);
        }
        for (f = 0; f < 2u; f++) {
            if (!idl[f] && fw->fin[f].due) {
                latch(fw, f, base, off);
            }
        }
        seg = t_left;
        for (f = 0; f < 2u; f++) {
            rem[f] = idl[f] ? INFINITY : fw->fin[f].duration_ms - since_start(&fw->fin[f], base, off);
            seg = fminf(seg, rem[f]);
        }
        seg = fmaxf(seg, 0.0f);
        for (f = 0; f < 2u; f++) {
            if (!idl[f] && rem[f] - seg <= PFW_TIE_MS) {
                fw->fin[f].due = 1; /* exactly on the turning point: latch at the next segment's start */
            }
        }
        for (f = 0; f < 2u; f++) {
            if (idl[f]) {
                shift_start(&fw->fin[f], seg); /* an idle fin's stroke clock stands still (advance_one) */
            }
        }
        off += seg;
        t_left -= seg;
        if (t_left <= PFW_TIE_MS) {
            break; /* stepping.advance_one's tie: what ends here latches at the next advance */
        }
    }
    fw->fins_ms = now_ms;
}

static void next_latch(const pfw_fw *fw, unsigned f, float out[4])
{
    const pfw_fin *fin = &fw->fin[f];
    int still = fin->from == fin->to;
    int next_power = still || fin->power == 0u;
    memcpy(out, fw->setpoint[f], 4u * sizeof(float));
    pfw_slew_at_latch(&fw->cfg, out, fin->pattern, fin->duration_ms, still);
    pfw_stretch_transition(&fw->cfg, out, fin->to, next_power);
}

void pfw_apply(pfw_fw *fw)
{
    unsigned f, j;
    float safe[2][4];
    int changed[2];
    pfw_event ev;
    if (fw->halt) {
        memset(&ev, 0, sizeof ev);
        ev.kind = PFW_EVENT_HALT;
        ev.ms = fw->fins_ms;
        for (f = 0; f < 2u; f++) {
            ev.angles[f] = pfw_fin_angle(fw, f);
        }
        for (f = 0; f < 2u; f++) {
            pfw_fin_rest(&fw->fin[f], ev.angles[f]);
            fw->fin[f].start_ms = fw->fins_ms;
        }
        push_event(fw, &ev);
        fw->halt = 0;
        fw->handed_valid = 0; /* a restart hands the fins their patterns */
        return;
    }
    if (fw->state != PFW_RUNNING) {
        return;
    }
    for (f = 0; f < 2u; f++) {
        next_latch(fw, f, safe[f]);
    }
    if (!fw->handed_valid || fw->has_command_id != fw->has_handed_id ||
        (fw->has_command_id && fw->command_id != fw->handed_id)) {
        changed[0] = changed[1] = 1;
    } else {
        for (f = 0; f < 2u; f++) {
            changed[f] = 0;
            for (j = 0; j < 4u; j++) {
                if (safe[f][j] != fw->handed[f][j]) {
                    changed[f] = 1;
                }
            }
        }
    }
    if (!changed[0] && !changed[1]) {
        return;
    }
    for (f = 0; f < 2u; f++) {
        if (!changed[f]) {
            continue; /* handed its own pattern again a fin is untouched (its phase kept) */
        }
        memcpy(fw->fin[f].pending, safe[f], sizeof safe[f]);
#ifdef PFW_BROKEN_LATCH_MIDSTROKE
        fw->fin[f].to = pfw_fin_angle(fw, f); /* broken on purpose: the new pattern starts here, mid-stroke */
        fw->fin[f].due = 1;
#endif
        if (fw->fin[f].from == fw->fin[f].to) {
            fw->fin[f].due = 1; /* strokes.command_one: a still fin latches at once, a power stroke next */
            fw->fin[f].power = 0;
        }
    }
    memcpy(fw->handed, safe, sizeof safe);
    fw->has_handed_id = fw->has_command_id;
    fw->handed_id = fw->command_id;
    fw->handed_valid = 1;
}
