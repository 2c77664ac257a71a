/*
 * fwp.c - payload codec, CRC-32, COBS and the serial stream decoder (see fwp.h and ../SPEC.md).
 */
#include "fwp.h"

#include <math.h>
#include <string.h>

const char *const fwp_error_names[FWP_E_COUNT] = {
    "oversize", "bad_framing", "bad_length", "bad_header", "unknown_id", "bad_crc", "bad_value",
    "wrong_direction", "duplicate", "stale", "seq_gap", "seq_restart", "foreign", "error_frame", "bad_transfer",
};

/* Seeds are CRC-32 of each message's line of the schema text (firmware_protocol/schema.py). */
static const fwp_msg_info_t MSG_INFO[] = {
    {0x01, 'h', 0x27c62abfu, "ESTOP"},
    {0x02, 'b', 0xd6345f42u, "FAULT"},
    {0x08, 'h', 0x9edb127fu, "SET_GOALS"},
    {0x09, 'b', 0x9e7cdd8du, "JOINT_STATE"},
    {0x0a, 'b', 0xc4e4a50au, "IMU"},
    {0x0b, 'b', 0xaed09659u, "FOOT_SENSORS"},
    {0x10, 'h', 0x25380758u, "TORQUE"},
    {0x11, 'h', 0xa5328940u, "WATCHDOG"},
    {0x12, 'h', 0x1570bb30u, "STREAM_RATES"},
    {0x18, '*', 0x62bd81f6u, "ACK"},
    {0x19, '*', 0xe4aed0d5u, "NACK"},
    {0x1a, 'b', 0xfc86c88bu, "STATUS"},
    {0x1b, '*', 0x6ed87247u, "HEARTBEAT"},
    {0x20, 'h', 0x86d68b20u, "HELLO"},
    {0x21, 'b', 0x622b8bfbu, "HELLO_ACK"},
};

