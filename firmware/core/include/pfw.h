/*
 * pfw.h - the robot's rules (docs/protocol.md section 5) as a portable C99 core.
 *
 * The specification is the Python reference hardware/radio/firmware.py (Firmware) with the fin rules of
 * pectoral_gym/model/servo.py (clip_beats) and finrules.py (slew_at_latch, stretch_transition), the fins of
 * pectoral_gym/model/strokes.py and stepping.advance_one, driven as finrules.py (apply_firmware, _hand_over)
 * and the emulator do; tests/test_firmware_differential.py
 * checks the two agree. All state lives in one caller-allocated pfw_fw; no dynamic memory; every call is bounded.
 *
 * Time: the caller's clock is a u32 millisecond count (wrapping); absolute times are kept as integer ms, and only
 * offsets inside a half-stroke as float. Angles [rad], periods [ms] (the wire unit), ratios [-], as float.
 *
 * Driving (what the emulator does with the reference):
 *   pfw_init(fw, cfg, boot, power_up_ms)     power-up: fins at rest at 90 deg, state IDLE, uptime 0 at clock
 *                                            power_up_ms; the fins' time starts at the first call
 *   pfw_receive(fw, bytes, n, now_ms)        bytes from the XBee: the fins run to now, every message completed by
 *                                            the bytes is handled (STATUS replies queued), then the fins are handed
 *                                            what to run (once per call, as the emulator does once per read)
 *   pfw_tick(fw, now_ms)                     every 10 ms: the fins run to now, lease and watchdog, hand-over
 *   pfw_tx_take(fw, out, max)                the 0x10 frames the robot sends (STATUS replies, LATCH reports)
 */
#ifndef PFW_H
#define PFW_H

#include <stddef.h>
#include <stdint.h>

#include "pfw_hal.h"

