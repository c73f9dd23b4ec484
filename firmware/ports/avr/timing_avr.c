/*
 * timing_avr.c - the worst-case step of the firmware, constructed and measured on the ATmega2560 in simavr.
 *
 * The real main loop (pfw_app_step over the HAL) runs with a scripted clock and a scripted XBee: the clock
 * advances 1 ms per step, and SET_FINS commands (both fins the same large pattern, a newer command identity each
 * time, alternating between two patterns so that the rate rule and the transition's stretch work) arrive so that
 * the step completing each frame is the first tick at or after both fins' stroke turning point: the frame's first
 * bytes arrive 3-4 ms before the turning point, its last bytes, and a HEARTBEAT right behind it, in that step
 * (32 bytes, what one step reads). That step runs the fins past the turning point (both latch: the rate rule,
 * clip and stretch for each, two LATCH reports encoded), decodes and handles the SET_FINS and the HEARTBEAT and
 * encodes two STATUS replies (the most messages one 32-byte read can complete: the shortest frame, a STOP or
 * HEARTBEAT, is 26 bytes), hands the fins the new command, then runs the 10 ms tick (lease,
 * watchdog, hand-over) and writes both servos and up to 64 bytes to the UART. A heartbeat between commands keeps
 * the watchdog fed; the scripted UART takes every byte the core offers.
 *
 * Probes (hal_avr.h): PA0 is high during every step, PA1 during the constructed worst-case steps only, and PA2
 * pulses once for every moving fin's latch in those steps (so the harness counts them). The harness
 * (sim/pfw_simavr.c) reports each probe's longest high time in cycles. The servos are the real ones (OCR1A/B).
 * The program ends with interrupts off and the CPU asleep: simavr stops there.
 */
#include <string.h>

#include "pfw.h"

#ifdef __AVR__
#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/sleep.h>

#include "hal_avr.h"
#define PROBE_ON(pin) (PORTA |= _BV(pin))
#define PROBE_OFF(pin) (PORTA &= (uint8_t)~_BV(pin))
#else /* a host build of the same scenario, to see what the constructed steps contain (make avr-timing-host) */
#include <stdio.h>
#define PA0 0
#define PA1 1
#define PA2 2
static unsigned long probe_count[3];
#define PROBE_ON(pin) ((void)0)
#define PROBE_OFF(pin) (probe_count[pin]++)
static uint32_t host_random32(void *ctx) { (void)ctx; return 0x12345678u; }
static void host_servo(void *ctx, uint8_t fin, float angle) { (void)ctx, (void)fin, (void)angle; }
static void hal_avr_init(pfw_hal *hal) { hal->random32 = host_random32; hal->servo_write = host_servo; }
static void hal_avr_kick(void) {}
#endif

#define SESSION 0x5EC0FFEEul
#define RUN_MS 20000u      /* scripted milliseconds */
#define HEARTBEAT_MS 100u  /* a keep-alive from the PC at least this often */

static pfw_app app;
static uint32_t fake_ms;
static const uint8_t *feed;
static size_t feed_len;
static uint8_t frame[2 * (2 * PFW_MAX_FRAME_DATA + 8)]; /* room for two frames back to back */
static uint16_t seq, command;
static volatile uint8_t sink;


static uint32_t fake_millis(void *ctx)
{
    (void)ctx;
    return fake_ms;
}

static size_t fake_read(void *ctx, uint8_t *buf, size_t max)
{
    size_t n = feed_len < max ? feed_len : max;
    (void)ctx;
    memcpy(buf, feed, n);
    feed += n;
    feed_len -= n;
    return n;
}

static size_t fake_write(void *ctx, const uint8_t *buf, size_t len)
{
    (void)ctx;
    for (size_t i = 0; i < len; i++)
        sink = buf[i]; /* what a UART ring copy costs */
    return len;
}

static void put16(uint8_t *p, uint16_t v)
{
    p[0] = (uint8_t)(v >> 8);
    p[1] = (uint8_t)v;
}

static void put32(uint8_t *p, uint32_t v)
{
    put16(p, (uint16_t)(v >> 16));
    put16(p + 2, (uint16_t)v);
}

/* An escaped Receive Packet frame carrying one message of `type` with `body` (docs/protocol.md, sections 1-2). */
static size_t build(uint8_t *out, uint8_t type, const uint8_t *body, uint8_t body_len)
{
    uint8_t data[12 + 10 + 28];
    uint8_t *msg = data + 12;
    size_t n = 8u + body_len;
    uint16_t crc;
    memset(data, 0, 12);
    data[0] = 0x90;
    data[1] = 0x00, data[2] = 0x13, data[3] = 0xA2, data[8] = 0x02; /* the PC's XBee */
    data[9] = 0xFF, data[10] = 0xFE, data[11] = 0x01;
    msg[0] = PFW_PROTOCOL_VERSION;
    msg[1] = type;
    put32(msg + 2, SESSION);
    put16(msg + 6, ++seq);
    memcpy(msg + 8, body, body_len);
    crc = pfw_crc16(msg, n);
    put16(msg + n, crc);
    return pfw_frame_encode(data, 12u + n + 2u, out, 2 * PFW_MAX_FRAME_DATA + 8);
}

