/* The rules of docs/protocol.md section 5 (firmware.py's Firmware): sessions, sequence numbers, lease and
 * deadline, watchdog, STOP, STATUS replies and LATCH reports. */
#include <string.h>

#include "pfw.h"
#include "pfw_internal.h"

void pfw_config_default(pfw_config *cfg)
{
    cfg->angle_min = PFW_DEFAULT_ANGLE_MIN;
    cfg->angle_max = PFW_DEFAULT_ANGLE_MAX;
    cfg->period_min_ms = PFW_DEFAULT_PERIOD_MIN_MS;
    cfg->period_max_ms = PFW_DEFAULT_PERIOD_MAX_MS;
    cfg->ratio_min = PFW_DEFAULT_RATIO_MIN;
    cfg->ratio_max = PFW_DEFAULT_RATIO_MAX;
    cfg->max_speed = PFW_DEFAULT_MAX_SPEED;
    cfg->max_rate[0] = PFW_DEFAULT_MAX_RATE_BIAS;
    cfg->max_rate[1] = PFW_DEFAULT_MAX_RATE_AMPLITUDE;
    cfg->max_rate[2] = PFW_DEFAULT_MAX_RATE_PERIOD;
    cfg->max_rate[3] = PFW_DEFAULT_MAX_RATE_RATIO;
    cfg->watchdog_ms = PFW_DEFAULT_WATCHDOG_MS;
    cfg->max_lease_ms = PFW_DEFAULT_MAX_LEASE_MS;
}

static int config_ok(const pfw_config *c)
{
    unsigned j;
    for (j = 0; j < 4u; j++) {
        if (!(c->max_rate[j] > 0.0f)) {
            return 0;
        }
    }
    return c->angle_min >= 0.0f && c->angle_min < c->angle_max && c->angle_max <= 3.1416f &&
           c->period_min_ms > 0.0f && c->period_min_ms <= c->period_max_ms && c->ratio_min > 0.0f &&
           c->ratio_min <= c->ratio_max && c->max_speed > 0.0f && c->watchdog_ms > 0u && c->watchdog_ms <= 1000u &&
           c->max_lease_ms > 0u && c->max_lease_ms <= 1000u;
}

int pfw_init(pfw_fw *fw, const pfw_config *cfg, uint32_t boot, uint32_t power_up_ms)
{
    unsigned f;
    if (!config_ok(cfg) || boot == 0u) {
        return -1;
    }
    memset(fw, 0, sizeof *fw);
    fw->cfg = *cfg;
    fw->boot = boot;
    fw->power_up_ms = power_up_ms;
    fw->fins_ms = power_up_ms;
    fw->state = PFW_IDLE;
    for (f = 0; f < 2u; f++) {
        pfw_fin_rest(&fw->fin[f], 0.5f * PFW_PI); /* rest_beats: 90 deg */
        fw->fin[f].start_ms = power_up_ms;
        memcpy(fw->command[f], fw->fin[f].pattern, sizeof fw->command[f]);
        memcpy(fw->setpoint[f], fw->fin[f].pattern, sizeof fw->setpoint[f]);
    }
    pfw_decoder_init(&fw->dec);
    return 0;
}

uint32_t pfw_uptime_ms(const pfw_fw *fw, uint32_t now_ms)
{
    return now_ms - fw->power_up_ms;
}

static int running(const pfw_fw *fw)
{
    return fw->state == PFW_RUNNING;
}

static void stop(pfw_fw *fw, uint8_t state)
{
    if (running(fw)) {
        fw->halt = 1;
    }
    fw->state = state;
}

/* ---------------------------------------------------------------- messages */
static int serial_newer16(uint16_t a, uint16_t b)
{
    uint16_t d = (uint16_t)(a - b);
    return d != 0u && d < 0x8000u;
}

static int elapsed_at_least(uint32_t now_ms, uint32_t then_ms, uint32_t span_ms)
{
    return (int32_t)(now_ms - then_ms) >= (int32_t)span_ms;
}