#ifdef __cplusplus
extern "C" {
#endif

/* ---------------------------------------------------------------- sizes (a port may override them) */
#ifndef PFW_TX_CAPACITY
#define PFW_TX_CAPACITY 1024u /* bytes of escaped frames waiting for the UART; a frame that does not fit is dropped */
#endif
#ifndef PFW_RX_BATCH
#define PFW_RX_BATCH 8u /* messages handled per batch (pfw_receive handles a longer read in several batches) */
#endif
#ifndef PFW_EVENT_CAPACITY
#define PFW_EVENT_CAPACITY 16u /* latch/halt events kept for pfw_event_take (oldest dropped when full) */
#endif
#define PFW_RETIRED 16u        /* sessions remembered as retired */
#define PFW_MAX_FRAME_DATA 255u
#define PFW_PROTOCOL_VERSION 3u

/* ---------------------------------------------------------------- defaults: must equal the Python ServoLimits and
 * FirmwareConfig (tests/test_firmware_differential.py checks them); the binding always passes the Python values. */
#define PFW_DEFAULT_ANGLE_MIN 0.17453292519943295f /* radians(10) */
#define PFW_DEFAULT_ANGLE_MAX 2.9670597283903604f  /* radians(170) */
#define PFW_DEFAULT_PERIOD_MIN_MS 400.0f
#define PFW_DEFAULT_PERIOD_MAX_MS 4000.0f
#define PFW_DEFAULT_RATIO_MIN 0.5f
#define PFW_DEFAULT_RATIO_MAX 6.0f
#define PFW_DEFAULT_MAX_SPEED 13.0f               /* rad/s, ROBOT_MAX_FIN_RATE */
#define PFW_DEFAULT_MAX_RATE_BIAS 3.141592653589793f /* rad/s, radians(180) */
#define PFW_DEFAULT_MAX_RATE_AMPLITUDE 3.141592653589793f
#define PFW_DEFAULT_MAX_RATE_PERIOD 4.0f          /* s/s */
#define PFW_DEFAULT_MAX_RATE_RATIO 10.0f          /* 1/s */
#define PFW_DEFAULT_WATCHDOG_MS 500u
#define PFW_DEFAULT_MAX_LEASE_MS 1000u

enum { PFW_IDLE = 0, PFW_RUNNING = 1, PFW_STOPPED = 2, PFW_WATCHDOG = 3, PFW_EXPIRED = 4 };
enum { PFW_SET_FINS = 0x01, PFW_STOP = 0x02, PFW_HEARTBEAT = 0x03, PFW_CLAIM = 0x04, PFW_STATUS = 0x81,
       PFW_LATCH = 0x82 };
enum { PFW_FLAG_CLIPPED = 0x01, PFW_FLAG_RATE_LIMITED = 0x02 };
enum { PFW_BIAS = 0, PFW_AMPLITUDE = 1, PFW_PERIOD = 2, PFW_RATIO = 3 };
enum { PFW_EVENT_LATCH = 1, PFW_EVENT_HALT = 2 };

typedef struct pfw_config {
    float angle_min, angle_max;         /* rad */
    float period_min_ms, period_max_ms; /* ms */
    float ratio_min, ratio_max;         /* - */
    float max_speed;                    /* rad/s: peak |g'| of every half-stroke, eq. 21 */
    float max_rate[4];                  /* per second: bias [rad/s], amplitude [rad/s], period [s/s], ratio [1/s] */
    uint16_t watchdog_ms;               /* (0, 1000] */
    uint16_t max_lease_ms;              /* (0, 1000] */
} pfw_config;

/* One fin: its half-stroke in progress (strokes.py) and the pattern commanded for its next turning point. */
typedef struct pfw_fin {
    float from, to;       /* rad: angle at the start and at the end (turning points) */
    float duration_ms;    /* ms, 0: finished */
    uint32_t start_ms;    /* clock ms of the start ... */
    float start_frac_ms;  /* ... plus this fraction [0, 1) ms */
    uint8_t power;        /* 1 power stroke, 0 recovery */
    uint8_t due;          /* the half-stroke is over (elapsed = duration): latch at the next advance */
    float pattern[4];     /* the pattern it runs: bias, amplitude [rad], period [ms], ratio */
    float pending[4];     /* the pattern it latches at its next turning point */
} pfw_fin;

typedef struct pfw_event {
    uint8_t kind;         /* PFW_EVENT_LATCH or PFW_EVENT_HALT */
    uint8_t fin;          /* latch: the fin */
    uint8_t power;        /* latch: a power stroke starts */
    uint8_t still;        /* latch: the half-stroke ends where it starts (a still fin's; no LATCH report) */
    uint32_t ms;          /* clock ms of the event ... */
    float frac_ms;        /* ... plus this fraction [0, 1) ms */
    float turn;           /* latch: angle where the half-stroke starts [rad] */
    float pattern[4];     /* latch: pattern it runs (bias, amplitude [rad], period [ms], ratio) */
    float angles[2];      /* halt: the angles both fins hold [rad] */
} pfw_event;

typedef struct pfw_decoder { /* XBee API-2 stream decoder; counters as protocol.StreamDecoder's */
    uint8_t buf[PFW_MAX_FRAME_DATA + 3];
    uint16_t len;
    uint8_t in_frame, escaped;
    uint32_t frames, messages, skipped_bytes, framing_errors, truncated, checksum_errors, crc_errors, malformed,
        other_frames;
} pfw_decoder;

typedef struct pfw_msg { /* a decoded message (PC -> robot kinds, plus the robot's own, which are ignored) */
    uint8_t type;
    uint32_t session;
    uint16_t seq;
    uint16_t fins[8];     /* SET_FINS wire words */
    uint16_t command, lease_ms;
    uint32_t deadline, boot;
    uint64_t src64;       /* sender's XBee address (broadcast for a frame that carries none) */
} pfw_msg;

typedef struct pfw_counters { /* Firmware.ignored, plus the sequence tracker's */
    uint32_t duplicate, stale, retired, refused, copy, bad_lease, late, boot, foreign_stop;
    uint32_t tracker_new, tracker_duplicates, tracker_stale, tracker_lost;
    uint32_t tx_dropped, events_dropped, rx_overflow;
} pfw_counters;

typedef struct pfw_fw {
    pfw_config cfg;
    uint32_t boot, power_up_ms;
    uint8_t state, halt, clipped, held_back[2];
    uint8_t has_session, has_command_id, has_last_valid, has_tracker_last, has_handed_id, handed_valid;
    uint32_t session;
    uint64_t session_addr;  /* the served session's last address: LATCH reports go there */
    uint32_t retired[PFW_RETIRED];
    uint8_t n_retired, retired_next;
    uint16_t command_id, tracker_last, status_seq, latch_seq, handed_id;
    uint32_t lease_end_ms, last_valid_ms, tripped_ms;
    float command[2][4], setpoint[2][4], handed[2][4];
    pfw_fin fin[2];
    uint32_t fins_ms;       /* the fins' time (clock ms) */
    uint8_t fins_started;   /* fins_ms is set (at the first call after pfw_init) */
    pfw_counters counters;
    pfw_decoder dec;
    pfw_msg batch[PFW_RX_BATCH];
    uint8_t n_batch;
    uint8_t tx[PFW_TX_CAPACITY];
    size_t tx_len;
    pfw_event events[PFW_EVENT_CAPACITY];
    uint8_t ev_head, ev_count;
} pfw_fw;

/* ---------------------------------------------------------------- the rules */
void pfw_config_default(pfw_config *cfg);
/* 0 on success; -1 for a config outside the rules' ranges (fw untouched) or a zero boot id. */
int pfw_init(pfw_fw *fw, const pfw_config *cfg, uint32_t boot, uint32_t power_up_ms);
void pfw_receive(pfw_fw *fw, const uint8_t *data, size_t len, uint32_t now_ms);
void pfw_tick(pfw_fw *fw, uint32_t now_ms);
size_t pfw_tx_take(pfw_fw *fw, uint8_t *out, size_t max);
/* The oldest event into *ev (1) or nothing left (0). */
int pfw_event_take(pfw_fw *fw, pfw_event *ev);
/* Fin angle [rad] at the fins' time (the last call's now). */
float pfw_fin_angle(const pfw_fw *fw, unsigned fin);
/* Time into fin's half-stroke [ms] at the fins' time. */
float pfw_fin_elapsed_ms(const pfw_fw *fw, unsigned fin);
uint32_t pfw_uptime_ms(const pfw_fw *fw, uint32_t now_ms);

/* ---------------------------------------------------------------- the servo limits (firmware.py's functions) */
int pfw_clip(const pfw_config *cfg, float beat[4]);  /* clip_beats of one fin; returns whether it changed */
void pfw_slew_at_latch(const pfw_config *cfg, float beat[4], const float ran[4], float duration_ms, int still);
void pfw_stretch_transition(const pfw_config *cfg, float beat[4], float turn, int next_power);

/* ---------------------------------------------------------------- wire */
uint16_t pfw_crc16(const uint8_t *data, size_t len);
void pfw_decoder_init(pfw_decoder *dec);
/* Feed one byte; returns 1 and fills *msg when it completes a valid message. */
int pfw_decoder_feed(pfw_decoder *dec, uint8_t byte, pfw_msg *msg);
/* Escape frame data into an API-2 frame: returns its length, or 0 if it does not fit in out_max. */
size_t pfw_frame_encode(const uint8_t *frame_data, size_t len, uint8_t *out, size_t out_max);

/* ---------------------------------------------------------------- the board's main loop (HAL only) */
typedef struct pfw_app {
    pfw_fw fw;
    pfw_hal hal;
    uint32_t last_tick_ms;
    uint8_t out[64];
    size_t out_len, out_pos;
} pfw_app;

/* Power-up: boot id from hal->random32, uptime from hal->millis(); 0, or -1 for a bad config. */
int pfw_app_init(pfw_app *app, const pfw_hal *hal, const pfw_config *cfg);
/* One pass of the main loop: UART in, a tick when PFW_TICK_MS have passed, servos, UART out. Bounded. */
void pfw_app_step(pfw_app *app);

#ifdef __cplusplus
}
#endif
#endif /* PFW_H */
