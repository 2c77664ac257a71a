/*
 * fwp_tool.c - command-line companion of the C reference (host-side tool, uses stdio and time.h).
 *
 *   fwp_tool info                     schema hash, limits, CRC check value and per-message seeds (JSON)
 *   fwp_tool serial host|board|any    hex byte stream on stdin -> one JSON line per delivered message
 *                                     (with the frame the C encoder makes of it), then the error counters
 *   fwp_tool can host|node [NODE...]  CAN frames on stdin, one per line: "X <id> <data>" (extended),
 *                                     "S <id> <data>" (standard), "R <id>" (remote), "E" (error frame);
 *                                     ids and data in hex, "-" for no data
 *   fwp_tool bench N                  one serial frame (hex) on stdin: C encode and decode rates, N frames
 *
 * Build: cc -std=c99 -O2 fwp.c fwp_can.c fwp_tool.c -o fwp_tool
 */
#include "fwp.h"
#include "fwp_can.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static void print_floats(const char *name, const float *v, unsigned n, int comma)
{
    unsigned i;
    printf("\"%s\":[", name);
    for (i = 0; i < n; i++) printf("%s%.17g", i ? "," : "", (double)v[i]);
    printf("]%s", comma ? "," : "");
}

static void print_u8s(const char *name, const uint8_t *v, unsigned n, int as_bool)
{
    unsigned i;
    printf("\"%s\":[", name);
    for (i = 0; i < n; i++) {
        if (i) printf(",");
        if (as_bool) printf("%s", v[i] ? "true" : "false");
        else printf("%u", v[i]);
    }
    printf("]");
}

/* The message as the JSON of firmware_protocol.messages.to_dict (floats exact: %.17g of the float32). */
static void print_msg(const fwp_msg_t *m)
{
    unsigned i, k;
    printf("{\"type\":\"%s\",", fwp_msg_info(m->msg_id)->name);
    switch (m->msg_id) {
    case FWP_ESTOP: printf("\"engage\":%s", m->u.estop.engage ? "true" : "false"); break;
    case FWP_FAULT:
        printf("\"board_time_us\":%lu,\"code\":%u,\"joint_id\":%u,\"value\":%.17g",
               (unsigned long)m->u.fault.board_time_us, m->u.fault.code, m->u.fault.joint_id,
               (double)m->u.fault.value);
        break;
    case FWP_SET_GOALS:
        printf("\"cmd_seq\":%u,", m->u.set_goals.cmd_seq);
        print_u8s("ids", m->u.set_goals.ids, m->u.set_goals.count, 0);
        printf(",");
        print_floats("position", m->u.set_goals.position, m->u.set_goals.count, 0);
        break;
    case FWP_JOINT_STATE: {
        const fwp_joint_state_t *j = &m->u.joint_state;
        printf("\"board_time_us\":%lu,", (unsigned long)j->board_time_us);
        print_u8s("ids", j->ids, j->count, 0);
        printf(",");
        print_floats("position", j->position, j->count, 1);
        print_floats("velocity", j->velocity, j->count, 1);
        print_floats("current", j->current, j->count, 1);
        printf("\"error\":[");
        for (i = 0; i < j->count; i++) printf("%s%u", i ? "," : "", j->error[i]);
        printf("]");
        break;
    }
    case FWP_IMU:
        printf("\"board_time_us\":%lu,", (unsigned long)m->u.imu.board_time_us);
        print_floats("orientation", m->u.imu.orientation, 4, 1);
        print_floats("angular_velocity", m->u.imu.angular_velocity, 3, 1);
        print_floats("acceleration", m->u.imu.acceleration, 3, 0);
        break;
    case FWP_FOOT_SENSORS: {
        const fwp_foot_sensors_t *f = &m->u.foot_sensors;
        printf("\"board_time_us\":%lu,", (unsigned long)f->board_time_us);
        print_u8s("foot_ids", f->foot_ids, f->count, 0);
        printf(",\"force\":[");
        for (i = 0; i < f->count; i++) {
            printf(i ? ",[" : "[");
            for (k = 0; k < 4; k++) printf("%s%.17g", k ? "," : "", (double)f->force[i][k]);
            printf("]");
        }
        printf("],");
        print_floats("cop_x", f->cop_x, f->count, 1);
        print_floats("cop_y", f->cop_y, f->count, 0);
        break;
    }
    case FWP_TORQUE:
        print_u8s("ids", m->u.torque.ids, m->u.torque.count, 0);
        printf(",");
        print_u8s("enable", m->u.torque.enable, m->u.torque.count, 1);
        break;
    case FWP_WATCHDOG:
        printf("\"timeout_ms\":%u,\"action\":%u", m->u.watchdog.timeout_ms, m->u.watchdog.action);
        break;
    case FWP_STREAM_RATES:
        printf("\"joint_state_hz\":%u,\"foot_sensors_hz\":%u,\"imu_hz\":%u,\"heartbeat_hz\":%u",
               m->u.stream_rates.joint_state_hz, m->u.stream_rates.foot_sensors_hz, m->u.stream_rates.imu_hz,
               m->u.stream_rates.heartbeat_hz);
        break;
    case FWP_ACK: printf("\"ref_msg_id\":%u,\"ref_seq\":%u", m->u.ack.ref_msg_id, m->u.ack.ref_seq); break;
    case FWP_NACK:
        printf("\"ref_msg_id\":%u,\"ref_seq\":%u,\"code\":%u", m->u.nack.ref_msg_id, m->u.nack.ref_seq,
               m->u.nack.code);
        break;
    case FWP_STATUS: {
        const fwp_status_t *s = &m->u.status;
        printf("\"state\":%u,\"watchdog_action\":%u,\"watchdog_timeout_ms\":%u,\"torque_mask\":%lu,"
               "\"last_cmd_seq\":%u,\"supply_voltage\":%.17g,\"rx_errors\":%u",
               s->state, s->watchdog_action, s->watchdog_timeout_ms, (unsigned long)s->torque_mask,
               s->last_cmd_seq, (double)s->supply_voltage, s->rx_errors);
        break;
    }
    case FWP_HEARTBEAT:
        printf("\"uptime_ms\":%lu,\"state\":%u", (unsigned long)m->u.heartbeat.uptime_ms, m->u.heartbeat.state);
        break;
    case FWP_HELLO: printf("\"schema_hash\":%llu", (unsigned long long)m->u.hello.schema_hash); break;
    case FWP_HELLO_ACK: {
        const fwp_hello_ack_t *h = &m->u.hello_ack;
        const char *c;
        printf("\"schema_hash\":%llu,\"device_id\":%lu,\"firmware_version\":%lu,\"capabilities\":%lu,",
               (unsigned long long)h->schema_hash, (unsigned long)h->device_id,
               (unsigned long)h->firmware_version, (unsigned long)h->capabilities);
        print_u8s("joint_ids", h->joint_ids, h->count, 0);
        printf(",\"joint_names\":[");
        for (i = 0; i < h->count; i++) {
            printf(i ? ",\"" : "\"");
            for (c = h->joint_names[i]; *c; c++) printf(*c == '"' || *c == '\\' ? "\\%c" : "%c", *c);
            printf("\"");
        }
        printf("]");
        break;
    }
    default: break;
    }
    printf("}");
}

