/* What the robot sends: STATUS replies and LATCH reports as Transmit Request frames (protocol.md sections 1-2). */
#include <math.h>
#include <string.h>

#include "pfw.h"
#include "pfw_internal.h"

static int running(const pfw_fw *fw)
{
    return fw->state == PFW_RUNNING;
}

static void put16(uint8_t *p, uint32_t v)
{
    p[0] = (uint8_t)(v >> 8);
    p[1] = (uint8_t)v;
}

static void put32(uint8_t *p, uint32_t v)
{
    p[0] = (uint8_t)(v >> 24);
    p[1] = (uint8_t)(v >> 16);
    p[2] = (uint8_t)(v >> 8);
    p[3] = (uint8_t)v;
}

/* A Transmit Request (0x10, frame id 0) to dest carrying a message of type with body; queued whole or dropped. */
static void send(pfw_fw *fw, uint64_t dest, uint8_t type, uint32_t session, uint16_t seq, const uint8_t *body,
                 size_t body_len)
{
    uint8_t data[14 + 10 + 23];
    uint8_t *msg = data + 14;
    size_t n = 10u + body_len, len;
    unsigned i;
    data[0] = 0x10u;
    data[1] = 0u;
    for (i = 0; i < 8u; i++) {
        data[2 + i] = (uint8_t)(dest >> (56u - 8u * i));
    }
    data[10] = 0xFFu;
    data[11] = 0xFEu;
    data[12] = 0u;
    data[13] = 0u;
    msg[0] = PFW_PROTOCOL_VERSION;
    msg[1] = type;
    put32(msg + 2, session);
    put16(msg + 6, seq);
    memcpy(msg + 8, body, body_len);
    put16(msg + 8 + body_len, pfw_crc16(msg, 8u + body_len));
    len = pfw_frame_encode(data, 14u + n, fw->tx + fw->tx_len, PFW_TX_CAPACITY - fw->tx_len);
    if (len == 0u) {
        fw->counters.tx_dropped++;
        return;
    }
    fw->tx_len += len;
}

size_t pfw_tx_take(pfw_fw *fw, uint8_t *out, size_t max)
{
    size_t n = fw->tx_len < max ? fw->tx_len : max;
    memcpy(out, fw->tx, n);
    memmove(fw->tx, fw->tx + n, fw->tx_len - n);
    fw->tx_len -= n;
    return n;
}

static uint32_t sat16(uint32_t v)
{
    return v > 0xFFFFu ? 0xFFFFu : v;
}

void pfw_status(pfw_fw *fw, const pfw_msg *ack, uint32_t now_ms)
{
    uint8_t body[23];
    uint8_t flags = 0;
    fw->status_seq = (uint16_t)(fw->status_seq + 1u);
    if (fw->clipped) {
        flags |= PFW_FLAG_CLIPPED;
    }
    if (running(fw) && (fw->held_back[0] || fw->held_back[1])) {
        flags |= PFW_FLAG_RATE_LIMITED;
    }
    put16(body, ack->seq);
    body[2] = ack->type;
    body[3] = fw->state;
    body[4] = flags;
    put16(body + 5, sat16(fw->dec.crc_errors + fw->dec.checksum_errors));
    put16(body + 7, sat16(fw->counters.tracker_duplicates));
    put16(body + 9, sat16(fw->counters.tracker_stale));
    put32(body + 11, pfw_uptime_ms(fw, now_ms));
    put32(body + 15, fw->has_session ? fw->session : 0u);
    put32(body + 19, fw->boot);
    send(fw, ack->src64, PFW_STATUS, ack->session, fw->status_seq, body, sizeof body);
}

static int close_to(float a, float b)
{
    return fabsf(a - b) <= 1e-8f + 1e-5f * fabsf(b); /* np.allclose */
}

void pfw_latch_report(pfw_fw *fw, unsigned fin, uint32_t ms, float frac)
{
    const pfw_fin *f = &fw->fin[fin];
    uint8_t body[20];
    uint32_t t;
    unsigned j;
    if (!running(fw) || !fw->has_session) {
        return; /* halted fins hold still: nothing latches that a replay needs */
    }
    /* bias, amplitude and ratio: the period may be stretched for the transition, which is not the rate rule */
    fw->held_back[fin] = (uint8_t)!(close_to(f->pattern[PFW_BIAS], fw->command[fin][PFW_BIAS]) &&
                                    close_to(f->pattern[PFW_AMPLITUDE], fw->command[fin][PFW_AMPLITUDE]) &&
                                    close_to(f->pattern[PFW_RATIO], fw->command[fin][PFW_RATIO]));
    if (f->to == f->from) {
        return; /* a half-stroke that ends where it starts moves nothing (a still fin's) */
    }
    fw->latch_seq = (uint16_t)(fw->latch_seq + 1u);
    t = ms - fw->power_up_ms;
    if (frac + PFW_MS_GUARD >= 1.0f) {
        t++; /* within the guard below the next whole ms: that ms */
    }
    put32(body, t);
    put32(body + 4, fw->boot);
    body[8] = (uint8_t)fin;
    body[9] = f->power ? 1u : 0u;
    put16(body + 10, (uint32_t)pfw_round_even(f->from * 1000.0f));
    for (j = 0; j < 4u; j++) {
        /* bias, amplitude [mrad]; period [ms]; ratio [1/1000] */
        float w = j == PFW_PERIOD ? f->pattern[j] : f->pattern[j] * 1000.0f;
        put16(body + 12 + 2u * j, (uint32_t)pfw_round_even(w));
    }
    send(fw, fw->session_addr, PFW_LATCH, fw->session, fw->latch_seq, body, sizeof body);
}

