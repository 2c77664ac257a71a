/*
 * fwp_can.c - CAN mapping: transfer encoder and reassembling receiver (see fwp_can.h).
 */
#include "fwp_can.h"

#include <string.h>

uint32_t fwp_can_id(uint8_t msg_id, int from_node, uint8_t node, uint8_t tid, int last, uint8_t index)
{
    return (uint32_t)msg_id << 21 | (uint32_t)(from_node != 0) << 20 | (uint32_t)(node & 0x7Fu) << 13 |
           (uint32_t)(tid & 0x1Fu) << 8 | (uint32_t)(last != 0) << 7 | (uint32_t)(index & 0x7Fu);
}

int fwp_can_encode(const fwp_msg_t *m, uint8_t node, uint8_t tid, int from_node, fwp_can_frame_t *frames,
                   size_t cap)
{
    uint8_t data[FWP_MAX_PAYLOAD + 4];
    const fwp_msg_info_t *info = fwp_msg_info(m->msg_id);
    int len;
    size_t n, count, i;
    uint32_t crc;
    if (info == NULL || (info->direction != '*' && (info->direction == 'b') != (from_node != 0))) return -1;
    if (node > FWP_CAN_MAX_NODE || (from_node && node == FWP_CAN_BROADCAST) || tid >= 1u << FWP_CAN_TID_BITS)
        return -1;
    len = fwp_encode_payload(m, data, FWP_MAX_PAYLOAD);
    if (len < 0) return -1;
    n = (size_t)len;
    if (n <= 8) {
        if (cap < 1) return -1;
        frames[0].id = fwp_can_id(m->msg_id, from_node, node, tid, 1, 0);
        frames[0].dlc = (uint8_t)n;
        memcpy(frames[0].data, data, n);
        return 1;
    }
    crc = fwp_seeded_crc(info->seed, data, n);
    data[n] = (uint8_t)crc; data[n + 1] = (uint8_t)(crc >> 8); data[n + 2] = (uint8_t)(crc >> 16);
    data[n + 3] = (uint8_t)(crc >> 24);
    n += 4;
    count = (n + 7) / 8;
    if (count > FWP_CAN_MAX_FRAMES || count > cap) return -1;
    for (i = 0; i < count; i++) {
        size_t chunk = n - 8 * i < 8 ? n - 8 * i : 8;
        frames[i].id = fwp_can_id(m->msg_id, from_node, node, tid, i + 1 == count, (uint8_t)i);
        frames[i].dlc = (uint8_t)chunk;
        memcpy(frames[i].data, data + 8 * i, chunk);
    }
    return (int)count;
}

void fwp_can_rx_init(fwp_can_rx_t *rx, int accept_from_node)
{
    memset(rx, 0, sizeof *rx);
    rx->accept_from_node = (uint8_t)(accept_from_node != 0);
}

void fwp_can_rx_accept_node(fwp_can_rx_t *rx, uint8_t node)
{
    rx->node_mask[(node & 0x7Fu) >> 3] |= (uint8_t)(1u << (node & 7u));
}

static int node_accepted(const fwp_can_rx_t *rx, uint8_t node)
{
    unsigned i;
    for (i = 0; i < sizeof rx->node_mask; i++)
        if (rx->node_mask[i]) return (rx->node_mask[node >> 3] >> (node & 7u)) & 1u;
    return 1;
}

static fwp_can_transfer_t *find_transfer(fwp_can_rx_t *rx, uint8_t msg_id, uint8_t node)
{
    unsigned i;
    for (i = 0; i < FWP_CAN_TRANSFERS; i++)
        if (rx->transfers[i].in_use && rx->transfers[i].msg_id == msg_id && rx->transfers[i].node == node)
            return &rx->transfers[i];
    return NULL;
}

/* A transfer of the same stream still in progress is abandoned: counted as bad_transfer. */
static void abort_transfer(fwp_can_rx_t *rx, uint8_t msg_id, uint8_t node)
{
    fwp_can_transfer_t *t = find_transfer(rx, msg_id, node);
    if (t != NULL) {
        if (!t->done) rx->errors[FWP_E_BAD_TRANSFER]++;
        t->in_use = 0;
    }
}

static fwp_can_transfer_t *new_transfer(fwp_can_rx_t *rx)
{
    unsigned i;
    fwp_can_transfer_t *oldest = &rx->transfers[0];
    for (i = 0; i < FWP_CAN_TRANSFERS; i++) {
        if (!rx->transfers[i].in_use) return &rx->transfers[i];
        if (rx->transfers[i].stamp < oldest->stamp) oldest = &rx->transfers[i];
    }
    if (!oldest->done) rx->errors[FWP_E_BAD_TRANSFER]++; /* every slot busy: evict the least recently used */
    return oldest;
}

static fwp_seq_t *stream_seq(fwp_can_rx_t *rx, uint8_t msg_id, uint8_t node)
{
    unsigned i;
    fwp_can_stream_t *slot = NULL, *oldest = &rx->streams[0];
    for (i = 0; i < FWP_CAN_STREAMS; i++) {
        fwp_can_stream_t *s = &rx->streams[i];
        if (s->in_use && s->msg_id == msg_id && s->node == node) { s->stamp = ++rx->clock; return &s->seq; }
        if (!s->in_use && slot == NULL) slot = s;
        if (s->stamp < oldest->stamp) oldest = s;
    }
    if (slot == NULL) slot = oldest;
    memset(slot, 0, sizeof *slot);
    slot->in_use = 1; slot->msg_id = msg_id; slot->node = node; slot->stamp = ++rx->clock;
    return &slot->seq;
}

/* Adds a frame of a multi-frame transfer. Returns 1 with the bytes in *done when the last frame is in,
 * 0 while incomplete, or -(enum fwp_error). */