static size_t build_set_fins(int variant)
{
    /* bias [mrad], amplitude [mrad], period [ms], ratio [1/1000], both fins the same: they latch together */
    static const uint16_t pattern[2][4] = {{1571, 1100, 700, 2000}, {1300, 700, 1500, 1000}};
    uint8_t body[28];
    for (int fin = 0; fin < 2; fin++)
        for (int k = 0; k < 4; k++)
            put16(body + 8 * fin + 2 * k, pattern[variant][k]);
    put16(body + 16, ++command);
    put16(body + 18, 1000u); /* lease [ms] */
    put32(body + 20, 0u);    /* no deadline */
    put32(body + 24, 0u);
    return build(frame, PFW_SET_FINS, body, sizeof body);
}

/* When fin's half-stroke in progress ends [clock ms, float], or -1 if it is still or already over. */
static float turning_at(const pfw_fin *f)
{
    if (f->due || f->duration_ms <= 0.0f || f->from == f->to)
        return -1.0f;
    return (float)f->start_ms + f->start_frac_ms + f->duration_ms;
}

int main(void)
{
    pfw_hal hal;
    pfw_config cfg;
    size_t len = 0, held = 0;
    uint32_t last_message = 0, target = 0;
    int variant = 0;

    hal_avr_init(&hal);
#ifdef __AVR__
    DDRA |= _BV(PA2);
#endif
    hal.millis = fake_millis;
    hal.uart_read = fake_read;
    hal.uart_write = fake_write;
    pfw_config_default(&cfg);
    pfw_app_init(&app, &hal, &cfg);

    len = build_set_fins(variant);
    feed = frame, feed_len = len; /* the first command, at 0 ms: still fins start at once */
    for (fake_ms = 1; fake_ms < RUN_MS; fake_ms++) {
        const pfw_fw *fw = &app.fw;
        int worst = 0;
        if (held && fake_ms == target) {
            feed_len += held; /* the frames' last bytes: both messages complete in this step */
            held = 0;
            worst = 1;
        } else if (!held && feed_len == 0u) {
            float turn = turning_at(&fw->fin[0]);
            if (turn > 0.0f && turn == turning_at(&fw->fin[1]) && turn - (float)fake_ms > 3.0f &&
                turn - (float)fake_ms <= 4.0f) {
                /* both fins turn in 3..4 ms: a new command's frame starts now (two steps read it, both before
                 * the turning point), and its last bytes wait for the first tick at or after the turning point */
                size_t beat;
                variant ^= 1;
                len = build_set_fins(variant);
                beat = build(frame + len, PFW_HEARTBEAT, NULL, 0); /* a keep-alive right behind it */
                held = 32u - beat; /* the last step's read (32 bytes) completes both messages */
                len += beat;
                held += beat;
                feed = frame, feed_len = len - held;
                target = app.last_tick_ms + PFW_TICK_MS;
                while ((float)target < turn)
                    target += PFW_TICK_MS;
                last_message = fake_ms;
            } else if (fake_ms - last_message >= HEARTBEAT_MS && (turn < 0.0f || turn - (float)fake_ms > 8.0f)) {
                len = build(frame, PFW_HEARTBEAT, NULL, 0);
                feed = frame, feed_len = len;
                last_message = fake_ms;
            }
        }
        if (worst)
            PROBE_ON(PA1);
        PROBE_ON(PA0);
        pfw_app_step(&app);
        PROBE_OFF(PA0);
        if (worst) {
            PROBE_OFF(PA1);
        }
        while (pfw_tx_take(&app.fw, app.out, sizeof app.out)) { /* drain, unmeasured: the UART's business */
        }
        app.out_len = app.out_pos = 0;
        {
            pfw_event ev;
            while (pfw_event_take(&app.fw, &ev)) {
                if (worst && ev.kind == PFW_EVENT_LATCH && !ev.still) { /* PA2: one pulse per latch, counted */
                    PROBE_ON(PA2);
                    PROBE_OFF(PA2);
                }
            }
        }
        hal_avr_kick();
    }
#ifdef __AVR__
    cli();
    sleep_enable();
    sleep_cpu(); /* asleep with interrupts off: simavr ends the run here */
#else
    printf("steps %lu, constructed worst steps %lu, moving-fin latches in them %lu\n", probe_count[0], probe_count[1],
           probe_count[2]);
#endif
    return 0;
}
