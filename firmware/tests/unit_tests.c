/* C unit tests of the core's wire layer and limits: `make -C firmware test` (built with the sanitizers).
 * Independent values: the CRC-16/CCITT-FALSE check value 0x29B1 of "123456789", Digi's escaping example
 * (frame data 23 11 -> 7E 00 02 23 7D 31 CB), the limits worked by hand. Exit status 0 when all pass. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "pfw.h"
#include "pfw_internal.h"

static int failures;

#define CHECK(cond)                                                   \
    do {                                                              \
        if (!(cond)) {                                                \
            printf("FAIL %s:%d: %s\n", __FILE__, __LINE__, #cond);    \
            failures++;                                               \
        }                                                             \
    } while (0)

static void test_crc(void)
{
    const uint8_t check[] = "123456789";
    CHECK(pfw_crc16(check, 9) == 0x29B1u);
}

static void test_escaping(void)
{
    const uint8_t data[] = {0x23, 0x11};
    const uint8_t want[] = {0x7E, 0x00, 0x02, 0x23, 0x7D, 0x31, 0xCB};
    uint8_t out[16];
    pfw_decoder dec;
    pfw_msg msg;
    size_t n = pfw_frame_encode(data, 2, out, sizeof out), i;
    int got = 0;
    CHECK(n == sizeof want && memcmp(out, want, sizeof want) == 0);
    CHECK(pfw_frame_encode(data, 2, out, 6) == 0); /* does not fit: nothing */
    pfw_decoder_init(&dec);
    for (i = 0; i < n; i++) {
        got |= pfw_decoder_feed(&dec, out[i], &msg);
    }
    CHECK(!got && dec.frames == 1u && dec.other_frames == 1u); /* a valid frame of another type */
}

static void test_decoder_resync(void)
{
    /* garbage, a frame cut by a new delimiter, a length lie: counted, nothing yielded */
    const uint8_t bytes[] = {0x01, 0x02, 0x7E, 0x00, 0x05, 0x90, 0x7E, 0x01, 0x2C, 0x7E, 0x00};
    pfw_decoder dec;
    pfw_msg msg;
    size_t i;
    int got = 0;
    pfw_decoder_init(&dec);
    for (i = 0; i < sizeof bytes; i++) {
        got |= pfw_decoder_feed(&dec, bytes[i], &msg);
    }
    CHECK(!got && dec.skipped_bytes == 2u && dec.truncated == 1u && dec.framing_errors == 1u);
}

static void test_round_even(void)
{
    CHECK(pfw_round_even(2.5f) == 2.0f && pfw_round_even(3.5f) == 4.0f && pfw_round_even(1570.4f) == 1570.0f);
    CHECK(pfw_round_even(0.5f) == 0.0f && pfw_round_even(65534.5f) == 65534.0f);
}

static void test_limits(void)
{
    pfw_config cfg;
    float beat[4] = {1.5f, 2.0f, 100.0f, 10.0f}, ran[4] = {1.0f, 0.1f, 1000.0f, 1.0f};
    pfw_config_default(&cfg);
    CHECK(pfw_clip(&cfg, beat));
    /* amplitude to half the range (80 deg), bias to the middle, ratio 6, period lengthened for 13 rad/s:
     * pi * 1.3963 * 7 / 13 = 2.362 s */
    CHECK(fabsf(beat[1] - 1.3962634f) < 1e-6f && fabsf(beat[0] - 1.5707964f) < 1e-6f && beat[3] == 6.0f);
    CHECK(fabsf(beat[2] - 2362.0f) < 1.0f);
    /* slew: in 100 ms the bias moves at most pi * 0.1 rad, the ratio at most 1 */
    beat[0] = 2.5f;
    beat[1] = 0.1f;
    beat[2] = 1000.0f;
    beat[3] = 3.0f;
    pfw_slew_at_latch(&cfg, beat, ran, 100.0f, 0);
    CHECK(fabsf(beat[0] - (1.0f + 0.31415927f)) < 1e-6f && beat[1] == 0.1f && beat[2] == 1000.0f && beat[3] == 2.0f);
    /* stretch: a power stroke from 0.2 rad to 2.9 rad at ratio 1 takes period / 2; pi * 2.7 / (2 * 13 * 0.5) */
    beat[0] = 2.0f;
    beat[1] = 0.9f;
    beat[2] = 400.0f;
    beat[3] = 1.0f;
    pfw_stretch_transition(&cfg, beat, 0.2f, 1);
    CHECK(fabsf(beat[2] - 652.47f) < 0.1f);
}

/* ---------------------------------------------------------------- the main loop on a simulated board */
typedef struct board {
    uint32_t now;
    uint8_t in[128];
    size_t in_len, in_pos;
    uint8_t out[4096];
    size_t out_len;
    float servo[2];
    unsigned servo_writes;
} board;

static uint32_t b_millis(void *ctx)
{
    return ((board *)ctx)->now;
}

