/*
 * sashil rig protocol v2, serial framing (drivers/protocol.md "Serial framing"), for the interface board.
 *
 *   COBS( type:u8 | seq:u16 | len:u8 | payload[len] | crc:u16 ) 0x00      (integers little-endian)
 *
 * crc: CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, MSB first, no final xor) over type..payload.
 * Portable C99: no dynamic allocation, only <stdint.h>/<stddef.h>; every function bounds-checks its
 * output buffer and reads only the bytes it is given. The same bytes as drivers/serial_codec.py.
 */
#ifndef SASHIL_FRAME_H
#define SASHIL_FRAME_H

#include <stddef.h>
#include <stdint.h>

#define SASHIL_MAX_PAYLOAD 32u
#define SASHIL_HEADER_SIZE 4u
#define SASHIL_CRC_SIZE 2u
/* header + payload + crc, COBS overhead, delimiter (as serial_codec.MAX_FRAME) */
#define SASHIL_MAX_FRAME (SASHIL_HEADER_SIZE + SASHIL_MAX_PAYLOAD + SASHIL_CRC_SIZE + 2u)

/* decode results (0: a frame); the negative kinds are the host decoder's counters */
enum {
    SASHIL_FRAME_OK = 0,
    SASHIL_FRAME_COBS = -1,         /* impossible COBS code sequence */
    SASHIL_FRAME_LENGTH = -2,       /* shorter than header + CRC, or the length field disagrees */
    SASHIL_FRAME_CRC = -3,          /* bad CRC */
    SASHIL_FRAME_UNKNOWN_TYPE = -4, /* a type code protocol v2 does not have */
    SASHIL_FRAME_OVERFLOW = -5      /* more than SASHIL_MAX_FRAME bytes without a delimiter */
};

uint16_t sashil_crc16(const uint8_t *data, size_t n);

/* COBS-encode n bytes into out (no delimiter); returns the length, 0 if cap is too small. */
size_t sashil_cobs_encode(const uint8_t *in, size_t n, uint8_t *out, size_t cap);

/* COBS-decode n bytes (no delimiter) into out; returns SASHIL_FRAME_OK or SASHIL_FRAME_COBS / _LENGTH. */
int sashil_cobs_decode(const uint8_t *in, size_t n, uint8_t *out, size_t cap, size_t *out_len);

/* The whole wire frame of one message, 0x00 included; returns its length, 0 if it does not fit. */
size_t sashil_frame_encode(uint8_t type, uint16_t seq, const uint8_t *payload, uint8_t len, uint8_t *out,
                           size_t cap);

/* One frame's COBS bytes (without the delimiter) -> type, seq, payload (SASHIL_MAX_PAYLOAD bytes). */
int sashil_frame_decode(const uint8_t *cobs, size_t n, uint8_t *type, uint16_t *seq, uint8_t *payload,
                        uint8_t *len);

/* The payload length of a protocol v2 message type, or -1 for an unknown type. */
int sashil_payload_size(uint8_t type);

/* A stream decoder: bytes in, one frame out at each delimiter (no allocation, fixed buffer). */
typedef struct {
    uint8_t buf[SASHIL_MAX_FRAME];
    size_t n;
    int skipping; /* inside an overlong run: drop bytes up to the next delimiter */
    uint32_t frames, bad_frames;
} sashil_stream;

void sashil_stream_init(sashil_stream *s);

/* Feed one byte. Returns 1 with type/seq/payload/len set when it completes a good frame, 0 when it
 * completes nothing, or a negative SASHIL_FRAME_* kind when it ends a bad frame (counted). */
int sashil_stream_feed(sashil_stream *s, uint8_t byte, uint8_t *type, uint16_t *seq, uint8_t *payload,
                       uint8_t *len);

#endif