/* CRC-32/ISO-HDLC (reflected polynomial 0xEDB88320), one entry per byte value. */
static const uint32_t CRC_TABLE[256] = {
    0x00000000u, 0x77073096u, 0xee0e612cu, 0x990951bau, 0x076dc419u, 0x706af48fu,
    0xe963a535u, 0x9e6495a3u, 0x0edb8832u, 0x79dcb8a4u, 0xe0d5e91eu, 0x97d2d988u,
    0x09b64c2bu, 0x7eb17cbdu, 0xe7b82d07u, 0x90bf1d91u, 0x1db71064u, 0x6ab020f2u,
    0xf3b97148u, 0x84be41deu, 0x1adad47du, 0x6ddde4ebu, 0xf4d4b551u, 0x83d385c7u,
    0x136c9856u, 0x646ba8c0u, 0xfd62f97au, 0x8a65c9ecu, 0x14015c4fu, 0x63066cd9u,
    0xfa0f3d63u, 0x8d080df5u, 0x3b6e20c8u, 0x4c69105eu, 0xd56041e4u, 0xa2677172u,
    0x3c03e4d1u, 0x4b04d447u, 0xd20d85fdu, 0xa50ab56bu, 0x35b5a8fau, 0x42b2986cu,
    0xdbbbc9d6u, 0xacbcf940u, 0x32d86ce3u, 0x45df5c75u, 0xdcd60dcfu, 0xabd13d59u,
    0x26d930acu, 0x51de003au, 0xc8d75180u, 0xbfd06116u, 0x21b4f4b5u, 0x56b3c423u,
    0xcfba9599u, 0xb8bda50fu, 0x2802b89eu, 0x5f058808u, 0xc60cd9b2u, 0xb10be924u,
    0x2f6f7c87u, 0x58684c11u, 0xc1611dabu, 0xb6662d3du, 0x76dc4190u, 0x01db7106u,
    0x98d220bcu, 0xefd5102au, 0x71b18589u, 0x06b6b51fu, 0x9fbfe4a5u, 0xe8b8d433u,
    0x7807c9a2u, 0x0f00f934u, 0x9609a88eu, 0xe10e9818u, 0x7f6a0dbbu, 0x086d3d2du,
    0x91646c97u, 0xe6635c01u, 0x6b6b51f4u, 0x1c6c6162u, 0x856530d8u, 0xf262004eu,
    0x6c0695edu, 0x1b01a57bu, 0x8208f4c1u, 0xf50fc457u, 0x65b0d9c6u, 0x12b7e950u,
    0x8bbeb8eau, 0xfcb9887cu, 0x62dd1ddfu, 0x15da2d49u, 0x8cd37cf3u, 0xfbd44c65u,
    0x4db26158u, 0x3ab551ceu, 0xa3bc0074u, 0xd4bb30e2u, 0x4adfa541u, 0x3dd895d7u,
    0xa4d1c46du, 0xd3d6f4fbu, 0x4369e96au, 0x346ed9fcu, 0xad678846u, 0xda60b8d0u,
    0x44042d73u, 0x33031de5u, 0xaa0a4c5fu, 0xdd0d7cc9u, 0x5005713cu, 0x270241aau,
    0xbe0b1010u, 0xc90c2086u, 0x5768b525u, 0x206f85b3u, 0xb966d409u, 0xce61e49fu,
    0x5edef90eu, 0x29d9c998u, 0xb0d09822u, 0xc7d7a8b4u, 0x59b33d17u, 0x2eb40d81u,
    0xb7bd5c3bu, 0xc0ba6cadu, 0xedb88320u, 0x9abfb3b6u, 0x03b6e20cu, 0x74b1d29au,
    0xead54739u, 0x9dd277afu, 0x04db2615u, 0x73dc1683u, 0xe3630b12u, 0x94643b84u,
    0x0d6d6a3eu, 0x7a6a5aa8u, 0xe40ecf0bu, 0x9309ff9du, 0x0a00ae27u, 0x7d079eb1u,
    0xf00f9344u, 0x8708a3d2u, 0x1e01f268u, 0x6906c2feu, 0xf762575du, 0x806567cbu,
    0x196c3671u, 0x6e6b06e7u, 0xfed41b76u, 0x89d32be0u, 0x10da7a5au, 0x67dd4accu,
    0xf9b9df6fu, 0x8ebeeff9u, 0x17b7be43u, 0x60b08ed5u, 0xd6d6a3e8u, 0xa1d1937eu,
    0x38d8c2c4u, 0x4fdff252u, 0xd1bb67f1u, 0xa6bc5767u, 0x3fb506ddu, 0x48b2364bu,
    0xd80d2bdau, 0xaf0a1b4cu, 0x36034af6u, 0x41047a60u, 0xdf60efc3u, 0xa867df55u,
    0x316e8eefu, 0x4669be79u, 0xcb61b38cu, 0xbc66831au, 0x256fd2a0u, 0x5268e236u,
    0xcc0c7795u, 0xbb0b4703u, 0x220216b9u, 0x5505262fu, 0xc5ba3bbeu, 0xb2bd0b28u,
    0x2bb45a92u, 0x5cb36a04u, 0xc2d7ffa7u, 0xb5d0cf31u, 0x2cd99e8bu, 0x5bdeae1du,
    0x9b64c2b0u, 0xec63f226u, 0x756aa39cu, 0x026d930au, 0x9c0906a9u, 0xeb0e363fu,
    0x72076785u, 0x05005713u, 0x95bf4a82u, 0xe2b87a14u, 0x7bb12baeu, 0x0cb61b38u,
    0x92d28e9bu, 0xe5d5be0du, 0x7cdcefb7u, 0x0bdbdf21u, 0x86d3d2d4u, 0xf1d4e242u,
    0x68ddb3f8u, 0x1fda836eu, 0x81be16cdu, 0xf6b9265bu, 0x6fb077e1u, 0x18b74777u,
    0x88085ae6u, 0xff0f6a70u, 0x66063bcau, 0x11010b5cu, 0x8f659effu, 0xf862ae69u,
    0x616bffd3u, 0x166ccf45u, 0xa00ae278u, 0xd70dd2eeu, 0x4e048354u, 0x3903b3c2u,
    0xa7672661u, 0xd06016f7u, 0x4969474du, 0x3e6e77dbu, 0xaed16a4au, 0xd9d65adcu,
    0x40df0b66u, 0x37d83bf0u, 0xa9bcae53u, 0xdebb9ec5u, 0x47b2cf7fu, 0x30b5ffe9u,
    0xbdbdf21cu, 0xcabac28au, 0x53b39330u, 0x24b4a3a6u, 0xbad03605u, 0xcdd70693u,
    0x54de5729u, 0x23d967bfu, 0xb3667a2eu, 0xc4614ab8u, 0x5d681b02u, 0x2a6f2b94u,
    0xb40bbe37u, 0xc30c8ea1u, 0x5a05df1bu, 0x2d02ef8du,
};

