/*
 * fwp.h - firmware_protocol reference implementation for the board side (see ../SPEC.md).
 *
 * C99, no dynamic allocation, no dependency beyond the C standard headers.
 * Assumes `float` is IEEE-754 binary32 (true of every current MCU toolchain).
 * Serial framing: fwp_encode_frame() / fwp_decoder_push(); CAN mapping: fwp_can.h.
 */
#ifndef FWP_H
#define FWP_H

#include <stddef.h>
#include <stdint.h>

#define FWP_PROTOCOL_VERSION 1u
#define FWP_SCHEMA_HASH 0x6f5e240a1fd5f602ull /* first 8 bytes (LE) of SHA-256 of the schema text */

#define FWP_MAX_PAYLOAD 1020u
#define FWP_MAX_JOINTS 32u
#define FWP_MAX_FEET 4u
#define FWP_MAX_NAME 16u
#define FWP_HEADER_SIZE 7u
#define FWP_CRC_SIZE 4u
#define FWP_MAX_FRAME (FWP_HEADER_SIZE + FWP_MAX_PAYLOAD + FWP_CRC_SIZE)
#define FWP_MAX_ENCODED (FWP_MAX_FRAME + FWP_MAX_FRAME / 254u + 1u) /* COBS bytes, no delimiter */
#define FWP_FLAG_FROM_BOARD 0x01u
#define FWP_NO_JOINT 0xFFu

enum fwp_msg_id {
    FWP_ESTOP = 0x01, FWP_FAULT = 0x02, FWP_SET_GOALS = 0x08, FWP_JOINT_STATE = 0x09, FWP_IMU = 0x0a,
    FWP_FOOT_SENSORS = 0x0b, FWP_TORQUE = 0x10, FWP_WATCHDOG = 0x11, FWP_STREAM_RATES = 0x12,
    FWP_ACK = 0x18, FWP_NACK = 0x19, FWP_STATUS = 0x1a, FWP_HEARTBEAT = 0x1b, FWP_HELLO = 0x20,
    FWP_HELLO_ACK = 0x21
};

enum fwp_watchdog_action { FWP_HOLD = 0, FWP_DROP_TORQUE = 1 };
enum fwp_board_state { FWP_DISCONNECTED = 0, FWP_ACTIVE = 1, FWP_HOLDING = 2, FWP_LIMP = 3, FWP_STATE_ESTOP = 4 };
enum fwp_nack_code {
    FWP_NACK_NOT_CONNECTED = 1, FWP_NACK_UNSUPPORTED = 2, FWP_NACK_UNKNOWN_JOINT = 3, FWP_NACK_ESTOPPED = 4,
    FWP_NACK_STALE_COMMAND = 5, FWP_NACK_BAD_VALUE = 6
};
enum fwp_fault_code {
    FWP_FAULT_WATCHDOG_EXPIRED = 1, FWP_FAULT_SERVO_COMMS = 2, FWP_FAULT_OVERHEAT = 3, FWP_FAULT_UNDERVOLTAGE = 4,
    FWP_FAULT_OVERCURRENT = 5, FWP_FAULT_SENSOR = 6, FWP_FAULT_LINK_RECOVERED = 7, FWP_FAULT_INTERNAL = 8
};

/* Error counters, same kinds and order as the Python StreamDecoder / CanDecoder. */
enum fwp_error {
    FWP_E_OVERSIZE, FWP_E_BAD_FRAMING, FWP_E_BAD_LENGTH, FWP_E_BAD_HEADER, FWP_E_UNKNOWN_ID, FWP_E_BAD_CRC,
    FWP_E_BAD_VALUE, FWP_E_WRONG_DIRECTION, FWP_E_DUPLICATE, FWP_E_STALE, FWP_E_SEQ_GAP, FWP_E_SEQ_RESTART,
    FWP_E_FOREIGN, FWP_E_ERROR_FRAME, FWP_E_BAD_TRANSFER, FWP_E_COUNT
};
extern const char *const fwp_error_names[FWP_E_COUNT];

/* Messages. Units as in SPEC.md: rad, rad/s, A, N, m, m/s^2, V. Repeated groups hold `count` records. */
typedef struct { uint8_t engage; } fwp_estop_t;
typedef struct { uint32_t board_time_us; uint16_t code; uint8_t joint_id; float value; } fwp_fault_t;
typedef struct { uint16_t cmd_seq; uint8_t count; uint8_t ids[FWP_MAX_JOINTS]; float position[FWP_MAX_JOINTS]; } fwp_set_goals_t;
typedef struct {
    uint32_t board_time_us;
    uint8_t count;
    uint8_t ids[FWP_MAX_JOINTS];
    float position[FWP_MAX_JOINTS], velocity[FWP_MAX_JOINTS], current[FWP_MAX_JOINTS];
    uint16_t error[FWP_MAX_JOINTS];
} fwp_joint_state_t;
typedef struct { uint32_t board_time_us; float orientation[4], angular_velocity[3], acceleration[3]; } fwp_imu_t;
typedef struct {
    uint32_t board_time_us;
    uint8_t count;
    uint8_t foot_ids[FWP_MAX_FEET];
    float force[FWP_MAX_FEET][4], cop_x[FWP_MAX_FEET], cop_y[FWP_MAX_FEET];
} fwp_foot_sensors_t;
typedef struct { uint8_t count; uint8_t ids[FWP_MAX_JOINTS]; uint8_t enable[FWP_MAX_JOINTS]; } fwp_torque_t;
typedef struct { uint16_t timeout_ms; uint8_t action; } fwp_watchdog_t;
typedef struct { uint16_t joint_state_hz, foot_sensors_hz, imu_hz, heartbeat_hz; } fwp_stream_rates_t;
typedef struct { uint8_t ref_msg_id; uint16_t ref_seq; } fwp_ack_t;
typedef struct { uint8_t ref_msg_id; uint16_t ref_seq; uint8_t code; } fwp_nack_t;
typedef struct {
    uint8_t state, watchdog_action;
    uint16_t watchdog_timeout_ms;
    uint32_t torque_mask;
    uint16_t last_cmd_seq;
    float supply_voltage;
    uint16_t rx_errors;
} fwp_status_t;
typedef struct { uint32_t uptime_ms; uint8_t state; } fwp_heartbeat_t;
typedef struct { uint64_t schema_hash; } fwp_hello_t;
typedef struct {
    uint64_t schema_hash;
    uint32_t device_id, firmware_version, capabilities;
    uint8_t count;
    uint8_t joint_ids[FWP_MAX_JOINTS];
    char joint_names[FWP_MAX_JOINTS][FWP_MAX_NAME + 1]; /* NUL-terminated */
} fwp_hello_ack_t;

