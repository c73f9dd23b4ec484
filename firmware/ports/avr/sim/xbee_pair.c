/* A virtual pair of XBee modules in API mode 2 (see xbee_pair.h). */
#include "xbee_pair.h"

#include <string.h>

enum { START = 0x7E, ESCAPE = 0x7D, XON = 0x11, XOFF = 0x13, TX_REQUEST = 0x10, RX_PACKET = 0x90 };
enum { HUNT, LEN_MSB, LEN_LSB, DATA, CHECKSUM };

void xbee_decoder_init(xbee_decoder *dec)
{
    memset(dec, 0, sizeof *dec);
    dec->state = HUNT;
}

size_t xbee_decoder_feed(xbee_decoder *dec, uint8_t byte)
{
    if (byte == START) { /* a delimiter always starts a frame, whatever came before */
        if (dec->state != HUNT)
            dec->bad++;
        dec->state = LEN_MSB;
        dec->escaped = 0;
        dec->have = 0;
        return 0;
    }
    if (dec->state == HUNT)
        return 0;
    if (byte == ESCAPE) {
        dec->escaped = 1;
        return 0;
    }
    if (dec->escaped) {
        byte ^= 0x20;
        dec->escaped = 0;
    }
    switch (dec->state) {
    case LEN_MSB:
        dec->length = (size_t)byte << 8;
        dec->state = LEN_LSB;
        return 0;
    case LEN_LSB:
        dec->length |= byte;
        if (dec->length == 0 || dec->length > XBEE_MAX_FRAME_DATA) {
            dec->bad++;
            dec->state = HUNT;
            return 0;
        }
        dec->state = DATA;
        return 0;
    case DATA:
        dec->data[dec->have++] = byte;
        if (dec->have == dec->length)
            dec->state = CHECKSUM;
        return 0;
    default: { /* CHECKSUM */
        unsigned sum = byte;
        for (size_t i = 0; i < dec->length; i++)
            sum += dec->data[i];
        dec->state = HUNT;
        if ((sum & 0xFFu) != 0xFFu) {
            dec->bad++;
            return 0;
        }
        return dec->length;
    }
    }
}

static size_t put_escaped(uint8_t *out, size_t at, uint8_t byte)
{
    if (byte == START || byte == ESCAPE || byte == XON || byte == XOFF) {
        out[at++] = ESCAPE;
        out[at++] = (uint8_t)(byte ^ 0x20);
    } else {
        out[at++] = byte;
    }
    return at;
}

size_t xbee_encode(const uint8_t *frame_data, size_t len, uint8_t *out)
{
    unsigned sum = 0;
    size_t at = 0;
    if (len == 0 || len > XBEE_MAX_FRAME_DATA)
        return 0;
    out[at++] = START;
    at = put_escaped(out, at, (uint8_t)(len >> 8));
    at = put_escaped(out, at, (uint8_t)(len & 0xFFu));
    for (size_t i = 0; i < len; i++) {
        sum += frame_data[i];
        at = put_escaped(out, at, frame_data[i]);
    }
    return put_escaped(out, at, (uint8_t)(0xFFu - (sum & 0xFFu)));
}

size_t xbee_forward(const uint8_t *frame_data, size_t len, uint64_t source, uint8_t *out)
{
    /* Transmit Request: type, frame id, dest64 (8), dest16 (2), radius, options, RF data (from offset 14). */
    /* Receive Packet: type, src64 (8), src16 (2), options, RF data (from offset 12). */
    uint8_t rx[XBEE_MAX_FRAME_DATA];
    size_t rf;
    if (len < 14 || frame_data[0] != TX_REQUEST)
        return 0;
    rf = len - 14;
    rx[0] = RX_PACKET;
    for (int i = 0; i < 8; i++)
        rx[1 + i] = (uint8_t)(source >> (56 - 8 * i));
    rx[9] = 0xFF;
    rx[10] = 0xFE;  /* 16-bit address unknown, as XBee 802.15.4 / DigiMesh modules report it */
    rx[11] = 0x01;  /* options: packet acknowledged */
    memcpy(rx + 12, frame_data + 14, rf);
    return xbee_encode(rx, 12 + rf, out);
}