static int admit(pfw_fw *fw, const pfw_msg *msg, uint32_t now_ms)
{
    unsigned i;
    int silent;
    for (i = 0; i < fw->n_retired; i++) {
        if (fw->retired[i] == msg->session) {
            fw->counters.retired++;
            return 0;
        }
    }
    silent = !fw->has_last_valid || elapsed_at_least(now_ms, fw->last_valid_ms, fw->cfg.watchdog_ms);
    if (fw->has_session && !silent && msg->type != PFW_CLAIM) {
        fw->counters.refused++; /* the served session is live: taking over needs a CLAIM */
        return 0;
    }
    if (fw->has_session) {
        fw->retired[fw->retired_next] = fw->session;
        fw->retired_next = (uint8_t)((fw->retired_next + 1u) % PFW_RETIRED);
        if (fw->n_retired < PFW_RETIRED) {
            fw->n_retired++;
        }
        if (running(fw)) {
            stop(fw, PFW_STOPPED); /* the new controller must command anew */
        }
    }
    fw->has_session = 1;
    fw->session = msg->session;
    fw->has_command_id = 0;
    fw->has_last_valid = 0;
    fw->has_tracker_last = 0; /* a fresh SequenceTracker, counters included */
    fw->counters.tracker_new = fw->counters.tracker_duplicates = 0;
    fw->counters.tracker_stale = fw->counters.tracker_lost = 0;
    return 1;
}

static void set_fins(pfw_fw *fw, const pfw_msg *msg, uint32_t now_ms)
{
    int32_t end, ahead;
    unsigned f, j;
    int clipped = 0;
    if (msg->lease_ms == 0u || msg->lease_ms > fw->cfg.max_lease_ms) {
        fw->counters.bad_lease++;
        return;
    }
    if (fw->has_command_id && !serial_newer16(msg->command, fw->command_id)) {
        fw->counters.copy++; /* a copy (or an older command): it neither extends nor restarts */
        return;
    }
    fw->has_command_id = 1;
    fw->command_id = msg->command;
    end = (int32_t)msg->lease_ms; /* ms after now: counted from our own receipt of the first copy */
    if (msg->deadline != 0u) {
        if (msg->boot != fw->boot) {
            fw->counters.boot++; /* a deadline on another power-up's clock: meaningless here */
            return;
        }
        ahead = (int32_t)(msg->deadline - pfw_uptime_ms(fw, now_ms)); /* u32 wrap-safe */
        if (ahead < end) {
            end = ahead;
        }
    }
#ifdef PFW_BROKEN_IGNORE_LEASE
    end = 0x7FFFFFFF; /* broken on purpose: the lease and the deadline never end a command */
#endif
    if (end <= 0) {
        fw->counters.late++; /* this command's time is over: never start it, stop the previous one */
        if (running(fw)) {
            stop(fw, PFW_EXPIRED);
            fw->tripped_ms = now_ms;
        }
        return;
    }
    fw->lease_end_ms = now_ms + (uint32_t)end;
    for (f = 0; f < 2u; f++) {
        for (j = 0; j < 4u; j++) {
            uint16_t w = msg->fins[4u * f + j];
            fw->command[f][j] = j == PFW_PERIOD ? (float)w : (float)w / 1000.0f;
        }
        clipped |= pfw_clip(&fw->cfg, fw->command[f]);
    }
    fw->clipped = (uint8_t)clipped;
    if (!running(fw)) {
        fw->state = PFW_RUNNING;
    }
}

