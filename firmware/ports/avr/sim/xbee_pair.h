/*
 * A virtual pair of XBee modules in API mode 2 (escaped), for the simulator harness.
 *
 * The PC's XBee takes Transmit Request frames (0x10) from the PC and the robot's XBee hands their RF data
 * to the microcontroller as Receive Packet frames (0x90), and the other way round (docs/protocol.md, section 1).
 * The pair delivers every frame at once and never loses one: the radio's delay and loss are the PC-side
 * channel's business (hardware/radio/channel.py), not the firmware's.
 */
#ifndef XBEE_PAIR_H
#define XBEE_PAIR_H

#include <stddef.h>
#include <stdint.h>

#define XBEE_MAX_FRAME_DATA 255u
#define XBEE_MAX_ENCODED (1u + 2u * (2u + XBEE_MAX_FRAME_DATA + 1u))

/* 64-bit addresses the two virtual modules report as the source of what they deliver. */
#define XBEE_PC_ADDRESS 0x0013A20000000002ull
#define XBEE_ROBOT_ADDRESS 0x0013A20000000001ull

/* A streaming decoder of escaped API frames. */
typedef struct {
    uint8_t data[XBEE_MAX_FRAME_DATA];
    size_t length;   /* announced frame-data length */
    size_t have;     /* frame-data bytes received */
    int state;       /* 0 hunt, 1 length MSB, 2 length LSB, 3 data, 4 checksum */
    int escaped;     /* the previous byte was 0x7D */
    uint32_t bad;    /* frames dropped: checksum, length or framing */
} xbee_decoder;

void xbee_decoder_init(xbee_decoder *dec);

/* Feed one wire byte; returns the frame-data length when a valid frame completes (frame in dec->data), else 0. */
size_t xbee_decoder_feed(xbee_decoder *dec, uint8_t byte);

/* Escape and frame `len` bytes of frame data into out (at least XBEE_MAX_ENCODED bytes); returns the size. */
size_t xbee_encode(const uint8_t *frame_data, size_t len, uint8_t *out);

/*
 * Turn a Transmit Request (0x10) received from one side into the Receive Packet (0x90) the other side's module
 * delivers, with `source` as its 64-bit source address. Returns the encoded size in out, or 0 if the frame is no
 * Transmit Request (the module consumes it: AT commands and the like are not forwarded).
 */
size_t xbee_forward(const uint8_t *frame_data, size_t len, uint64_t source, uint8_t *out);

#endif