const fwp_msg_info_t *fwp_msg_info(uint8_t msg_id)
{
    size_t i;
    for (i = 0; i < sizeof MSG_INFO / sizeof MSG_INFO[0]; i++)
        if (MSG_INFO[i].msg_id == msg_id) return &MSG_INFO[i];
    return NULL;
}

uint32_t fwp_crc32(uint32_t crc, const uint8_t *data, size_t n)
{
    crc = ~crc;
    while (n--) crc = CRC_TABLE[(crc ^ *data++) & 0xFFu] ^ (crc >> 8);
    return ~crc;
}

uint32_t fwp_seeded_crc(uint32_t seed, const uint8_t *data, size_t n)
{
    uint8_t s[4];
    s[0] = (uint8_t)seed; s[1] = (uint8_t)(seed >> 8); s[2] = (uint8_t)(seed >> 16); s[3] = (uint8_t)(seed >> 24);
    return fwp_crc32(fwp_crc32(0, data, n), s, 4);
}

/* ---- little-endian writer / reader ---------------------------------------------------------- */

typedef struct { uint8_t *p; size_t n, cap; int err; } wbuf_t;

static void put8(wbuf_t *w, uint8_t v)
{
    if (w->n >= w->cap) { w->err = 1; return; }
    w->p[w->n++] = v;
}
static void put16(wbuf_t *w, uint16_t v) { put8(w, (uint8_t)v); put8(w, (uint8_t)(v >> 8)); }
static void put32(wbuf_t *w, uint32_t v) { put16(w, (uint16_t)v); put16(w, (uint16_t)(v >> 16)); }
static void put64(wbuf_t *w, uint64_t v) { put32(w, (uint32_t)v); put32(w, (uint32_t)(v >> 32)); }
static void putf(wbuf_t *w, float f)
{
    uint32_t v;
    if (!isfinite(f)) w->err = 1;
    memcpy(&v, &f, 4);
    put32(w, v);
}

static uint8_t get8(const uint8_t **p) { return *(*p)++; }
static uint16_t get16(const uint8_t **p) { uint16_t v = (uint16_t)((*p)[0] | (*p)[1] << 8); *p += 2; return v; }
static uint32_t get32(const uint8_t **p)
{
    uint32_t v = (uint32_t)(*p)[0] | (uint32_t)(*p)[1] << 8 | (uint32_t)(*p)[2] << 16 | (uint32_t)(*p)[3] << 24;
    *p += 4;
    return v;
}
static uint64_t get64(const uint8_t **p) { uint64_t lo = get32(p); return lo | (uint64_t)get32(p) << 32; }
/* Reads a float32; clears *ok if it is not finite (the decoder rejects NaN and infinities). */
static float getf(const uint8_t **p, int *ok)
{
    uint32_t v = get32(p);
    float f;
    memcpy(&f, &v, 4);
    if (!isfinite(f)) *ok = 0;
    return f;
}

static int unique_ids(const uint8_t *ids, unsigned n)
{
    uint8_t seen[32] = {0};
    unsigned i;
    for (i = 0; i < n; i++) {
        if (seen[ids[i] >> 3] & (1u << (ids[i] & 7))) return 0;
        seen[ids[i] >> 3] |= (uint8_t)(1u << (ids[i] & 7));
    }
    return 1;
}

static int name_ok(const char *s, size_t n)
{
    size_t i;
    if (n < 1 || n > FWP_MAX_NAME) return 0;
    for (i = 0; i < n; i++)
        if ((unsigned char)s[i] < 0x20 || (unsigned char)s[i] > 0x7e) return 0;
    return 1;
}

