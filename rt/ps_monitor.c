#include "ps_args.h"
#include "ps_monitor.h"

#include <errno.h>
#include <getopt.h>
#include <math.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../drivers/ps_actuator.h"
#include "../drivers/ps_can_socket.h"
#include "../drivers/ps_candump.h"
#include "ps_clock.h"
#include "ps_err.h"

static const char *const REQUEST_NAMES[PS_ACT_REQ_COUNT] = {
    [PS_ACT_REQ_ENABLE] = "enable",
    [PS_ACT_REQ_DISABLE] = "disable",
    [PS_ACT_REQ_SET_ZERO] = "set zero",
    [PS_ACT_REQ_CLEAR_FAULT] = "clear fault",
};

void ps_monitor_init(ps_monitor_t *m, const ps_robot_cfg_t *r)
{
    memset(m, 0, sizeof(*m));
    ps_imu_rx_init(&m->imu_rx, &r->imu);
}

static void raw(const ps_can_frame_t *f, char *out, size_t len)
{
    int n = snprintf(out, len, "unknown %s%0*X [%u]", f->is_fd ? "FD " : "", f->is_ext ? 8 : 3,
                     f->id, f->len);
    for (uint8_t i = 0; i < f->len && n > 0 && (size_t)n < len; i++)
        n += snprintf(out + n, len - (size_t)n, " %02X", f->data[i]);
}

static ps_monitor_kind_t describe_drive_frame(const ps_robot_cfg_t *r, uint32_t j,
                                              const ps_can_frame_t *f, char *out, size_t len)
{
    const ps_act_cfg_t *a = &r->act[j];
    const ps_act_proto_t *p = ps_act_proto_get(a->protocol);
    const char *name = r->joint_name[j];
    const int req = p->classify_request(a, f);
    if (req >= 0 && req < PS_ACT_REQ_COUNT) {
        snprintf(out, len, "%s request %s", name, REQUEST_NAMES[req]);
        return PS_MONITOR_REQUEST;
    }
    ps_act_cmd_t motor, joint;
    if (p->decode_cmd(a, f, &motor) < 0) {
        snprintf(out, len, "%s malformed command (%s, %u bytes)", name, p->name, f->len);
        return PS_MONITOR_MALFORMED;
    }
    ps_act_cmd_from_motor(a, &motor, &joint);
    snprintf(out, len, "%s cmd q=%+.4f rad qd=%+.3f rad/s kp=%.1f kd=%.2f tau=%+.2f Nm", name,
             joint.q_rad, joint.qd_rad_s, joint.kp_nm_rad, joint.kd_nm_s_rad, joint.tau_ff_nm);
    return PS_MONITOR_COMMAND;
}

static int describe_joint(const ps_robot_cfg_t *r, uint32_t bus_idx, const ps_can_frame_t *f,
                          int *out_joint, char *out, size_t len, ps_monitor_kind_t *kind)
{
    for (uint32_t j = 0; j < r->n_joints; j++) {
        const ps_act_cfg_t *a = &r->act[j];
        const ps_act_proto_t *p = ps_act_proto_get(a->protocol);
        if (a->bus_idx != bus_idx || p == NULL)
            continue;
        if (p->match_reply(a, f)) {
            *out_joint = (int)j;
            ps_act_meas_t m;
            if (ps_act_decode_reply(a, f, &m) < 0) {
                snprintf(out, len, "%s malformed reply (%s, %u bytes)", r->joint_name[j], p->name,
                         f->len);
                *kind = PS_MONITOR_MALFORMED;
            } else {
                snprintf(out, len,
                         "%s reply q=%+.4f rad qd=%+.3f rad/s tau=%+.2f Nm T=%.0f C faults %s",
                         r->joint_name[j], m.q_rad, m.qd_rad_s, m.tau_nm, m.temp_c,
                         ps_act_fault_name(m.fault_bits));
                *kind = PS_MONITOR_REPLY;
            }
            return 1;
        }
        uint32_t fault_bits = 0;
        const int frc = p->decode_fault != NULL ? p->decode_fault(a, f, &fault_bits) : -ENOENT;
        if (frc != -ENOENT) {
            *out_joint = (int)j;
            if (frc < 0) {
                snprintf(out, len, "%s malformed fault report (%s, %u bytes)", r->joint_name[j],
                         p->name, f->len);
                *kind = PS_MONITOR_MALFORMED;
            } else {
                snprintf(out, len, "%s fault report: %s%s", r->joint_name[j],
                         ps_act_fault_name(fault_bits),
                         fault_bits & (fault_bits - 1u) ? " and more" : "");
                *kind = PS_MONITOR_FAULT;
            }
            return 1;
        }
        if (p->is_for_drive(a, f)) {
            *out_joint = (int)j;
            *kind = describe_drive_frame(r, j, f, out, len);
            return 1;
        }
    }
    return 0;
}

