/* Fuzz driver of the core: random and mutated XBee frames and ticks, built with ASan + UBSan.
 *
 *   build/fuzz_frames [frames [seed]]      (make -C firmware fuzz; default 1000000 frames, seed 1)
 *
 * Deterministic (xorshift64* from the seed). Each iteration builds a valid SET_FINS, STOP, CLAIM or HEARTBEAT
 * message (random sessions, sequence numbers, command ids, leases, deadlines, patterns; 1 in 25 with a bit flipped
 * inside an intact frame, for the CRC-16), mutates the frame (bit flips,
 * truncation, length lies, escape abuse, stray delimiters, garbage, splicing) or not, feeds it in random pieces,
 * and ticks the clock by 0..60 ms (sometimes across the u32 wrap). After every call it checks invariants: a state
 * in 0..4, fin angles finite and inside the servo range, every byte the robot sends decodes as a well-formed
 * Transmit Request. Any violation or sanitizer report exits nonzero. Prints the counts at the end. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "pfw.h"

static uint64_t rng_state;

static uint32_t rnd(void)
{
    rng_state ^= rng_state >> 12;
    rng_state ^= rng_state << 25;
    rng_state ^= rng_state >> 27;
    return (uint32_t)((rng_state * 2685821657736338717ull) >> 32);
}

static uint32_t below(uint32_t n)
{
    return n ? rnd() % n : 0u;
}

static void put16(uint8_t *p, uint32_t v)
{
    p[0] = (uint8_t)(v >> 8);
    p[1] = (uint8_t)v;
}

static void put32(uint8_t *p, uint32_t v)
{
    put16(p, v >> 16);
    put16(p + 2, v & 0xFFFFu);
}

static pfw_fw fw;
static pfw_decoder out_dec;
static uint32_t sessions[4], seqs[4], commands[4];
static unsigned long tx_frames, violations, latches, running_ticks, reboots;
static unsigned long seen[6]; /* decoder counters of the power-ups before this one: messages, crc, checksum,
                               * framing, truncated, malformed */

static void add_decoder(unsigned long *to)
{
    to[0] += fw.dec.messages;
    to[1] += fw.dec.crc_errors;
    to[2] += fw.dec.checksum_errors;
    to[3] += fw.dec.framing_errors;
    to[4] += fw.dec.truncated;
    to[5] += fw.dec.malformed;
}

static size_t build_frame(uint8_t *out, size_t max, uint32_t clock)
{
    uint8_t data[14 + 10 + 28 + 8];
    uint8_t *msg = data + 12;
    unsigned who = below(4), kind = below(10), i;
    size_t body = 0, n;
    data[0] = 0x90;
    for (i = 1; i < 9; i++) {
        data[i] = (uint8_t)(0x10u + who);
    }
    data[9] = 0xFF;
    data[10] = 0xFE;
    data[11] = 0x01;
    msg[0] = below(50) ? 3u : (uint8_t)rnd();
    msg[1] = kind < 6 ? PFW_SET_FINS : kind < 7 ? PFW_STOP : kind < 8 ? PFW_CLAIM : kind < 9 ? PFW_HEARTBEAT
                                                                                               : (uint8_t)rnd();
    put32(msg + 2, sessions[who]);
    seqs[who] += below(8) ? 1u : (uint32_t)below(3) - 1u;
    put16(msg + 6, seqs[who]);
    if (msg[1] == PFW_SET_FINS) {
        for (i = 0; i < 8; i++) {
            put16(msg + 8 + 2 * i, below(4) ? below(4000) : rnd());
        }
        commands[who] += below(6) ? 1u : below(3);
        put16(msg + 24, commands[who]);
        put16(msg + 26, below(10) ? 1u + below(1000) : rnd());
        put32(msg + 28, below(3) ? 0u : pfw_uptime_ms(&fw, clock) + below(1500) - 200u);
        put32(msg + 32, below(10) ? fw.boot : rnd());
        body = 28;
    }
    put16(msg + 8 + body, pfw_crc16(msg, 8 + body));
    if (below(25) == 0) { /* damaged inside an intact frame: only the CRC-16 catches it */
        msg[below((uint32_t)(10 + body))] ^= (uint8_t)(1u << below(8));
    }
    n = pfw_frame_encode(data, 12 + 10 + body, out, max);
    return n;
}