/* Firmware.receive: act on msg, queue the STATUS that answers it (if any). */
static void handle(pfw_fw *fw, const pfw_msg *msg, uint32_t now_ms)
{
    uint16_t d;
    if (msg->type == PFW_STATUS || msg->type == PFW_LATCH) {
        return; /* the robot's own kinds: not for us */
    }
    if (!fw->has_session || msg->session != fw->session) {
        if (!admit(fw, msg, now_ms)) {
            if (msg->type == PFW_STOP) { /* a stop never needs authority */
#ifdef PFW_BROKEN_IGNORE_RETIRED_STOP
                int i, retired = 0;
                for (i = 0; i < (int)fw->n_retired; i++) {
                    retired |= fw->retired[i] == msg->session;
                }
                if (!retired) {
                    fw->counters.foreign_stop++;
                    stop(fw, PFW_STOPPED);
                }
#else
                fw->counters.foreign_stop++;
                stop(fw, PFW_STOPPED);
#endif
            }
            pfw_status(fw, msg, now_ms); /* refused, but answered: the sender learns whom the robot serves */
            return;
        }
    }
    /* SequenceTracker.check */
    if (!fw->has_tracker_last) {
        fw->has_tracker_last = 1;
        fw->tracker_last = msg->seq;
        fw->counters.tracker_new++;
    } else {
        d = (uint16_t)(msg->seq - fw->tracker_last);
        if (d == 0u) {
            fw->counters.tracker_duplicates++;
            fw->counters.duplicate++; /* acknowledged, nothing else: no liveness from a repeat */
            pfw_status(fw, msg, now_ms);
            return;
        }
        if (d >= 0x8000u) {
            fw->counters.tracker_stale++;
            fw->counters.stale++;
            return;
        }
        fw->counters.tracker_lost += (uint32_t)d - 1u;
        fw->tracker_last = msg->seq;
        fw->counters.tracker_new++;
    }
    fw->session_addr = msg->src64; /* LATCH reports go where the served session's last new message came from */
    fw->has_last_valid = 1;
    fw->last_valid_ms = now_ms;
    if (msg->type == PFW_STOP) {
        stop(fw, PFW_STOPPED);
    } else if (msg->type == PFW_SET_FINS) {
        set_fins(fw, msg, now_ms);
    }
    pfw_status(fw, msg, now_ms);
}

static void handle_batch(pfw_fw *fw, uint32_t now_ms)
{
    unsigned i;
    for (i = 0; i < fw->n_batch; i++) {
        handle(fw, &fw->batch[i], now_ms);
    }
    fw->n_batch = 0;
}

void pfw_receive(pfw_fw *fw, const uint8_t *data, size_t len, uint32_t now_ms)
{
    size_t i;
    pfw_advance(fw, now_ms); /* the fins at the time the firmware hears the bytes */
    for (i = 0; i < len; i++) {
        if (pfw_decoder_feed(&fw->dec, data[i], &fw->batch[fw->n_batch])) {
            fw->n_batch++;
            if (fw->n_batch == PFW_RX_BATCH) {
                fw->counters.rx_overflow++;
                handle_batch(fw, now_ms);
            }
        }
    }
    /* as the emulator: decode the read, then handle its messages (the CRC count of the whole read in each STATUS) */
    handle_batch(fw, now_ms);
    pfw_apply(fw);
}

void pfw_tick(pfw_fw *fw, uint32_t now_ms)
{
    unsigned f;
    pfw_advance(fw, now_ms);
    if (running(fw) && (int32_t)(now_ms - fw->lease_end_ms) >= 0) {
        stop(fw, PFW_EXPIRED);
        fw->tripped_ms = now_ms;
    }
    if (running(fw) && fw->has_last_valid && (int32_t)(now_ms - fw->last_valid_ms) > (int32_t)fw->cfg.watchdog_ms) {
        stop(fw, PFW_WATCHDOG);
        fw->tripped_ms = now_ms;
    }
    if (running(fw)) {
        memcpy(fw->setpoint, fw->command, sizeof fw->command); /* rate-limited where the fins latch it */
    } else {
        for (f = 0; f < 2u; f++) {
            float angle = pfw_fin_angle(fw, f);
            fw->setpoint[f][PFW_BIAS] = angle; /* rest_beats(fin_angles) */
            fw->setpoint[f][PFW_AMPLITUDE] = 0.0f;
            fw->setpoint[f][PFW_PERIOD] = 1000.0f;
            fw->setpoint[f][PFW_RATIO] = 1.0f;
        }
    }
    pfw_apply(fw);
}
