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

int main(void)
{
    test_crc();
    test_escaping();
    test_decoder_resync();
    test_round_even();
    test_limits();
    if (failures) {
        printf("%d failure(s)\n", failures);
        return 1;
    }
    printf("unit tests: all passed\n");
    return 0;
}
