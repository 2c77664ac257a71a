/*
 * fwp_can.h - the CAN mapping (classic CAN, 29-bit ids, 8-byte frames) of firmware_protocol (../SPEC.md).
 *
 * id = msg_id (8) | from_node (1) | node (7) | transfer id (5) | last (1) | frame index (7).
 * Payloads of up to 8 bytes go in one frame; longer ones in 8-byte frames ending with a CRC-32.
 */
#ifndef FWP_CAN_H
#define FWP_CAN_H

#include "fwp.h"

#define FWP_CAN_BROADCAST 0u
#define FWP_CAN_MAX_NODE 127u
#define FWP_CAN_MAX_FRAMES 128u
#define FWP_CAN_TID_BITS 5u
#define FWP_CAN_TID_BEHIND 4u
#ifndef FWP_CAN_TRANSFERS
#define FWP_CAN_TRANSFERS 4u /* multi-frame transfers reassembled at once (about 1 KiB each) */
#endif
#ifndef FWP_CAN_STREAMS
#define FWP_CAN_STREAMS 32u /* (message, node) streams whose transfer ids are tracked */
#endif

typedef struct { uint32_t id; uint8_t dlc; uint8_t data[8]; } fwp_can_frame_t;

uint32_t fwp_can_id(uint8_t msg_id, int from_node, uint8_t node, uint8_t tid, int last, uint8_t index);

/* Frames of one transfer into frames[0..cap); returns how many, or -1 on a bad message or argument. */
int fwp_can_encode(const fwp_msg_t *m, uint8_t node, uint8_t tid, int from_node, fwp_can_frame_t *frames,
                   size_t cap);

typedef struct {
    uint8_t in_use, msg_id, node, tid, next_index, last_dlc;
    uint8_t done; /* complete: kept only to recognise a repeat of its last frame */
    uint8_t last_data[8];
    uint16_t len;
    uint32_t stamp; /* least recently used is evicted first */
    uint8_t data[FWP_MAX_PAYLOAD + 4];
} fwp_can_transfer_t;

typedef struct {
    uint8_t in_use, msg_id, node;
    fwp_seq_t seq;
    uint32_t stamp;
} fwp_can_stream_t;

typedef struct {
    uint8_t accept_from_node; /* 1: deliver frames nodes sent (host side); 0: frames the host sent (node) */
    uint8_t node_mask[16];    /* accepted node ids; all zero = any */
    uint32_t clock;
    fwp_can_transfer_t transfers[FWP_CAN_TRANSFERS];
    fwp_can_stream_t streams[FWP_CAN_STREAMS];
    uint32_t errors[FWP_E_COUNT];
    uint32_t delivered;
} fwp_can_rx_t;

void fwp_can_rx_init(fwp_can_rx_t *rx, int accept_from_node);
void fwp_can_rx_accept_node(fwp_can_rx_t *rx, uint8_t node);
/* Feed one received frame; returns 1 when it completed a valid transfer (then *out holds it), else 0. */
int fwp_can_rx_push(fwp_can_rx_t *rx, const fwp_can_frame_t *f, int is_extended, int is_error, int is_remote,
                    fwp_rx_t *out);

#endif