static void print_errors(const uint32_t *errors, uint32_t delivered)
{
    unsigned i;
    printf("{\"delivered\":%lu,\"errors\":{", (unsigned long)delivered);
    for (i = 0; i < FWP_E_COUNT; i++) printf("%s\"%s\":%lu", i ? "," : "", fwp_error_names[i], (unsigned long)errors[i]);
    printf("}}\n");
}

static int hexval(int c)
{
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    return -1;
}

/* Next byte of a hex stream on stdin (non-hex characters skipped); -1 at the end. */
static int next_hex_byte(void)
{
    int hi = -1, c, v;
    while ((c = getchar()) != EOF) {
        if ((v = hexval(c)) < 0) continue;
        if (hi < 0) hi = v;
        else return hi << 4 | v;
    }
    return -1;
}

static int run_serial(enum fwp_accept accept)
{
    static fwp_decoder_t d;
    static uint8_t frame[FWP_MAX_ENCODED + 1];
    fwp_rx_t rx;
    int b;
    size_t i, n;
    fwp_decoder_init(&d, accept);
    while ((b = next_hex_byte()) >= 0) {
        if (!fwp_decoder_push(&d, (uint8_t)b, &rx)) continue;
        n = fwp_encode_frame(&rx.msg, rx.seq, rx.from_board, frame, sizeof frame);
        printf("{\"seq\":%u,\"from_board\":%s,\"msg\":", rx.seq, rx.from_board ? "true" : "false");
        print_msg(&rx.msg);
        printf(",\"frame\":\"");
        for (i = 0; i < n; i++) printf("%02x", frame[i]);
        printf("\"}\n");
    }
    print_errors(d.errors, d.delivered);
    return 0;
}

static int run_can(int accept_from_node, int argc, char **argv)
{
    static fwp_can_rx_t rx;
    static fwp_can_frame_t frames[FWP_CAN_MAX_FRAMES];
    char line[128], kind, data[64];
    fwp_rx_t out;
    int i, j, n;
    fwp_can_rx_init(&rx, accept_from_node);
    for (i = 0; i < argc; i++) fwp_can_rx_accept_node(&rx, (uint8_t)atoi(argv[i]));
    while (fgets(line, sizeof line, stdin) != NULL) {
        fwp_can_frame_t f;
        unsigned long id = 0;
        memset(&f, 0, sizeof f);
        data[0] = '\0';
        if (sscanf(line, " %c %lx %63s", &kind, &id, data) < 1) continue;
        f.id = (uint32_t)id;
        for (j = 0; data[j] && data[j + 1] && hexval(data[j]) >= 0 && f.dlc < 8; j += 2)
            f.data[f.dlc++] = (uint8_t)(hexval(data[j]) << 4 | hexval(data[j + 1]));
        if (!fwp_can_rx_push(&rx, &f, kind == 'X', kind == 'E', kind == 'R', &out)) continue;
        n = fwp_can_encode(&out.msg, out.node, (uint8_t)out.seq, out.from_board, frames, FWP_CAN_MAX_FRAMES);
        printf("{\"seq\":%u,\"from_node\":%s,\"node\":%u,\"msg\":", out.seq, out.from_board ? "true" : "false",
               out.node);
        print_msg(&out.msg);
        printf(",\"frames\":[");
        for (i = 0; i < n; i++) {
            printf("%s[%lu,\"", i ? "," : "", (unsigned long)frames[i].id);
            for (j = 0; j < frames[i].dlc; j++) printf("%02x", frames[i].data[j]);
            printf("\"]");
        }
        printf("]}\n");
    }
    print_errors(rx.errors, rx.delivered);
    return 0;
}