typedef struct {
    uint8_t msg_id; /* enum fwp_msg_id: selects the union member */
    union {
        fwp_estop_t estop;
        fwp_fault_t fault;
        fwp_set_goals_t set_goals;
        fwp_joint_state_t joint_state;
        fwp_imu_t imu;
        fwp_foot_sensors_t foot_sensors;
        fwp_torque_t torque;
        fwp_watchdog_t watchdog;
        fwp_stream_rates_t stream_rates;
        fwp_ack_t ack;
        fwp_nack_t nack;
        fwp_status_t status;
        fwp_heartbeat_t heartbeat;
        fwp_hello_t hello;
        fwp_hello_ack_t hello_ack;
    } u;
} fwp_msg_t;

/* A delivered message and its envelope. node: CAN node id (see fwp_can.h); 0xFF on serial. */
typedef struct {
    fwp_msg_t msg;
    uint16_t seq;
    uint8_t from_board;
    uint8_t node;
} fwp_rx_t;

/* Message table: direction 'h' (host -> board), 'b' (board -> host) or '*' (both); CRC seed. */
typedef struct { uint8_t msg_id; char direction; uint32_t seed; const char *name; } fwp_msg_info_t;
const fwp_msg_info_t *fwp_msg_info(uint8_t msg_id); /* NULL for an id not in the schema */

uint32_t fwp_crc32(uint32_t crc, const uint8_t *data, size_t n); /* CRC-32/ISO-HDLC, chainable like zlib */
uint32_t fwp_seeded_crc(uint32_t seed, const uint8_t *data, size_t n); /* CRC of data followed by seed (LE) */

/* Payload codec. encode: bytes written, or -1 if a value breaks the schema's rules (count, duplicate ids,
 * non-finite float, enum value, name). decode: 0, or -(enum fwp_error) BAD_LENGTH / BAD_VALUE. */
int fwp_encode_payload(const fwp_msg_t *m, uint8_t *out, size_t cap);
int fwp_decode_payload(uint8_t msg_id, const uint8_t *p, size_t n, fwp_msg_t *out);

/* One serial frame (COBS bytes + 0x00 delimiter) into out; returns its size, or 0 on error.
 * FWP_MAX_ENCODED + 1 bytes always suffice. */
size_t fwp_encode_frame(const fwp_msg_t *m, uint16_t seq, int from_board, uint8_t *out, size_t cap);

typedef struct { uint8_t valid; uint16_t last; } fwp_seq_t;

enum fwp_accept { FWP_ACCEPT_HOST = 0, FWP_ACCEPT_BOARD = 1, FWP_ACCEPT_ANY = 2 };

typedef struct {
    uint8_t buf[FWP_MAX_ENCODED]; /* decoded bytes of the frame in progress */
    uint16_t len;                 /* decoded bytes so far */
    uint16_t encoded;             /* encoded bytes since the last delimiter */
    uint8_t code;                 /* current COBS block code */
    uint8_t remaining;            /* data bytes left in the current block */
    uint8_t skipping;             /* oversize frame: drop until the next delimiter */
    uint8_t accept;               /* enum fwp_accept */
    fwp_seq_t seq[2];             /* per direction: [0] host frames, [1] board frames */
    uint32_t errors[FWP_E_COUNT];
    uint32_t delivered;
} fwp_decoder_t;

void fwp_decoder_init(fwp_decoder_t *d, enum fwp_accept accept);
/* Feed one received byte; returns 1 when it completed a valid frame (then *out holds it), else 0. */
int fwp_decoder_push(fwp_decoder_t *d, uint8_t byte, fwp_rx_t *out);

/* Sequence classification shared by both framings (d = seq - last mod 2^bits): NEW (d - 1 frames lost,
 * added to *lost), RESTART (accept: the peer restarted), DUPLICATE or STALE (drop). */
enum fwp_seq_verdict { FWP_SEQ_NEW, FWP_SEQ_RESTART, FWP_SEQ_DUPLICATE, FWP_SEQ_STALE };
enum fwp_seq_verdict fwp_seq_classify(fwp_seq_t *s, uint16_t seq, unsigned bits, unsigned behind, uint32_t *lost);

#endif
