/* Host port: a flat interface over the core for tests and the emulator (hardware/radio/cfirmware.py, ctypes).
 * Built as build/libpfw_host.so by `make -C firmware host`. Plain arrays in and out: no struct layout to mirror. */
#include <string.h>

#include "pfw.h"

size_t pfw_host_size(void)
{
    return sizeof(pfw_fw);
}

/* limits: angle_min, angle_max [rad], period_min, period_max [ms], ratio_min, ratio_max, max_speed [rad/s],
 * max_rate[4]; ms: watchdog, max_lease. Returns pfw_init's result. */
int pfw_host_init(pfw_fw *fw, const float limits[11], const uint16_t ms[2], uint32_t boot, uint32_t power_up_ms)
{
    pfw_config cfg;
    unsigned j;
    cfg.angle_min = limits[0];
    cfg.angle_max = limits[1];
    cfg.period_min_ms = limits[2];
    cfg.period_max_ms = limits[3];
    cfg.ratio_min = limits[4];
    cfg.ratio_max = limits[5];
    cfg.max_speed = limits[6];
    for (j = 0; j < 4u; j++) {
        cfg.max_rate[j] = limits[7 + j];
    }
    cfg.watchdog_ms = ms[0];
    cfg.max_lease_ms = ms[1];
    return pfw_init(fw, &cfg, boot, power_up_ms);
}

void pfw_host_defaults(float limits[11], uint16_t ms[2])
{
    pfw_config cfg;
    unsigned j;
    pfw_config_default(&cfg);
    limits[0] = cfg.angle_min;
    limits[1] = cfg.angle_max;
    limits[2] = cfg.period_min_ms;
    limits[3] = cfg.period_max_ms;
    limits[4] = cfg.ratio_min;
    limits[5] = cfg.ratio_max;
    limits[6] = cfg.max_speed;
    for (j = 0; j < 4u; j++) {
        limits[7 + j] = cfg.max_rate[j];
    }
    ms[0] = cfg.watchdog_ms;
    ms[1] = cfg.max_lease_ms;
}

/* out[0..]: state, has_session, session, boot, status_seq, latch_seq, clipped, held_back0, held_back1,
 * has_command_id, command_id, power_up_ms, fins_ms, lease_end_ms, has_last_valid, last_valid_ms, n_retired;
 * then the counters duplicate, stale, retired, refused, copy, bad_lease, late, boot, foreign_stop, tracker_new,
 * tracker_duplicates, tracker_stale, tracker_lost, tx_dropped, events_dropped, rx_overflow; then the decoder's
 * frames, messages, skipped_bytes, framing_errors, truncated, checksum_errors, crc_errors, malformed,
 * other_frames. Returns the count written (at most max). */
size_t pfw_host_info(const pfw_fw *fw, uint32_t *out, size_t max)
{
    const pfw_counters *c = &fw->counters;
    const pfw_decoder *d = &fw->dec;
    uint32_t v[] = {fw->state, fw->has_session, fw->session, fw->boot, fw->status_seq, fw->latch_seq, fw->clipped,
                    fw->held_back[0], fw->held_back[1], fw->has_command_id, fw->command_id, fw->power_up_ms,
                    fw->fins_ms, fw->lease_end_ms, fw->has_last_valid, fw->last_valid_ms, fw->n_retired,
                    c->duplicate, c->stale, c->retired, c->refused, c->copy, c->bad_lease, c->late, c->boot,
                    c->foreign_stop, c->tracker_new, c->tracker_duplicates, c->tracker_stale, c->tracker_lost,
                    c->tx_dropped, c->events_dropped, c->rx_overflow,
                    d->frames, d->messages, d->skipped_bytes, d->framing_errors, d->truncated, d->checksum_errors,
                    d->crc_errors, d->malformed, d->other_frames};
    size_t n = sizeof v / sizeof v[0];
    if (n > max) {
        n = max;
    }
    memcpy(out, v, n * sizeof v[0]);
    return n;
}

/* out: from, to, duration [ms], elapsed [ms], power, pattern[4] (bias, amplitude [rad], period [ms], ratio),
 * angle [rad], pending[4], due, command[4], setpoint[4]. */
void pfw_host_fin(const pfw_fw *fw, unsigned fin, float out[23])
{
    const pfw_fin *f = &fw->fin[fin & 1u];
    unsigned j;
    out[0] = f->from;
    out[1] = f->to;
    out[2] = f->duration_ms;
    out[3] = pfw_fin_elapsed_ms(fw, fin & 1u);
    out[4] = (float)f->power;
    for (j = 0; j < 4u; j++) {
        out[5 + j] = f->pattern[j];
        out[10 + j] = f->pending[j];
        out[15 + j] = fw->command[fin & 1u][j];
        out[19 + j] = fw->setpoint[fin & 1u][j];
    }
    out[9] = pfw_fin_angle(fw, fin & 1u);
    out[14] = (float)f->due;
}

/* The oldest event: ints = kind, fin, power, still, ms; floats = frac [ms], turn, pattern[4], angles[2].
 * Returns 0 when there is none. */
int pfw_host_event(pfw_fw *fw, uint32_t ints[5], float floats[8])
{
    pfw_event ev;
    unsigned j;
    if (!pfw_event_take(fw, &ev)) {
        return 0;
    }
    ints[0] = ev.kind;
    ints[1] = ev.fin;
    ints[2] = ev.power;
    ints[3] = ev.still;
    ints[4] = ev.ms;
    floats[0] = ev.frac_ms;
    floats[1] = ev.turn;
    for (j = 0; j < 4u; j++) {
        floats[2 + j] = ev.pattern[j];
    }
    floats[6] = ev.angles[0];
    floats[7] = ev.angles[1];
    return 1;
}

/* Clip, slew and stretch one fin's pattern (period in ms), for tests of the limits alone. */
int pfw_host_clip(const pfw_fw *fw, float beat[4])
{
    return pfw_clip(&fw->cfg, beat);
}

void pfw_host_next(const pfw_fw *fw, float beat[4], const float ran[4], float duration_ms, int still, float turn,
                   int next_power)
{
    pfw_slew_at_latch(&fw->cfg, beat, ran, duration_ms, still);
    pfw_stretch_transition(&fw->cfg, beat, turn, next_power);
}