/* ---- payload encoder ------------------------------------------------------------------------ */

int fwp_encode_payload(const fwp_msg_t *m, uint8_t *out, size_t cap)
{
    wbuf_t w;
    unsigned i, k;
    w.p = out; w.n = 0; w.cap = cap; w.err = 0;
    switch (m->msg_id) {
    case FWP_ESTOP:
        if (m->u.estop.engage > 1) return -1;
        put8(&w, m->u.estop.engage);
        break;
    case FWP_FAULT: {
        const fwp_fault_t *f = &m->u.fault;
        if (f->code < 1 || f->code > 8) return -1;
        put32(&w, f->board_time_us); put16(&w, f->code); put8(&w, f->joint_id); putf(&w, f->value);
        break;
    }
    case FWP_SET_GOALS: {
        const fwp_set_goals_t *g = &m->u.set_goals;
        if (g->count > FWP_MAX_JOINTS || !unique_ids(g->ids, g->count)) return -1;
        put16(&w, g->cmd_seq); put8(&w, g->count);
        for (i = 0; i < g->count; i++) { put8(&w, g->ids[i]); putf(&w, g->position[i]); }
        break;
    }
    case FWP_JOINT_STATE: {
        const fwp_joint_state_t *j = &m->u.joint_state;
        if (j->count > FWP_MAX_JOINTS || !unique_ids(j->ids, j->count)) return -1;
        put32(&w, j->board_time_us); put8(&w, j->count);
        for (i = 0; i < j->count; i++) {
            put8(&w, j->ids[i]); putf(&w, j->position[i]); putf(&w, j->velocity[i]); putf(&w, j->current[i]);
            put16(&w, j->error[i]);
        }
        break;
    }
    case FWP_IMU: {
        const fwp_imu_t *u = &m->u.imu;
        put32(&w, u->board_time_us);
        for (k = 0; k < 4; k++) putf(&w, u->orientation[k]);
        for (k = 0; k < 3; k++) putf(&w, u->angular_velocity[k]);
        for (k = 0; k < 3; k++) putf(&w, u->acceleration[k]);
        break;
    }
    case FWP_FOOT_SENSORS: {
        const fwp_foot_sensors_t *f = &m->u.foot_sensors;
        if (f->count > FWP_MAX_FEET || !unique_ids(f->foot_ids, f->count)) return -1;
        put32(&w, f->board_time_us); put8(&w, f->count);
        for (i = 0; i < f->count; i++) {
            put8(&w, f->foot_ids[i]);
            for (k = 0; k < 4; k++) putf(&w, f->force[i][k]);
            putf(&w, f->cop_x[i]); putf(&w, f->cop_y[i]);
        }
        break;
    }
    case FWP_TORQUE: {
        const fwp_torque_t *t = &m->u.torque;
        if (t->count > FWP_MAX_JOINTS || !unique_ids(t->ids, t->count)) return -1;
        put8(&w, t->count);
        for (i = 0; i < t->count; i++) {
            if (t->enable[i] > 1) return -1;
            put8(&w, t->ids[i]); put8(&w, t->enable[i]);
        }
        break;
    }
    case FWP_WATCHDOG:
        if (m->u.watchdog.action > FWP_DROP_TORQUE) return -1;
        put16(&w, m->u.watchdog.timeout_ms); put8(&w, m->u.watchdog.action);
        break;
    case FWP_STREAM_RATES: {
        const fwp_stream_rates_t *r = &m->u.stream_rates;
        put16(&w, r->joint_state_hz); put16(&w, r->foot_sensors_hz); put16(&w, r->imu_hz); put16(&w, r->heartbeat_hz);
        break;
    }
    case FWP_ACK:
        put8(&w, m->u.ack.ref_msg_id); put16(&w, m->u.ack.ref_seq);
        break;
    case FWP_NACK:
        if (m->u.nack.code < 1 || m->u.nack.code > 6) return -1;
        put8(&w, m->u.nack.ref_msg_id); put16(&w, m->u.nack.ref_seq); put8(&w, m->u.nack.code);
        break;
    case FWP_STATUS: {
        const fwp_status_t *s = &m->u.status;
        if (s->state > FWP_STATE_ESTOP || s->watchdog_action > FWP_DROP_TORQUE) return -1;
        put8(&w, s->state); put8(&w, s->watchdog_action); put16(&w, s->watchdog_timeout_ms);
        put32(&w, s->torque_mask); put16(&w, s->last_cmd_seq); putf(&w, s->supply_voltage); put16(&w, s->rx_errors);
        break;
    }
    case FWP_HEARTBEAT:
        if (m->u.heartbeat.state > FWP_STATE_ESTOP) return -1;
        put32(&w, m->u.heartbeat.uptime_ms); put8(&w, m->u.heartbeat.state);
        break;
    case FWP_HELLO:
        put64(&w, m->u.hello.schema_hash);
        break;
    case FWP_HELLO_ACK: {
        const fwp_hello_ack_t *h = &m->u.hello_ack;
        if (h->count > FWP_MAX_JOINTS || !unique_ids(h->joint_ids, h->count)) return -1;
        put64(&w, h->schema_hash); put32(&w, h->device_id); put32(&w, h->firmware_version);
        put32(&w, h->capabilities); put8(&w, h->count);
        for (i = 0; i < h->count; i++) {
            size_t n = strlen(h->joint_names[i]);
            if (!name_ok(h->joint_names[i], n)) return -1;
            put8(&w, h->joint_ids[i]); put8(&w, (uint8_t)n);
            for (k = 0; k < n; k++) put8(&w, (uint8_t)h->joint_names[i][k]);
        }
        break;
    }
    default:
        return -1;
    }
    return w.err ? -1 : (int)w.n;
}

