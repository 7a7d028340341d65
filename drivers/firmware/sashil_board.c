/* The interface board's logic, protocol v2: see sashil_board.h. */
#include "sashil_board.h"

enum { T_SAMPLE = 1, T_COMMAND = 2, T_ROAD_SPEED = 3, T_STATUS = 4, T_HELLO = 5, T_VERSION = 6, T_CONFIGURE = 7 };

static void put16(uint8_t *p, uint16_t v) { p[0] = (uint8_t)v; p[1] = (uint8_t)(v >> 8); }
static void put32(uint8_t *p, uint32_t v) { put16(p, (uint16_t)v); put16(p + 2, (uint16_t)(v >> 16)); }
static uint16_t get16(const uint8_t *p) { return (uint16_t)(p[0] | ((uint16_t)p[1] << 8)); }
static uint32_t get32(const uint8_t *p) { return (uint32_t)get16(p) | ((uint32_t)get16(p + 2) << 16); }

/* A message as the DBC's CAN frames: the payloads are the serial ones, but for the Sample (split in
 * SampleA: arm, road; SampleEdges: the two edge ages and directions; SampleB: seq, 24-bit device
 * time, current, flags) and the Command (seq first). */
static void emit_can(sashil_board *b, uint8_t type, uint16_t seq, const uint8_t *p, uint8_t len)
{
    uint8_t d[8];
    switch (type) {
    case T_SAMPLE:
        b->hal.send_can(b->hal.ctx, SASHIL_CAN_SAMPLE_A, p + 4, 8);
        b->hal.send_can(b->hal.ctx, SASHIL_CAN_SAMPLE_EDGES, p + 15, 5);
        put16(d, seq);
        d[2] = p[0];
        d[3] = p[1];
        d[4] = p[2]; /* device time, low 24 bits */
        d[5] = p[12];
        d[6] = p[13];
        d[7] = p[14];
        b->hal.send_can(b->hal.ctx, SASHIL_CAN_SAMPLE_B, d, 8);
        break;
    case T_STATUS:
        b->hal.send_can(b->hal.ctx, SASHIL_CAN_STATUS, p, len);
        break;
    case T_VERSION:
        b->hal.send_can(b->hal.ctx, SASHIL_CAN_VERSION, p, len);
        break;
    default:
        break; /* the board sends nothing else */
    }
}

static void emit(sashil_board *b, uint8_t type, uint16_t seq, const uint8_t *payload, uint8_t len)
{
    uint8_t frame[SASHIL_MAX_FRAME];
    if (b->link == SASHIL_LINK_CAN && b->hal.send_can != NULL) {
        emit_can(b, type, seq, payload, len);
        return;
    }
    /* the serial link, or a CAN link on a HAL without send_can: then the board's only way to answer
     * (the Status refusing the CAN session) is its serial transmitter, if it has one */
    size_t n = sashil_frame_encode(type, seq, payload, len, frame, sizeof frame);
    if (n > 0 && b->hal.send != NULL) {
        b->hal.send(b->hal.ctx, frame, n);
    }
}

static uint8_t board_flags(const sashil_board *b) { return b->watchdog_tripped ? SASHIL_FLAG_WATCHDOG : 0u; }

static void reply_status(sashil_board *b, uint8_t fault)
{
    uint8_t p[6];
    p[0] = (uint8_t)(board_flags(b) | b->status_flags);
    p[1] = fault;
    put16(p + 2, (uint16_t)sashil_board_bad_frames(b));
    put16(p + 4, b->watchdog_trips);
    emit(b, T_STATUS, ++b->tx_seq, p, sizeof p);
}

static void set_drive(sashil_board *b, uint16_t counts)
{
    if (counts > b->current_max_counts) {
        counts = b->current_max_counts;
    }
    b->drive_counts = counts;
    b->hal.set_coil(b->hal.ctx, counts);
}

static void set_road(sashil_board *b, int32_t urad_s)
{
    b->road_urad_s = urad_s;
    b->hal.set_road_speed(b->hal.ctx, urad_s);
}

/* Microseconds from an edge to the sample, as the wire's u16: SASHIL_EDGE_AGE_NONE for no edge or
 * one 65.535 ms old or more; an edge the capture stamped after the sample's clock reading (it
 * happened while the sample was taken) counts as age 0. Modular 32-bit arithmetic: the clock wraps. */
static uint16_t edge_age(const sashil_edge *edge, uint64_t now_us)
{
    if (edge->dir == 0) {
        return SASHIL_EDGE_AGE_NONE;
    }
    uint32_t age = (uint32_t)now_us - edge->time_us;
    if (age >= 0x80000000u) {
        return 0u;
    }
    return age < SASHIL_EDGE_AGE_NONE ? (uint16_t)age : (uint16_t)SASHIL_EDGE_AGE_NONE;
}