/* The length an IMU frame with f's id has (0: not one of the IMU's ids). */
static uint8_t imu_frame_len(const ps_imu_cfg_t *imu, const ps_can_frame_t *f)
{
    uint32_t ids[PS_IMU_MAX_FRAMES];
    uint8_t lens[PS_IMU_MAX_FRAMES];
    const unsigned n = ps_imu_frames(imu, ids, lens);
    for (unsigned i = 0; i < n && !f->is_ext; i++)
        if (f->id == ids[i])
            return lens[i];
    return 0;
}

static ps_monitor_kind_t describe_imu(ps_monitor_t *m, const ps_imu_cfg_t *imu,
                                      const ps_can_frame_t *f, char *out, size_t len)
{
    ps_imu_sample_t s;
    const int rc = ps_imu_rx_feed(&m->imu_rx, f, &s);
    if (rc >= 0)
        m->has_imu_start = true;
    if (rc < 0 && rc != -PS_ERR_STALE && !m->has_imu_start && f->len == imu_frame_len(imu, f)) {
        /* a capture (candump, the live monitor) that begins between a
         * sample's frames sees the rest of that sample first */
        snprintf(out, len, "imu frame %03X [%u] of a sample begun before the capture", f->id,
                 f->len);
        return PS_MONITOR_IMU;
    }
    if (rc == 1) {
        snprintf(out, len,
                 "imu sample %u gyro %+.3f %+.3f %+.3f rad/s accel %+.3f %+.3f %+.3f m/s2 %d C "
                 "status %02X",
                 s.seq, s.gyro_body_rad_s[0], s.gyro_body_rad_s[1], s.gyro_body_rad_s[2],
                 s.accel_body_m_s2[0], s.accel_body_m_s2[1], s.accel_body_m_s2[2], s.temp_c,
                 s.status);
        return PS_MONITOR_IMU;
    }
    if (rc == -PS_ERR_STALE) {
        snprintf(out, len, "imu sample %u refused: the same six values %u times in a row (frozen)",
                 s.seq, m->imu_rx.n_same);
        return PS_MONITOR_MALFORMED;
    }
    if (rc == 0) {
        if (m->imu_rx.protocol == PS_IMU_PROTO_XSENS)
            snprintf(out, len, "imu xsens frame %03X [%u] of a sample", f->id, f->len);
        else
            snprintf(out, len, "imu gyro half (seq %u)", f->len == 8 ? f->data[6] : 0u);
        return PS_MONITOR_IMU;
    }
    snprintf(out, len, "imu malformed frame %03X [%u] (wrong length or unpaired seq)", f->id,
             f->len);
    return PS_MONITOR_MALFORMED;
}

ps_monitor_kind_t ps_monitor_describe(ps_monitor_t *m, const ps_robot_cfg_t *r, uint32_t bus_idx,
                                      const ps_can_frame_t *f, int *out_joint, char *out,
                                      size_t len)
{
    *out_joint = -1;
    ps_monitor_kind_t kind = PS_MONITOR_UNKNOWN;
    if (describe_joint(r, bus_idx, f, out_joint, out, len, &kind))
        return kind;
    if (bus_idx == r->imu.bus_idx && imu_frame_len(&r->imu, f) != 0)
        return describe_imu(m, &r->imu, f, out, len);
    raw(f, out, len);
    return PS_MONITOR_UNKNOWN;
}

/* ---- the command ------------------------------------------------------ */

typedef struct {
    uint64_t n_cmd, n_reply, n_other;
} joint_count_t;

static struct {
    const char *board, *robot, *log_path;
    double duration_s;
    uint64_t max_frames;
    bool is_rates;
    ps_board_cfg_t board_cfg;
    ps_robot_cfg_t robot_cfg;
    ps_monitor_t mon;
    ps_can_socket_t sock[PS_MAX_BUSES];
    uint32_t n_open;
    joint_count_t count[PS_MAX_JOINTS];
    uint64_t n_frames, n_unknown, n_malformed, n_imu;
} g;

static volatile sig_atomic_t g_stop;

static void on_signal(int sig)
{
    (void)sig;
    g_stop = 1;
}

static const char USAGE[] =
    "usage: pushstep monitor --board FILE [--robot FILE] [--log FILE] [options]\n"
    "Decodes the board's CAN buses as the robot file describes them: each frame as a\n"
    "joint's command or mode request, a joint's reply, an IMU half or sample, or\n"
    "unknown. Live through SocketCAN (the board's interfaces), or offline from a\n"
    "candump -L log (--log; `pushstep --candump` and candump -L write them).\n"
    "\n"
    "  --board NAME|FILE   board file: which interface is which bus\n"
    "  --robot NAME|FILE   robot file (default robots/ps1.yaml)\n"
    "  --log FILE          decode this candump -L log instead of the live buses\n"
    "  --duration S        stop after S seconds (live)\n"
    "  --count N           stop after N frames\n"
    "  --rates             print commands and replies per second per joint at the end\n"
    "                      instead of every frame\n";