/* ---- payload decoder ------------------------------------------------------------------------ */

#define BAD_LENGTH (-(int)FWP_E_BAD_LENGTH)
#define BAD_VALUE (-(int)FWP_E_BAD_VALUE)

/* Checks a counted message's size: head bytes, then count records of rec bytes (count byte at head - 1). */
static int group_size(const uint8_t *p, size_t n, size_t head, size_t rec, unsigned max, unsigned *count)
{
    if (n < head) return BAD_LENGTH;
    *count = p[head - 1];
    if (*count > max) return BAD_LENGTH;
    if (n != head + rec * *count) return BAD_LENGTH;
    return 0;
}

static int decode_hello_ack(const uint8_t *p, size_t n, fwp_hello_ack_t *h)
{
    const uint8_t *q = p, *end = p + n;
    unsigned i, count;
    if (n < 21) return BAD_LENGTH;
    count = p[20];
    if (count > FWP_MAX_JOINTS) return BAD_LENGTH;
    h->schema_hash = get64(&q); h->device_id = get32(&q); h->firmware_version = get32(&q);
    h->capabilities = get32(&q); h->count = get8(&q);
    for (i = 0; i < count; i++) {
        size_t len;
        if (q + 1 > end) return BAD_LENGTH;
        h->joint_ids[i] = get8(&q);
        if (q >= end) return BAD_LENGTH;
        len = get8(&q);
        if ((size_t)(end - q) < len) return BAD_LENGTH;
        if (!name_ok((const char *)q, len)) return BAD_VALUE;
        memcpy(h->joint_names[i], q, len);
        h->joint_names[i][len] = '\0';
        q += len;
    }
    if (q != end) return BAD_LENGTH;
    return unique_ids(h->joint_ids, count) ? 0 : BAD_VALUE;
}

