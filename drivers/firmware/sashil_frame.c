/* sashil rig protocol v2, serial framing: see sashil_frame.h. */
#include "sashil_frame.h"

uint16_t sashil_crc16(const uint8_t *data, size_t n)
{
    uint16_t crc = 0xFFFFu;
    for (size_t i = 0; i < n; i++) {
        crc ^= (uint16_t)((uint16_t)data[i] << 8);
        for (int bit = 0; bit < 8; bit++) {
            crc = (crc & 0x8000u) ? (uint16_t)((crc << 1) ^ 0x1021u) : (uint16_t)(crc << 1);
        }
    }
    return crc;
}

size_t sashil_cobs_encode(const uint8_t *in, size_t n, uint8_t *out, size_t cap)
{
    size_t code_at = 0, o = 1;
    uint8_t code = 1;
    int full = 0; /* the last block was a full 254-byte run (code 0xFF, no implied zero) */
    if (cap == 0) {
        return 0;
    }
    for (size_t i = 0; i < n; i++) {
        full = 0;
        if (in[i] == 0) {
            out[code_at] = code;
            code_at = o++;
            code = 1;
        } else {
            if (o >= cap) {
                return 0;
            }
            out[o++] = in[i];
            code++;
            if (code == 0xFFu) {
                out[code_at] = code;
                code_at = o++;
                code = 1;
                full = 1;
            }
        }
        if (o > cap) {
            return 0;
        }
    }
    if (full) {
        return o - 1; /* no block after a full run */
    }
    if (code_at >= cap) {
        return 0;
    }
    out[code_at] = code;
    return o;
}

int sashil_cobs_decode(const uint8_t *in, size_t n, uint8_t *out, size_t cap, size_t *out_len)
{
    size_t i = 0, o = 0;
    while (i < n) {
        uint8_t code = in[i];
        if (code == 0) {
            return SASHIL_FRAME_COBS;
        }
        size_t end = i + code;
        if (end > n) {
            return SASHIL_FRAME_COBS;
        }
        for (size_t j = i + 1; j < end; j++) {
            if (in[j] == 0) {
                return SASHIL_FRAME_COBS;
            }
            if (o >= cap) {
                return SASHIL_FRAME_LENGTH;
            }
            out[o++] = in[j];
        }
        i = end;
        if (code != 0xFFu && i < n) {
            if (o >= cap) {
                return SASHIL_FRAME_LENGTH;
            }
            out[o++] = 0;
        }
    }
    *out_len = o;
    return SASHIL_FRAME_OK;
}

int sashil_payload_size(uint8_t type)
{
    switch (type) {
    case 0x01: return 20; /* Sample */
    case 0x02: return 3;  /* Command */
    case 0x03: return 4;  /* RoadSpeed */
    case 0x04: return 6;  /* Status */
    case 0x05: return 1;  /* Hello */
    case 0x06: return 7;  /* Version */
    case 0x07: return 5;  /* Configure */
    default: return -1;
    }
}

size_t sashil_frame_encode(uint8_t type, uint16_t seq, const uint8_t *payload, uint8_t len, uint8_t *out,
                           size_t cap)
{
    uint8_t body[SASHIL_HEADER_SIZE + SASHIL_MAX_PAYLOAD + SASHIL_CRC_SIZE];
    if (len > SASHIL_MAX_PAYLOAD) {
        return 0;
    }
    body[0] = type;
    body[1] = (uint8_t)(seq & 0xFFu);
    body[2] = (uint8_t)(seq >> 8);
    body[3] = len;
    for (size_t i = 0; i < len; i++) {
        body[SASHIL_HEADER_SIZE + i] = payload[i];
    }
    size_t n = SASHIL_HEADER_SIZE + len;
    uint16_t crc = sashil_crc16(body, n);
    body[n++] = (uint8_t)(crc & 0xFFu);
    body[n++] = (uint8_t)(crc >> 8);
    if (cap == 0) {
        return 0;
    }
    size_t m = sashil_cobs_encode(body, n, out, cap - 1);
    if (m == 0) {
        return 0;
    }
    out[m] = 0;
    return m + 1;
}

int sashil_frame_decode(const uint8_t *cobs, size_t n, uint8_t *type, uint16_t *seq, uint8_t *payload,
                        uint8_t *len)
{
    uint8_t body[SASHIL_MAX_FRAME];
    size_t m = 0;
    int rc = sashil_cobs_decode(cobs, n, body, sizeof body, &m);
    if (rc != SASHIL_FRAME_OK) {
        return rc;
    }
    if (m < SASHIL_HEADER_SIZE + SASHIL_CRC_SIZE) {
        return SASHIL_FRAME_LENGTH;
    }
    uint16_t crc = (uint16_t)(body[m - 2] | ((uint16_t)body[m - 1] << 8));
    if (sashil_crc16(body, m - SASHIL_CRC_SIZE) != crc) {
        return SASHIL_FRAME_CRC;
    }
    size_t payload_len = m - SASHIL_HEADER_SIZE - SASHIL_CRC_SIZE;
    if (body[3] != payload_len || payload_len > SASHIL_MAX_PAYLOAD) {
        return SASHIL_FRAME_LENGTH;
    }
    int expected = sashil_payload_size(body[0]);
    if (expected < 0) {
        return SASHIL_FRAME_UNKNOWN_TYPE;
    }
    if ((size_t)expected != payload_len) {
        return SASHIL_FRAME_LENGTH;
    }
    *type = body[0];
    *seq = (uint16_t)(body[1] | ((uint16_t)body[2] << 8));
    *len = (uint8_t)payload_len;
    for (size_t i = 0; i < payload_len; i++) {
        payload[i] = body[SASHIL_HEADER_SIZE + i];
    }
    return SASHIL_FRAME_OK;
}

void sashil_stream_init(sashil_stream *s)
{
    s->n = 0;
    s->skipping = 0;
    s->frames = 0;
    s->bad_frames = 0;
}

int sashil_stream_feed(sashil_stream *s, uint8_t byte, uint8_t *type, uint16_t *seq, uint8_t *payload,
                       uint8_t *len)
{
    if (byte != 0) {
        if (s->skipping) {
            return 0;
        }
        if (s->n >= sizeof s->buf) { /* overlong: count it once, drop up to the next delimiter */
            s->skipping = 1;
            s->n = 0;
            s->bad_frames++;
            return SASHIL_FRAME_OVERFLOW;
        }
        s->buf[s->n++] = byte;
        return 0;
    }
    if (s->skipping) {
        s->skipping = 0;
        s->n = 0;
        return 0;
    }
    if (s->n == 0) {
        return 0; /* idle delimiters between frames */
    }
    int rc = sashil_frame_decode(s->buf, s->n, type, seq, payload, len);
    s->n = 0;
    if (rc == SASHIL_FRAME_OK) {
        s->frames++;
        return 1;
    }
    s->bad_frames++;
    return rc;
}