static size_t b_read(void *ctx, uint8_t *buf, size_t max)
{
    board *b = ctx;
    size_t n = b->in_len - b->in_pos;
    n = n < max ? n : max;
    n = n < 5u ? n : 5u; /* the UART delivers a few bytes at a time */
    memcpy(buf, b->in + b->in_pos, n);
    b->in_pos += n;
    return n;
}

static size_t b_write(void *ctx, const uint8_t *buf, size_t len)
{
    board *b = ctx;
    size_t n = len < 7u ? len : 7u; /* the UART takes a few bytes at a time */
    if (b->out_len + n > sizeof b->out) {
        n = sizeof b->out - b->out_len;
    }
    memcpy(b->out + b->out_len, buf, n);
    b->out_len += n;
    return n;
}

static void b_servo(void *ctx, uint8_t fin, float angle)
{
    board *b = ctx;
    b->servo[fin & 1u] = angle;
    b->servo_writes++;
}

static uint32_t b_random(void *ctx)
{
    (void)ctx;
    return 0u; /* a zero draw: the boot id must still be nonzero */
}

static void test_app_on_a_simulated_board(void)
{
    static board b;
    static pfw_app app;
    pfw_hal hal = {&b, b_millis, b_read, b_write, b_servo, b_random};
    pfw_config cfg;
    uint8_t data[14 + 10 + 28], *msg = data + 12;
    const uint16_t words[8] = {1571, 500, 1000, 1000, 1571, 500, 1000, 1000};
    pfw_decoder dec;
    pfw_msg out;
    unsigned i, statuses = 0, latches = 0;
    size_t k;
    float moved = 0.0f, held;
    memset(&b, 0, sizeof b);
    b.now = 0xFFFFFF00u; /* the clock wraps during the test */
    pfw_config_default(&cfg);
    CHECK(pfw_app_init(&app, &hal, &cfg) == 0 && app.fw.boot == 1u);
    /* a Receive Packet with SET_FINS: session 7, seq 1, command 1, lease 800 ms, no deadline */
    memset(data, 0, sizeof data);
    data[0] = 0x90;
    data[8] = 0x42;
    data[9] = 0xFF;
    data[10] = 0xFE;
    data[11] = 0x01;
    msg[0] = 3;
    msg[1] = PFW_SET_FINS;
    msg[5] = 7;
    msg[7] = 1;
    for (i = 0; i < 8; i++) {
        msg[8 + 2 * i] = (uint8_t)(words[i] >> 8);
        msg[9 + 2 * i] = (uint8_t)words[i];
    }
    msg[25] = 1;
    msg[26] = 800 >> 8;
    msg[27] = 800 & 0xFF;
    k = pfw_crc16(msg, 36);
    data[12 + 36] = (uint8_t)(k >> 8);
    data[12 + 37] = (uint8_t)k;
    b.in_len = pfw_frame_encode(data, 12 + 38, b.in, sizeof b.in);
    CHECK(b.in_len > 0u);
    for (i = 0; i < 400; i++) { /* 400 ms */
        b.now++;
        pfw_app_step(&app);

        if (fabsf(b.servo[0] - 1.5707964f) > moved) {
            moved = fabsf(b.servo[0] - 1.5707964f);
        }
    }
    CHECK(app.fw.state == PFW_RUNNING && moved > 0.4f && b.servo_writes >= 80u);
    for (i = 0; i < 600; i++) { /* silence: the watchdog halts the fins at 500 ms */
        b.now++;
        pfw_app_step(&app);
    }
    held = b.servo[0];
    for (i = 0; i < 100; i++) {
        b.now++;
        pfw_app_step(&app);
    }
    CHECK(app.fw.state == PFW_WATCHDOG && b.servo[0] == held);
    pfw_decoder_init(&dec);
    for (k = 0; k < b.out_len; k++) {
        if (pfw_decoder_feed(&dec, b.out[k], &out)) {
            statuses += out.type == PFW_STATUS;
            latches += out.type == PFW_LATCH;

            CHECK(out.src64 == 0x000000000000FFFFull); /* a Transmit Request names no sender */
        }
    }
    /* One STATUS; the message completes at 11 ms (5 bytes a read), the fins take the command at the tick at 20 ms
     * (firmware.py: the setpoint follows the command at a tick) and latch from rest there: a LATCH per fin. Their
     * next turning point, 500 ms later at 520 ms, meets the watchdog's trip (520 - 11 > 500 ms): halted, no LATCH. */
    CHECK(statuses == 1u && latches == 2u && dec.checksum_errors == 0u && dec.framing_errors == 0u);
    CHECK(app.fw.tx_len == 0u && app.out_pos == app.out_len);
}

int main(void)
{
    test_crc();
    test_escaping();
    test_decoder_resync();
    test_round_even();
    test_limits();
    test_app_on_a_simulated_board();
    if (failures) {
        printf("%d failure(s)\n", failures);
        return 1;
    }
    printf("unit tests: all passed\n");
    return 0;
}