int fwp_decode_payload(uint8_t msg_id, const uint8_t *p, size_t n, fwp_msg_t *out)
{
    const uint8_t *q = p;
    unsigned i, k, count;
    int ok = 1, r;
    out->msg_id = msg_id;
    switch (msg_id) {
    case FWP_ESTOP:
        if (n != 1) return BAD_LENGTH;
        out->u.estop.engage = get8(&q);
        ok = out->u.estop.engage <= 1;
        break;
    case FWP_FAULT: {
        fwp_fault_t *f = &out->u.fault;
        if (n != 11) return BAD_LENGTH;
        f->board_time_us = get32(&q); f->code = get16(&q); f->joint_id = get8(&q); f->value = getf(&q, &ok);
        ok = ok && f->code >= 1 && f->code <= 8;
        break;
    }
    case FWP_SET_GOALS: {
        fwp_set_goals_t *g = &out->u.set_goals;
        if ((r = group_size(p, n, 3, 5, FWP_MAX_JOINTS, &count)) != 0) return r;
        g->cmd_seq = get16(&q); g->count = get8(&q);
        for (i = 0; i < count; i++) { g->ids[i] = get8(&q); g->position[i] = getf(&q, &ok); }
        ok = ok && unique_ids(g->ids, count);
        break;
    }
    case FWP_JOINT_STATE: {
        fwp_joint_state_t *j = &out->u.joint_state;
        if ((r = group_size(p, n, 5, 15, FWP_MAX_JOINTS, &count)) != 0) return r;
        j->board_time_us = get32(&q); j->count = get8(&q);
        for (i = 0; i < count; i++) {
            j->ids[i] = get8(&q); j->position[i] = getf(&q, &ok); j->velocity[i] = getf(&q, &ok);
            j->current[i] = getf(&q, &ok); j->error[i] = get16(&q);
        }
        ok = ok && unique_ids(j->ids, count);
        break;
    }
    case FWP_IMU: {
        fwp_imu_t *u = &out->u.imu;
        if (n != 44) return BAD_LENGTH;
        u->board_time_us = get32(&q);
        for (k = 0; k < 4; k++) u->orientation[k] = getf(&q, &ok);
        for (k = 0; k < 3; k++) u->angular_velocity[k] = getf(&q, &ok);
        for (k = 0; k < 3; k++) u->acceleration[k] = getf(&q, &ok);
        break;
    }
    case FWP_FOOT_SENSORS: {
        fwp_foot_sensors_t *f = &out->u.foot_sensors;
        if ((r = group_size(p, n, 5, 25, FWP_MAX_FEET, &count)) != 0) return r;
        f->board_time_us = get32(&q); f->count = get8(&q);
        for (i = 0; i < count; i++) {
            f->foot_ids[i] = get8(&q);
            for (k = 0; k < 4; k++) f->force[i][k] = getf(&q, &ok);
            f->cop_x[i] = getf(&q, &ok); f->cop_y[i] = getf(&q, &ok);
        }
        ok = ok && unique_ids(f->foot_ids, count);
        break;
    }
    case FWP_TORQUE: {
        fwp_torque_t *t = &out->u.torque;
        if ((r = group_size(p, n, 1, 2, FWP_MAX_JOINTS, &count)) != 0) return r;
        t->count = get8(&q);
        for (i = 0; i < count; i++) {
            t->ids[i] = get8(&q); t->enable[i] = get8(&q);
            ok = ok && t->enable[i] <= 1;
        }
        ok = ok && unique_ids(t->ids, count);
        break;
    }
    case FWP_WATCHDOG:
        if (n != 3) return BAD_LENGTH;
        out->u.watchdog.timeout_ms = get16(&q); out->u.watchdog.action = get8(&q);
        ok = out->u.watchdog.action <= FWP_DROP_TORQUE;
        break;
    case FWP_STREAM_RATES: {
        fwp_stream_rates_t *s = &out->u.stream_rates;
        if (n != 8) return BAD_LENGTH;
        s->joint_state_hz = get16(&q); s->foot_sensors_hz = get16(&q); s->imu_hz = get16(&q);
        s->heartbeat_hz = get16(&q);
        break;
    }
    case FWP_ACK:
        if (n != 3) return BAD_LENGTH;
        out->u.ack.ref_msg_id = get8(&q); out->u.ack.ref_seq = get16(&q);
        break;
    case FWP_NACK:
        if (n != 4) return BAD_LENGTH;
        out->u.nack.ref_msg_id = get8(&q); out->u.nack.ref_seq = get16(&q); out->u.nack.code = get8(&q);
        ok = out->u.nack.code >= 1 && out->u.nack.code <= 6;
        break;
    case FWP_STATUS: {
        fwp_status_t *s = &out->u.status;
        if (n != 16) return BAD_LENGTH;
        s->state = get8(&q); s->watchdog_action = get8(&q); s->watchdog_timeout_ms = get16(&q);
        s->torque_mask = get32(&q); s->last_cmd_seq = get16(&q); s->supply_voltage = getf(&q, &ok);
        s->rx_errors = get16(&q);
        ok = ok && s->state <= FWP_STATE_ESTOP && s->watchdog_action <= FWP_DROP_TORQUE;
        break;
    }
    case FWP_HEARTBEAT:
        if (n != 5) return BAD_LENGTH;
        out->u.heartbeat.uptime_ms = get32(&q); out->u.heartbeat.state = get8(&q);
        ok = out->u.heartbeat.state <= FWP_STATE_ESTOP;
        break;
    case FWP_HELLO:
        if (n != 8) return BAD_LENGTH;
        out->u.hello.schema_hash = get64(&q);
        break;
    case FWP_HELLO_ACK:
        return decode_hello_ack(p, n, &out->u.hello_ack);
    default:
        return -(int)FWP_E_UNKNOWN_ID;
    }
    return ok ? 0 : BAD_VALUE;
}