static size_t mutate(uint8_t *buf, size_t n, size_t max)
{
    unsigned kind = below(12), k;
    size_t i;
    switch (kind) {
    case 0: case 1: /* bit flips */
        for (k = 0; k <= below(4); k++) {
            buf[below((uint32_t)n)] ^= (uint8_t)(1u << below(8));
        }
        return n;
    case 2: /* truncation */
        return below((uint32_t)n) + 1u;
    case 3: /* length lie */
        put16(buf + 1, rnd() & (below(2) ? 0xFFu : 0xFFFFu));
        return n;
    case 4: /* escape abuse: a stray escape, an escaped ordinary byte, a trailing escape */
        if (n + 2 > max) {
            return n;
        }
        i = 1u + below((uint32_t)n - 1u);
        memmove(buf + i + 1, buf + i, n - i);
        buf[i] = 0x7D;
        n++;
        if (below(2)) {
            buf[n++] = 0x7D;
        }
        return n;
    case 5: /* a stray delimiter */
        buf[1u + below((uint32_t)n - 1u)] = 0x7E;
        return n;
    case 6: /* garbage */
        n = below((uint32_t)max);
        for (i = 0; i < n; i++) {
            buf[i] = (uint8_t)rnd();
        }
        return n;
    default:
        return n; /* valid */
    }
}

static void check(void)
{
    uint8_t tx[PFW_TX_CAPACITY];
    size_t n = pfw_tx_take(&fw, tx, sizeof tx), i;
    unsigned f;
    pfw_msg msg;
    pfw_event ev;
    uint32_t checksum_errors = out_dec.checksum_errors, frames = out_dec.frames;
    for (i = 0; i < n; i++) {
        (void)pfw_decoder_feed(&out_dec, tx[i], &msg);
    }
    tx_frames += out_dec.frames - frames;
    if (out_dec.checksum_errors != checksum_errors || out_dec.framing_errors || out_dec.truncated ||
        out_dec.crc_errors || out_dec.malformed) {
        printf("violation: the robot sent a damaged frame\n");
        violations++;
    }
    if (fw.state > PFW_EXPIRED) {
        printf("violation: state %u\n", fw.state);
        violations++;
    }
    for (f = 0; f < 2; f++) {
        float a = pfw_fin_angle(&fw, f);
        if (!isfinite(a) || a < fw.cfg.angle_min - 1e-5f || a > fw.cfg.angle_max + 1e-5f) {
            printf("violation: fin %u angle %g\n", f, (double)a);
            violations++;
        }
    }
    while (pfw_event_take(&fw, &ev)) {
        latches += ev.kind == PFW_EVENT_LATCH;
        if (ev.kind == PFW_EVENT_LATCH && !(ev.frac_ms >= 0.0f && ev.frac_ms < 1.0f)) {
            printf("violation: latch fraction %g\n", (double)ev.frac_ms);
            violations++;
        }
    }
}

int main(int argc, char **argv)
{
    unsigned long frames = argc > 1 ? strtoul(argv[1], NULL, 10) : 1000000ul, it;
    unsigned long seed = argc > 2 ? strtoul(argv[2], NULL, 10) : 1ul;
    pfw_config cfg;
    uint8_t buf[600];
    size_t n, pos, piece;
    uint32_t clock;
    unsigned i;
    rng_state = 0x9E3779B97F4A7C15ull ^ (uint64_t)seed;
    pfw_config_default(&cfg);
    clock = rnd();
    if (pfw_init(&fw, &cfg, rnd() | 1u, clock) != 0) {
        return 2;
    }
    pfw_decoder_init(&out_dec);
    for (i = 0; i < 4; i++) {
        sessions[i] = rnd();
        seqs[i] = rnd();
        commands[i] = rnd();
    }
    for (it = 0; it < frames && violations == 0; it++) {
        n = build_frame(buf, 300, clock);
        if (n > 0 && below(3) == 0) {
            n = mutate(buf, n, 300);
        }
        if (below(20) == 0) { /* splice a second frame on */
            n += build_frame(buf + n, sizeof buf - n, clock);
        }
        for (pos = 0; pos < n; pos += piece) {
            piece = below(3) ? n - pos : 1u + below((uint32_t)(n - pos));
            pfw_receive(&fw, buf + pos, piece, clock);
            check();
        }
        clock += below(4) ? below(12) : below(61);
        if (below(2000) == 0) {
            clock += 0xFFFFF000u; /* hop close to the wrap (and across it) */
        }
        pfw_tick(&fw, clock);
        running_ticks += fw.state == PFW_RUNNING;
        check();
        if (below(200000) == 0) {
            add_decoder(seen);
            reboots++;
            (void)pfw_init(&fw, &cfg, rnd() | 1u, clock); /* a reboot */
        }
    }
    add_decoder(seen);
    printf("fuzz_frames: %lu frames, seed %lu, %lu reboots, %lu robot frames checked, decoder: %lu messages, "
           "%lu crc, %lu checksum, %lu framing, %lu truncated, %lu malformed; %lu latches, %lu ticks running; "
           "%lu violations\n",
           it, seed, reboots, tx_frames, seen[0], seen[1], seen[2], seen[3], seen[4], seen[5], latches,
           running_ticks, violations);
    return violations ? 1 : 0;
}