static int parse(int argc, char **argv)
{
    static const struct option LONG[] = {
        {"board", required_argument, NULL, 'b'}, {"robot", required_argument, NULL, 'r'},
        {"log", required_argument, NULL, 'l'},   {"duration", required_argument, NULL, 'd'},
        {"count", required_argument, NULL, 'n'}, {"rates", no_argument, NULL, 'R'},
        {"help", no_argument, NULL, 'h'},        {NULL, 0, NULL, 0},
    };
    int c;
    char *end;
    while ((c = getopt_long(argc, argv, "h", LONG, NULL)) != -1) {
        switch (c) {
        case 'b':
            g.board = optarg;
            break;
        case 'r':
            g.robot = optarg;
            break;
        case 'l':
            g.log_path = optarg;
            break;
        case 'd':
            if (ps_args_seconds(optarg, 0.0, 1e9, false, &g.duration_s) < 0) {
                fprintf(stderr, "pushstep monitor: --duration: '%s' is not seconds >= 0\n", optarg);
                return -EINVAL;
            }
            break;
        case 'n':
            g.max_frames = strtoull(optarg, &end, 10);
            if (*end != '\0' || optarg[0] == '-') {
                fprintf(stderr, "pushstep monitor: --count: '%s' is not a count\n", optarg);
                return -EINVAL;
            }
            break;
        case 'R':
            g.is_rates = true;
            break;
        case 'h':
            fputs(USAGE, stdout);
            exit(0);
        default:
            return -EINVAL;
        }
    }
    if (optind < argc || g.board == NULL) {
        fputs(USAGE, stderr);
        return -EINVAL;
    }
    return 0;
}

static void take(uint32_t bus_idx, const ps_can_frame_t *f)
{
    char text[256];
    int j;
    const ps_monitor_kind_t kind =
        ps_monitor_describe(&g.mon, &g.robot_cfg, bus_idx, f, &j, text, sizeof(text));
    g.n_frames++;
    g.n_unknown += kind == PS_MONITOR_UNKNOWN;
    g.n_malformed += kind == PS_MONITOR_MALFORMED;
    g.n_imu += kind == PS_MONITOR_IMU;
    if (j >= 0) {
        g.count[j].n_cmd += kind == PS_MONITOR_COMMAND;
        g.count[j].n_reply += kind == PS_MONITOR_REPLY;
        g.count[j].n_other +=
            kind == PS_MONITOR_REQUEST || kind == PS_MONITOR_MALFORMED || kind == PS_MONITOR_FAULT;
    }
    if (!g.is_rates)
        printf("(%lld.%06lld) %s %s\n", (long long)(f->t_ns / 1000000000LL),
               (long long)(f->t_ns % 1000000000LL / 1000), g.board_cfg.buses[bus_idx].ifname, text);
    if (g.max_frames != 0 && g.n_frames >= g.max_frames)
        g_stop = 1;
}

static int bus_of(const char *ifname)
{
    for (uint32_t b = 0; b < g.board_cfg.n_buses; b++)
        if (strcmp(g.board_cfg.buses[b].ifname, ifname) == 0)
            return (int)b;
    return -1;
}

static int run_log(double *out_span_s)
{
    FILE *f = fopen(g.log_path, "r");
    if (f == NULL) {
        fprintf(stderr, "pushstep monitor: --log %s: %s\n", g.log_path, strerror(errno));
        return 2;
    }
    char line[PS_CANDUMP_LINE_MAX + 2], ifname[PS_CANDUMP_IFNAME_MAX], err[128];
    int64_t t_first = -1, t_last = 0;
    unsigned lineno = 0;
    int rc = 0;
    while (!g_stop && fgets(line, sizeof(line), f) != NULL) {
        lineno++;
        ps_can_frame_t fr;
        if (ps_candump_parse(line, &fr, ifname, sizeof(ifname), err, sizeof(err)) < 0) {
            fprintf(stderr, "pushstep monitor: %s:%u: %s\n", g.log_path, lineno, err);
            rc = 2;
            break;
        }
        const int b = bus_of(ifname);
        if (b < 0) {
            fprintf(stderr, "pushstep monitor: %s:%u: interface %s is not a bus of the board\n",
                    g.log_path, lineno, ifname);
            rc = 2;
            break;
        }
        t_first = t_first < 0 ? fr.t_ns : t_first;
        t_last = fr.t_ns;
        take((uint32_t)b, &fr);
    }
    fclose(f);
    *out_span_s = t_first >= 0 ? (double)(t_last - t_first) * 1e-9 : 0.0;
    return rc;
}