static double seconds(clock_t t0) { return (double)(clock() - t0) / CLOCKS_PER_SEC; }

static int run_bench(long count)
{
    static fwp_decoder_t d;
    static uint8_t frame[FWP_MAX_ENCODED + 1];
    uint8_t *stream;
    fwp_rx_t rx, first;
    size_t len = 0, n, i;
    long k, rounds = 0, encoded = 0;
    int b, got = 0;
    clock_t t0;
    double t_enc, t_dec;
    fwp_decoder_init(&d, FWP_ACCEPT_ANY);
    while ((b = next_hex_byte()) >= 0)
        if (fwp_decoder_push(&d, (uint8_t)b, &first)) got = 1;
    if (!got || count < 1 || count > 65536) { fprintf(stderr, "fwp_tool bench: need one valid frame, N 1..65536\n"); return 2; }
    stream = malloc((size_t)count * sizeof frame); /* the tool may allocate; the library never does */
    if (stream == NULL) return 2;
    t0 = clock();
    do { /* encode: count frames with consecutive sequence numbers, repeated for at least 0.3 s */
        for (len = 0, k = 0; k < count; k++) {
            n = fwp_encode_frame(&first.msg, (uint16_t)k, first.from_board, stream + len, sizeof frame);
            if (n == 0) return 2;
            len += n;
        }
        encoded += count;
    } while ((t_enc = seconds(t0)) < 0.3);
    t0 = clock();
    do { /* decode the whole stream with a fresh decoder each round */
        long delivered = 0;
        fwp_decoder_init(&d, FWP_ACCEPT_ANY);
        for (i = 0; i < len; i++) delivered += fwp_decoder_push(&d, stream[i], &rx);
        if (delivered != count) { fprintf(stderr, "fwp_tool bench: decoded %ld of %ld\n", delivered, count); return 2; }
        rounds++;
    } while ((t_dec = seconds(t0)) < 0.3);
    printf("{\"frame_bytes\":%lu,\"encode_fps\":%.0f,\"decode_fps\":%.0f}\n", (unsigned long)(len / (size_t)count),
           (double)encoded / t_enc, (double)(rounds * count) / t_dec);
    free(stream);
    return 0;
}

static int run_info(void)
{
    static const uint8_t ids[] = {0x01, 0x02, 0x08, 0x09, 0x0a, 0x0b, 0x10, 0x11, 0x12, 0x18, 0x19, 0x1a, 0x1b,
                                  0x20, 0x21};
    unsigned i;
    static const uint8_t check[] = "123456789";
    printf("{\"schema_hash\":%llu,\"version\":%u,\"max_payload\":%u,\"max_encoded\":%u,\"crc_check\":%lu,"
           "\"seeds\":{", (unsigned long long)FWP_SCHEMA_HASH, FWP_PROTOCOL_VERSION, FWP_MAX_PAYLOAD,
           (unsigned)FWP_MAX_ENCODED, (unsigned long)fwp_crc32(0, check, 9));
    for (i = 0; i < sizeof ids; i++) {
        const fwp_msg_info_t *m = fwp_msg_info(ids[i]);
        printf("%s\"%s\":[%u,\"%c\",%lu]", i ? "," : "", m->name, m->msg_id, m->direction, (unsigned long)m->seed);
    }
    printf("}}\n");
    return 0;
}

int main(int argc, char **argv)
{
    if (argc >= 2 && strcmp(argv[1], "info") == 0) return run_info();
    if (argc == 3 && strcmp(argv[1], "serial") == 0) {
        if (strcmp(argv[2], "host") == 0) return run_serial(FWP_ACCEPT_HOST);
        if (strcmp(argv[2], "board") == 0) return run_serial(FWP_ACCEPT_BOARD);
        if (strcmp(argv[2], "any") == 0) return run_serial(FWP_ACCEPT_ANY);
    }
    if (argc >= 3 && strcmp(argv[1], "can") == 0) {
        if (strcmp(argv[2], "node") == 0) return run_can(1, argc - 3, argv + 3);
        if (strcmp(argv[2], "host") == 0) return run_can(0, argc - 3, argv + 3);
    }
    if (argc == 3 && strcmp(argv[1], "bench") == 0) return run_bench(atol(argv[2]));
    fprintf(stderr, "usage: fwp_tool info | serial host|board|any | can host|node [NODE...] | bench N\n");
    return 2;
}