static int add_segment(fwp_can_rx_t *rx, uint8_t msg_id, uint8_t node, uint8_t tid, int last, uint8_t index,
                       const fwp_can_frame_t *f, fwp_can_transfer_t **done)
{
    fwp_can_transfer_t *t = find_transfer(rx, msg_id, node);
    if (index == 0) {
        if (t != NULL && t->tid == tid && t->next_index == 1 && t->last_dlc == f->dlc &&
            memcmp(t->last_data, f->data, f->dlc) == 0)
            return -(int)FWP_E_DUPLICATE;
        abort_transfer(rx, msg_id, node);
        if (f->dlc != 8) return -(int)FWP_E_BAD_TRANSFER;
        t = new_transfer(rx);
        t->in_use = 1; t->done = 0; t->msg_id = msg_id; t->node = node; t->tid = tid; t->next_index = 1;
        t->stamp = ++rx->clock;
        t->last_dlc = 8; memcpy(t->last_data, f->data, 8);
        t->len = 8; memcpy(t->data, f->data, 8);
        return 0;
    }
    if (t == NULL) return -(int)FWP_E_BAD_TRANSFER;
    t->stamp = ++rx->clock;
    if (t->tid == tid && index + 1 == t->next_index && t->last_dlc == f->dlc &&
        memcmp(t->last_data, f->data, f->dlc) == 0)
        return -(int)FWP_E_DUPLICATE;
    if (t->done || t->tid != tid || index != t->next_index || (!last && f->dlc != 8) || f->dlc == 0) {
        t->in_use = 0;
        return -(int)FWP_E_BAD_TRANSFER;
    }
    memcpy(t->data + t->len, f->data, f->dlc);
    t->len = (uint16_t)(t->len + f->dlc);
    t->next_index++;
    t->last_dlc = f->dlc; memcpy(t->last_data, f->data, f->dlc);
    if (!last) {
        if (t->next_index == FWP_CAN_MAX_FRAMES) { t->in_use = 0; return -(int)FWP_E_BAD_TRANSFER; }
        return 0;
    }
    t->done = 1;
    *done = t;
    return 1;
}

static int parse(fwp_can_rx_t *rx, const fwp_can_frame_t *f, fwp_rx_t *out)
{
    uint8_t msg_id = (uint8_t)(f->id >> 21), node = (uint8_t)(f->id >> 13 & 0x7Fu);
    uint8_t tid = (uint8_t)(f->id >> 8 & 0x1Fu), index = (uint8_t)(f->id & 0x7Fu);
    int from_node = (int)(f->id >> 20 & 1u), last = (int)(f->id >> 7 & 1u), r;
    const fwp_msg_info_t *info = fwp_msg_info(msg_id);
    const uint8_t *payload = f->data;
    size_t n = f->dlc;
    fwp_can_transfer_t *t = NULL;
    if (info == NULL) return -(int)FWP_E_UNKNOWN_ID;
    if (info->direction != '*' && (info->direction == 'b') != (from_node != 0)) return -(int)FWP_E_BAD_HEADER;
    if (index == 0 && last) {
        abort_transfer(rx, msg_id, node);
    } else {
        uint32_t crc;
        r = add_segment(rx, msg_id, node, tid, last, index, f, &t);
        if (r <= 0) return r == 0 ? 1 : r; /* 1: incomplete, nothing to report */
        payload = t->data;
        n = t->len;
        if (n <= 8 + 4) return -(int)FWP_E_BAD_LENGTH; /* fits one frame: must not be split */
        n -= 4;
        crc = (uint32_t)payload[n] | (uint32_t)payload[n + 1] << 8 | (uint32_t)payload[n + 2] << 16 |
              (uint32_t)payload[n + 3] << 24;
        if (fwp_seeded_crc(info->seed, payload, n) != crc) return -(int)FWP_E_BAD_CRC;
    }
    r = fwp_decode_payload(msg_id, payload, n, &out->msg);
    if (r != 0) return r;
    {
        fwp_seq_t *s = stream_seq(rx, msg_id, node);
        if (msg_id == FWP_HELLO || msg_id == FWP_HELLO_ACK) s->valid = 0;
        switch (fwp_seq_classify(s, tid, FWP_CAN_TID_BITS, FWP_CAN_TID_BEHIND, &rx->errors[FWP_E_SEQ_GAP])) {
        case FWP_SEQ_DUPLICATE: return -(int)FWP_E_DUPLICATE;
        case FWP_SEQ_STALE: return -(int)FWP_E_STALE;
        case FWP_SEQ_RESTART: rx->errors[FWP_E_SEQ_RESTART]++; break;
        case FWP_SEQ_NEW: break;
        }
    }
    out->seq = tid;
    out->from_board = (uint8_t)from_node;
    out->node = node;
    return 0;
}

int fwp_can_rx_push(fwp_can_rx_t *rx, const fwp_can_frame_t *f, int is_extended, int is_error, int is_remote,
                    fwp_rx_t *out)
{
    int r;
    if (is_error) { rx->errors[FWP_E_ERROR_FRAME]++; return 0; }
    if (!is_extended || is_remote) { rx->errors[FWP_E_FOREIGN]++; return 0; }
    if ((int)(f->id >> 20 & 1u) != rx->accept_from_node) { rx->errors[FWP_E_WRONG_DIRECTION]++; return 0; }
    if (!node_accepted(rx, (uint8_t)(f->id >> 13 & 0x7Fu))) return 0; /* another node's traffic */
    if (f->dlc > 8) { rx->errors[FWP_E_BAD_LENGTH]++; return 0; }
    r = parse(rx, f, out);
    if (r == 1) return 0;
    if (r < 0) { rx->errors[-r]++; return 0; }
    rx->delivered++;
    return 1;
}