/* ---- serial frames ------------------------------------------------------------------------ */

/* The canonical COBS encoder: a final run of exactly 254 non-zero bytes gets no empty block after it. */
static size_t cobs_encode(const uint8_t *in, size_t n, uint8_t *out)
{
    size_t code_at = 0, o = 1, i;
    uint8_t code = 1;
    for (i = 0; i < n; i++) {
        if (in[i] == 0) {
            out[code_at] = code; code_at = o++; code = 1;
        } else {
            out[o++] = in[i];
            if (++code == 0xFF) {
                out[code_at] = code; code = 1;
                if (i + 1 == n) return o; /* data ends with a full block */
                code_at = o++;
            }
        }
    }
    out[code_at] = code;
    return o;
}

size_t fwp_encode_frame(const fwp_msg_t *m, uint16_t seq, int from_board, uint8_t *out, size_t cap)
{
    uint8_t raw[FWP_MAX_FRAME];
    const fwp_msg_info_t *info = fwp_msg_info(m->msg_id);
    int len;
    uint32_t crc;
    size_t n;
    if (info == NULL || (info->direction != '*' && (info->direction == 'b') != (from_board != 0))) return 0;
    len = fwp_encode_payload(m, raw + FWP_HEADER_SIZE, FWP_MAX_PAYLOAD);
    if (len < 0) return 0;
    raw[0] = FWP_PROTOCOL_VERSION;
    raw[1] = from_board ? FWP_FLAG_FROM_BOARD : 0;
    raw[2] = m->msg_id;
    raw[3] = (uint8_t)seq; raw[4] = (uint8_t)(seq >> 8);
    raw[5] = (uint8_t)len; raw[6] = (uint8_t)(len >> 8);
    n = FWP_HEADER_SIZE + (size_t)len;
    crc = fwp_seeded_crc(info->seed, raw, n);
    raw[n] = (uint8_t)crc; raw[n + 1] = (uint8_t)(crc >> 8); raw[n + 2] = (uint8_t)(crc >> 16);
    raw[n + 3] = (uint8_t)(crc >> 24);
    n += FWP_CRC_SIZE;
    if (cap < n + n / 254 + 2) return 0;
    n = cobs_encode(raw, n, out);
    out[n++] = 0;
    return n;
}

enum fwp_seq_verdict fwp_seq_classify(fwp_seq_t *s, uint16_t seq, unsigned bits, unsigned behind, uint32_t *lost)
{
    uint32_t modulus = 1u << bits, d;
    if (!s->valid) { s->valid = 1; s->last = seq; return FWP_SEQ_NEW; }
    d = ((uint32_t)seq - s->last) & (modulus - 1u);
    if (d == 0) return FWP_SEQ_DUPLICATE;
    if (d >= modulus - behind) return FWP_SEQ_STALE;
    s->last = seq;
    if (d < modulus / 2) { *lost += d - 1; return FWP_SEQ_NEW; }
    return FWP_SEQ_RESTART;
}

void fwp_decoder_init(fwp_decoder_t *d, enum fwp_accept accept)
{
    memset(d, 0, sizeof *d);
    d->accept = (uint8_t)accept;
}