static int run_live(double *out_span_s)
{
    char err[PS_ERR_MSG_LEN];
    struct pollfd pfd[PS_MAX_BUSES];
    for (uint32_t b = 0; b < g.board_cfg.n_buses; b++) {
        ps_can_socket_cfg_t c = {.is_fd = g.board_cfg.buses[b].is_fd,
                                 .n_filters = 2,
                                 .filters = {{0, 0, false}, {0, 0, true}}};
        memcpy(c.ifname, g.board_cfg.buses[b].ifname, sizeof(c.ifname));
        if (ps_can_socket_open(&g.sock[b], &c, err, sizeof(err)) < 0) {
            fprintf(stderr, "pushstep monitor: %s\n", err);
            return 2;
        }
        g.n_open = b + 1u;
        pfd[b] = (struct pollfd){.fd = g.sock[b].fd, .events = POLLIN};
    }
    const ps_clock_t *clk = ps_clock_monotonic();
    const int64_t t0 = ps_clock_now_ns(clk);
    const int64_t end = g.duration_s > 0 ? t0 + (int64_t)(g.duration_s * 1e9) : 0;
    while (!g_stop && (end == 0 || ps_clock_now_ns(clk) < end)) {
        if (poll(pfd, g.n_open, 100) <= 0)
            continue;
        for (uint32_t b = 0; b < g.n_open && !g_stop; b++) {
            if (!(pfd[b].revents & (POLLIN | POLLERR | POLLHUP | POLLNVAL)))
                continue;
            ps_can_port_t port = ps_can_socket_port(&g.sock[b]);
            ps_can_frame_t rx[PS_CAN_SOCKET_BATCH];
            const int n = ps_can_recv_batch(&port, rx, PS_CAN_SOCKET_BATCH);
            if (n < 0) { /* the interface went down or away */
                fprintf(stderr, "pushstep monitor: %s: %s\n", g.board_cfg.buses[b].ifname,
                        strerror(-n));
                return 1;
            }
            for (int i = 0; i < n && !g_stop; i++)
                take(b, &rx[i]);
        }
    }
    *out_span_s = (double)(ps_clock_now_ns(clk) - t0) * 1e-9;
    return 0;
}

static void print_rates(double span_s)
{
    const double s = span_s > 0 ? span_s : 1.0;
    printf("%-18s %4s %12s %12s %8s\n", "joint", "bus", "commands/s", "replies/s", "other");
    for (uint32_t j = 0; j < g.robot_cfg.n_joints; j++)
        printf("%-18s %4u %12.1f %12.1f %8llu\n", g.robot_cfg.joint_name[j],
               g.robot_cfg.act[j].bus_idx, (double)g.count[j].n_cmd / s,
               (double)g.count[j].n_reply / s, (unsigned long long)g.count[j].n_other);
}

int ps_monitor_main(int argc, char **argv, const char *data_dir)
{
    memset(&g, 0, sizeof(g));
    if (parse(argc, argv) < 0)
        return 2;
    char board_path[PATH_MAX], robot_path[PATH_MAX], err[PS_ERR_MSG_LEN];
    ps_config_resolve(data_dir, g.board, "boards", "sim", board_path, sizeof(board_path));
    ps_config_resolve(data_dir, g.robot, "robots", "ps1", robot_path, sizeof(robot_path));
    int rc = ps_config_load_board(board_path, &g.board_cfg, err, sizeof(err));
    if (rc == 0)
        rc = ps_config_load_robot(robot_path, &g.robot_cfg, err, sizeof(err));
    if (rc == 0)
        rc = ps_config_check_pair(&g.board_cfg, &g.robot_cfg, err, sizeof(err));
    if (rc < 0) {
        fprintf(stderr, "pushstep monitor: %s\n", err);
        return 2;
    }
    ps_monitor_init(&g.mon, &g.robot_cfg);
    struct sigaction sa = {.sa_handler = on_signal};
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
    double span_s = 0.0;
    int status = g.log_path != NULL ? run_log(&span_s) : run_live(&span_s);
    for (uint32_t b = 0; b < g.n_open; b++)
        ps_can_socket_close(&g.sock[b]);
    if (g.is_rates)
        print_rates(span_s);
    printf("monitor: %llu frames in %.3f s: %llu joint or IMU frames, %llu malformed, %llu "
           "unknown\n",
           (unsigned long long)g.n_frames, span_s,
           (unsigned long long)(g.n_frames - g.n_unknown - g.n_malformed),
           (unsigned long long)g.n_malformed, (unsigned long long)g.n_unknown);
    return status;
}
