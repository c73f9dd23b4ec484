/* The wire: CRC-16/CCITT-FALSE, XBee API mode 2 frames, message decoding (protocol.py, xbee.py). */
#include <string.h>

#include "pfw.h"
#include "pfw_internal.h"

#define START 0x7Eu
#define ESCAPE 0x7Du
#define XON 0x11u
#define XOFF 0x13u

uint16_t pfw_crc16(const uint8_t *data, size_t len)
{
    uint16_t crc = 0xFFFFu;
    size_t i;
    unsigned bit;
    for (i = 0; i < len; i++) {
        crc = (uint16_t)(crc ^ (uint16_t)((uint16_t)data[i] << 8));
        for (bit = 0; bit < 8u; bit++) {
            uint16_t shifted = (uint16_t)(crc << 1);
            crc = (crc & 0x8000u) ? (uint16_t)(shifted ^ 0x1021u) : shifted;
        }
    }
    return crc;
}

void pfw_decoder_init(pfw_decoder *dec)
{
    memset(dec, 0, sizeof *dec);
}

static uint16_t get16(const uint8_t *p)
{
    return (uint16_t)(((uint16_t)p[0] << 8) | p[1]); /* no int overflow where int is 16 bits */
}

static uint32_t get32(const uint8_t *p)
{
    return ((uint32_t)p[0] << 24) | ((uint32_t)p[1] << 16) | ((uint32_t)p[2] << 8) | (uint32_t)p[3];
}

/* decode_message: 0 ok, 1 crc error, 2 other (malformed). */
static int decode_message(const uint8_t *p, size_t n, pfw_msg *msg)
{
    size_t body, want;
    unsigned i;
    if (n < 10u) {
        return 2;
    }
#ifndef PFW_BROKEN_SKIP_CRC
    if (pfw_crc16(p, n - 2u) != get16(p + n - 2u)) {
        return 1;
    }
#endif
    if (p[0] != PFW_PROTOCOL_VERSION) {
        return 2;
    }
    switch (p[1]) {
    case PFW_SET_FINS: want = 28u; break;
    case PFW_STOP: case PFW_HEARTBEAT: case PFW_CLAIM: want = 0u; break;
    case PFW_STATUS: want = 23u; break;
    case PFW_LATCH: want = 20u; break;
    default: return 2;
    }
    body = n - 10u;
    if (body != want) {
        return 2;
    }
    if (p[1] == PFW_LATCH && p[8 + 8] > 1u) {
        return 2; /* a LATCH of a fin that does not exist */
    }
    msg->type = p[1];
    msg->session = get32(p + 2);
    msg->seq = get16(p + 6);
    if (p[1] == PFW_SET_FINS) {
        for (i = 0; i < 8u; i++) {
            msg->fins[i] = get16(p + 8 + 2u * i);
        }
        msg->command = get16(p + 24);
        msg->lease_ms = get16(p + 26);
        msg->deadline = get32(p + 28);
        msg->boot = get32(p + 32);
    }
    return 0;
}

static void frame_done(pfw_decoder *dec, pfw_msg *msg, int *got)
{
    const uint8_t *data = dec->buf + 2;
    size_t length = (size_t)get16(dec->buf), i, off;
    uint8_t sum = 0;
    int verdict;
    dec->in_frame = 0;
    for (i = 0; i < length; i++) {
        sum = (uint8_t)(sum + data[i]);
    }
    sum = (uint8_t)(0xFFu - sum);
    if (sum != dec->buf[length + 2u]) {
        dec->checksum_errors++;
        return;
    }
    dec->frames++;
    msg->src64 = 0x000000000000FFFFull; /* broadcast: a frame that names no sender */
    if (data[0] == 0x10u && length >= 14u) {
        off = 14u;
    } else if (data[0] == 0x90u && length >= 12u) {
        off = 12u;
        msg->src64 = 0;
        for (i = 1; i < 9u; i++) {
            msg->src64 = (msg->src64 << 8) | data[i];
        }
    } else {
        dec->other_frames++;
        return;
    }
    verdict = decode_message(data + off, length - off, msg);
    if (verdict == 1) {
        dec->crc_errors++;
    } else if (verdict == 2) {
        dec->malformed++;
    } else {
        dec->messages++;
        *got = 1;
    }
}

int pfw_decoder_feed(pfw_decoder *dec, uint8_t byte, pfw_msg *msg)
{
    int got = 0;
    size_t length;
    if (byte == START) {
        if (dec->in_frame && dec->len) {
            dec->truncated++; /* a new frame began before the previous one was complete */
        }
        dec->len = 0;
        dec->in_frame = 1;
        dec->escaped = 0;
        return 0;
    }
    if (!dec->in_frame) {
        dec->skipped_bytes++;
        return 0;
    }
    if (dec->escaped) {
        byte ^= 0x20u;
        dec->escaped = 0;
    } else if (byte == ESCAPE) {
        dec->escaped = 1;
        return 0;
    }
    dec->buf[dec->len++] = byte; /* len < length + 3 <= sizeof buf: the frame completes or fails before */
    if (dec->len < 2u) {
        return 0;
    }
    length = (size_t)get16(dec->buf);
    if (length == 0u || length > PFW_MAX_FRAME_DATA) {
        dec->framing_errors++;
        dec->in_frame = 0;
        dec->len = 0;
        return 0;
    }
    if ((size_t)dec->len < length + 3u) {
        return 0;
    }
    frame_done(dec, msg, &got);
    dec->len = 0;
    return got;
}

static int special(uint8_t b)
{
    return b == START || b == ESCAPE || b == XON || b == XOFF;
}

size_t pfw_frame_encode(const uint8_t *frame_data, size_t len, uint8_t *out, size_t out_max)
{
    size_t n = 0, i;
    uint8_t sum = 0, head[2], b;
    if (len == 0u || len > PFW_MAX_FRAME_DATA || out_max < 1u) {
        return 0;
    }
    out[n++] = START;
    head[0] = (uint8_t)(len >> 8);
    head[1] = (uint8_t)(len & 0xFFu);
    for (i = 0; i < len + 3u; i++) {
        if (i < 2u) {
            b = head[i];
        } else if (i < len + 2u) {
            b = frame_data[i - 2u];
            sum = (uint8_t)(sum + b);
        } else {
            b = (uint8_t)(0xFFu - sum);
        }
        if (special(b)) {
            if (n + 2u > out_max) {
                return 0;
            }
            out[n++] = ESCAPE;
            out[n++] = (uint8_t)(b ^ 0x20u);
        } else {
            if (n + 1u > out_max) {
                return 0;
            }
            out[n++] = b;
        }
    }
    return n;
}