static void send_sample(sashil_board *b, uint64_t now_us)
{
    uint8_t p[20];
    int32_t arm = 0, road = 0;
    sashil_edge arm_edge = {0u, 0}, road_edge = {0u, 0};
    b->hal.read_encoders(b->hal.ctx, &arm, &road);
    if (b->hal.read_edges != NULL) {
        b->hal.read_edges(b->hal.ctx, &arm_edge, &road_edge);
    }
    put32(p, (uint32_t)(now_us - b->boot_us)); /* the device clock, wraps at 2^32 us */
    put32(p + 4, (uint32_t)arm);
    put32(p + 8, (uint32_t)road);
    put16(p + 12, (uint16_t)b->hal.read_current(b->hal.ctx));
    p[14] = (uint8_t)(b->hal.sensor_flags(b->hal.ctx) | board_flags(b));
    put16(p + 15, edge_age(&arm_edge, now_us));
    put16(p + 17, edge_age(&road_edge, now_us));
    p[19] = (uint8_t)((arm_edge.dir > 0 ? SASHIL_EDGE_ARM_UP : 0u) | (road_edge.dir > 0 ? SASHIL_EDGE_ROAD_UP : 0u));
    emit(b, T_SAMPLE, ++b->sample_seq, p, sizeof p);
}

static void configure(sashil_board *b, const uint8_t *p, uint64_t now_us)
{
    uint16_t rate = get16(p), watchdog = get16(p + 2);
    uint8_t pacing = p[4];
    int rate_ok = rate >= 1u && rate <= b->max_rate_hz && (b->fixed_rate_hz == 0u || rate == b->fixed_rate_hz);
    uint8_t fault = SASHIL_FAULT_NONE;
    if (!rate_ok || watchdog < 1u || pacing > SASHIL_PACING_HOST) {
        fault = SASHIL_FAULT_BAD_CONFIGURE;
    } else if (b->link == SASHIL_LINK_CAN && b->hal.send_can == NULL) {
        fault = SASHIL_FAULT_NO_CAN; /* the session could never send a sample */
    }
    if (fault != SASHIL_FAULT_NONE) { /* refused: the session, if any, goes on as it was */
        b->refusals++;
        reply_status(b, fault);
        return;
    }
    b->rate_hz = rate;
    b->watchdog_ms = watchdog;
    b->pacing = pacing;
    b->configured = 1;
    b->sessions++;
    b->next_sample_us = now_us;
    b->period_rem = 0u;
    set_drive(b, 0);
    b->commanded = 0;
    b->watchdog_tripped = 0;
    reply_status(b, SASHIL_FAULT_NONE);
}

static void handle(sashil_board *b, uint8_t type, const uint8_t *p, uint64_t now_us)
{
    switch (type) {
    case T_HELLO: {
        uint8_t v[7];
        v[0] = SASHIL_PROTOCOL_VERSION;
        put32(v + 1, b->counts_per_rev);
        put16(v + 5, b->current_max_counts);
        emit(b, T_VERSION, ++b->tx_seq, v, sizeof v);
        break;
    }
    case T_CONFIGURE:
        configure(b, p, now_us);
        break;
    case T_COMMAND:
        if (!b->configured) {
            break; /* a Command before Configure drives nothing */
        }
        b->last_cmd_us = now_us;
        b->commanded = 1;
        b->watchdog_tripped = 0;
        set_drive(b, (p[2] & 0x01u) ? get16(p) : 0u);
        if (b->pacing == SASHIL_PACING_HOST) {
            send_sample(b, now_us);
        }
        break;
    case T_ROAD_SPEED:
        set_road(b, (int32_t)get32(p));
        break;
    default:
        break; /* device-to-host messages coming back: ignored */
    }
}

void sashil_board_init(sashil_board *b, const sashil_hal *hal, uint32_t counts_per_rev, uint16_t current_max_counts,
                       uint16_t fixed_rate_hz)
{
    sashil_board zero = {0};
    *b = zero;
    b->hal = *hal;
    b->counts_per_rev = counts_per_rev;
    b->current_max_counts = current_max_counts;
    b->fixed_rate_hz = fixed_rate_hz;
    b->max_rate_hz = SASHIL_MAX_RATE_HZ;
    b->rate_hz = 1000;
    b->watchdog_ms = 50;
    sashil_stream_init(&b->rx);
}