/* Checks a complete, COBS-decoded frame in the order the Python decoder does; 0 or -(enum fwp_error). */
static int parse_frame(fwp_decoder_t *d, fwp_rx_t *out)
{
    const uint8_t *b = d->buf;
    const fwp_msg_info_t *info;
    size_t n = d->len;
    uint16_t length, seq;
    uint8_t flags;
    int from_board, r;
    if (n < FWP_HEADER_SIZE + FWP_CRC_SIZE) return -(int)FWP_E_BAD_LENGTH;
    if (b[0] != FWP_PROTOCOL_VERSION) return -(int)FWP_E_BAD_HEADER;
    info = fwp_msg_info(b[2]);
    if (info == NULL) return -(int)FWP_E_UNKNOWN_ID;
    if (fwp_seeded_crc(info->seed, b, n - FWP_CRC_SIZE) !=
        ((uint32_t)b[n - 4] | (uint32_t)b[n - 3] << 8 | (uint32_t)b[n - 2] << 16 | (uint32_t)b[n - 1] << 24))
        return -(int)FWP_E_BAD_CRC;
    flags = b[1];
    if (flags & (uint8_t)~FWP_FLAG_FROM_BOARD) return -(int)FWP_E_BAD_HEADER;
    length = (uint16_t)(b[5] | b[6] << 8);
    if (length != n - FWP_HEADER_SIZE - FWP_CRC_SIZE) return -(int)FWP_E_BAD_LENGTH;
    from_board = flags & FWP_FLAG_FROM_BOARD;
    if (info->direction != '*' && (info->direction == 'b') != (from_board != 0)) return -(int)FWP_E_BAD_HEADER;
    if (d->accept != FWP_ACCEPT_ANY && (d->accept == FWP_ACCEPT_BOARD) != (from_board != 0))
        return -(int)FWP_E_WRONG_DIRECTION;
    r = fwp_decode_payload(b[2], b + FWP_HEADER_SIZE, length, &out->msg);
    if (r != 0) return r;
    seq = (uint16_t)(b[3] | b[4] << 8);
    if (b[2] == FWP_HELLO || b[2] == FWP_HELLO_ACK) d->seq[from_board].valid = 0;
    switch (fwp_seq_classify(&d->seq[from_board], seq, 16, 256, &d->errors[FWP_E_SEQ_GAP])) {
    case FWP_SEQ_DUPLICATE: return -(int)FWP_E_DUPLICATE;
    case FWP_SEQ_STALE: return -(int)FWP_E_STALE;
    case FWP_SEQ_RESTART: d->errors[FWP_E_SEQ_RESTART]++; break;
    case FWP_SEQ_NEW: break;
    }
    out->seq = seq;
    out->from_board = (uint8_t)from_board;
    out->node = 0xFF;
    return 0;
}

static void restart(fwp_decoder_t *d)
{
    d->len = 0; d->encoded = 0; d->code = 0; d->remaining = 0;
}

int fwp_decoder_push(fwp_decoder_t *d, uint8_t byte, fwp_rx_t *out)
{
    int r;
    if (byte == 0) {
        if (d->skipping || d->encoded == 0) { d->skipping = 0; restart(d); return 0; }
        if (d->remaining != 0) r = -(int)FWP_E_BAD_FRAMING; /* the last block runs past the delimiter */
        else r = parse_frame(d, out);
        restart(d);
        if (r != 0) { d->errors[-r]++; return 0; }
        d->delivered++;
        return 1;
    }
    if (d->skipping) return 0;
    if (++d->encoded > FWP_MAX_ENCODED) {
        d->errors[FWP_E_OVERSIZE]++;
        d->skipping = 1;
        restart(d);
        return 0;
    }
    if (d->remaining == 0) { /* a code byte: the previous block (unless full) stood for a zero */
        if (d->encoded > 1 && d->code != 0xFF) d->buf[d->len++] = 0;
        d->code = byte;
        d->remaining = (uint8_t)(byte - 1);
    } else {
        d->buf[d->len++] = byte;
        d->remaining--;
    }
    return 0;
}