static void boot(sashil_board *b, uint64_t now_us)
{
    if (!b->booted) {
        b->booted = 1;
        b->boot_us = now_us;
    }
}

void sashil_board_receive(sashil_board *b, const uint8_t *bytes, size_t n, uint64_t now_us)
{
    uint8_t type = 0, len = 0, payload[SASHIL_MAX_PAYLOAD];
    uint16_t seq = 0;
    boot(b, now_us);
    for (size_t i = 0; i < n; i++) {
        if (sashil_stream_feed(&b->rx, bytes[i], &type, &seq, payload, &len) == 1) {
            handle(b, type, payload, now_us);
        }
    }
}

/* The next sample 1e6/rate_hz us on: the whole microseconds, plus the remainder carried in units of
 * 1/rate_hz us, so the period is exact on average and a sample is never more than 1 us off the
 * ideal grid (1e6/3000 = 333 us + 1/3 us: 3000 Hz and not 3003 Hz). */
static void next_sample_time(sashil_board *b)
{
    b->next_sample_us += 1000000u / b->rate_hz;
    b->period_rem += 1000000u % b->rate_hz;
    if (b->period_rem >= b->rate_hz) {
        b->period_rem -= b->rate_hz;
        b->next_sample_us++;
    }
}

void sashil_board_tick(sashil_board *b, uint64_t now_us)
{
    boot(b, now_us);
    if (b->commanded && !b->watchdog_tripped && now_us - b->last_cmd_us >= (uint64_t)b->watchdog_ms * 1000u) {
        b->watchdog_tripped = 1;
        b->watchdog_trips++;
        set_drive(b, 0);
        if (b->road_urad_s != 0) {
            set_road(b, 0); /* coil and road to rest */
        }
        reply_status(b, SASHIL_FAULT_NONE);
    }
    if (b->configured && b->pacing == SASHIL_PACING_DEVICE && now_us >= b->next_sample_us) {
        send_sample(b, now_us);
        next_sample_time(b);
        if (b->next_sample_us <= now_us) { /* fell behind by a whole period: do not burst */
            b->overruns++;
            b->next_sample_us = now_us;
            next_sample_time(b);
        }
    }
}

void sashil_board_set_link(sashil_board *b, uint8_t link) { b->link = link; }

void sashil_board_set_max_rate(sashil_board *b, uint16_t max_rate_hz)
{
    b->max_rate_hz = max_rate_hz >= 1u && max_rate_hz <= SASHIL_MAX_RATE_HZ ? max_rate_hz : SASHIL_MAX_RATE_HZ;
}

void sashil_board_receive_can(sashil_board *b, uint16_t id, const uint8_t *data, uint8_t len, uint64_t now_us)
{
    uint8_t type, want;
    boot(b, now_us);
    switch (id) {
    case SASHIL_CAN_COMMAND:
        type = T_COMMAND, want = 5;
        break;
    case SASHIL_CAN_ROAD_SPEED:
        type = T_ROAD_SPEED, want = 4;
        break;
    case SASHIL_CAN_CONFIGURE:
        type = T_CONFIGURE, want = 5;
        break;
    case SASHIL_CAN_HELLO:
        type = T_HELLO, want = 1;
        break;
    default:
        return; /* another node's frame, or the board's own ids */
    }
    if (len != want) {
        b->can_bad_frames++;
        return;
    }
    /* a CAN Command carries its sequence number first; the rest are the serial payloads */
    handle(b, type, type == T_COMMAND ? data + 2 : data, now_us);
}

uint64_t sashil_board_next_event_us(const sashil_board *b)
{
    uint64_t next = UINT64_MAX;
    if (b->configured && b->pacing == SASHIL_PACING_DEVICE) {
        next = b->next_sample_us;
    }
    if (b->commanded && !b->watchdog_tripped) {
        uint64_t deadline = b->last_cmd_us + (uint64_t)b->watchdog_ms * 1000u;
        next = deadline < next ? deadline : next;
    }
    return next;
}

uint16_t sashil_board_sessions(const sashil_board *b) { return b->sessions; }

uint16_t sashil_board_refusals(const sashil_board *b) { return b->refusals; }

void sashil_board_set_status_flags(sashil_board *b, uint8_t flags) { b->status_flags = flags; }

uint16_t sashil_board_watchdog_trips(const sashil_board *b) { return b->watchdog_trips; }

uint32_t sashil_board_overruns(const sashil_board *b) { return b->overruns; }

uint32_t sashil_board_bad_frames(const sashil_board *b) { return b->rx.bad_frames + b->can_bad_frames; }

size_t sashil_board_size(void) { return sizeof(sashil_board); }
