#include "ps_args.h"
#include "ps_emulate.h"

#include <errno.h>
#include <fcntl.h>
#include <linux/can.h>
#include <linux/can/error.h>
#include <getopt.h>
#include <math.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "../drivers/ps_can_socket.h"
#include "../drivers/ps_gpio.h"
#include "../sim/ps_hoist.h"
#include "ps_app.h"
#include "ps_clock.h"
#include "ps_config.h"
#include "ps_config_sim.h"
#include "ps_err.h"

#define MAX_SAMPLES  (1u << 22) /* reaction samples kept: ~70 min of 1 kHz x 1 drive */
#define HB_SAMPLE_NS 250000LL   /* the relay looks at the heartbeat line 4 times a ms */

typedef struct {
    const char *board, *robot, *report_path, *estop_path, *heartbeat_path;
    char ifaces[PS_MAX_BUSES][PS_NAME_LEN];
    uint32_t n_ifaces;
    double duration_s, press_estop_at_s, bus_off_at_s, restart_at_s;
} emu_opts_t;

typedef struct {
    int64_t last_reply_ns; /* 0: no reply since the last command */
    int64_t last_cmd_ns;   /* kernel stamp of the previous command */
    uint64_t n_cmd_seen;   /* the drive's n_cmd_frames at the last look */
    uint64_t n_late;
} emu_joint_t;

static struct {
    emu_opts_t o;
    ps_board_cfg_t board;
    ps_robot_cfg_t robot;
    ps_sim_devices_cfg_t robot_sim;
    ps_sim_robot_t sim_robot;
    ps_hoist_t hoist;
    ps_can_socket_t sock[PS_MAX_BUSES];
    uint32_t n_open;
    emu_joint_t joint[PS_MAX_JOINTS];
    int64_t *reaction_ns;
    size_t n_reaction;
    uint64_t n_cmd[PS_MAX_BUSES], n_reply[PS_MAX_BUSES];
    int64_t first_cmd_ns[PS_MAX_BUSES], last_cmd_ns[PS_MAX_BUSES]; /* the span commands came in */
    int64_t period_ns, t0_ns;
    /* the longest time between two plant steps: a stall of the emulator's
     * own (a busy VM), which its drives' comms timeout would see too */
    int64_t last_step_ns, longest_step_gap_ns;
    /* e-stop and heartbeat */
    int estop_fd, heartbeat_fd;
    int64_t estop_press_ns, estop_seen_ns; /* 0: not yet */
    char hb_level;
    int64_t hb_first_ns, hb_last_change_ns, hb_stopped_ns;
    int64_t hb_changes_ns[8]; /* the last changes, a ring: hb_n_changes % 8 is next */
    uint64_t hb_n_changes;
    bool is_powered;
    bool is_bus_off_sent, is_restart_sent;
} e;

static volatile sig_atomic_t g_stop;

static void on_signal(int sig)
{
    (void)sig;
    g_stop = 1;
}

static const char USAGE[] =
    "usage: pushstep emulate --board FILE --ifaces IF0[,IF1...] [options]\n"
    "The robot on a hoist (free joints, trunk upright and still) at the far end of\n"
    "real CAN interfaces: every drive of the robot file answers in its protocol,\n"
    "the IMU sends its frames. For running the real drivers without a robot, e.g.\n"
    "in a VM: the runtime on vxcan0, the emulator on its peer vxcan1.\n"
    "\n"
    "  --board NAME|FILE       the runtime's board file (bus order, FD, bitrates)\n"
    "  --robot NAME|FILE       robot file (default robots/ps1.yaml)\n"
    "  --ifaces A,B,...        the far-end interface of each of the board's buses\n"
    "  --duration S            stop after S seconds (default: at SIGINT/SIGTERM)\n"
    "  --estop-file PATH       the e-stop line's pull, e.g. gpio-mockup's\n"
    "                          /sys/kernel/debug/gpio-mockup/gpiochip0/0\n"
    "  --press-estop-at S      press the e-stop S seconds after start (needs\n"
    "                          --estop-file; active-low as the board says)\n"
    "  --heartbeat-file PATH   the enable line's value: play the watchdog relay\n"
    "  --bus-off-at S          send a bus-off error report on bus 0 at S seconds\n"
    "  --restart-at S          send \"controller restarted\" on bus 0 at S seconds\n"
    "  --report FILE.json      write the figures as JSON\n"
    "Prints: frames, commands per second per bus, late commands, the longest\n"
    "gap between its own plant steps (a stall its drives' 100 ms comms timeout\n"
    "would see), reaction from each reply to the drive's next command\n"
    "(percentiles), e-stop to the first limp or damping command, when the\n"
    "heartbeat stopped.\n";

static int parse_ifaces(const char *arg)
{
    char buf[PS_MAX_BUSES * PS_NAME_LEN];
    snprintf(buf, sizeof(buf), "%s", arg);
    e.o.n_ifaces = 0;
    for (char *save = NULL, *t = strtok_r(buf, ",", &save); t; t = strtok_r(NULL, ",", &save)) {
        if (e.o.n_ifaces == PS_MAX_BUSES || strlen(t) >= PS_NAME_LEN)
            return -EINVAL;
        snprintf(e.o.ifaces[e.o.n_ifaces++], PS_NAME_LEN, "%s", t);
    }
    return e.o.n_ifaces > 0 ? 0 : -EINVAL;
}

static int parse_seconds(const char *arg, const char *name, double *out)
{
    if (ps_args_seconds(arg, 0.0, 1e6, false, out) < 0) {
        fprintf(stderr, "pushstep emulate: %s: '%s' is not a number of seconds in [0, 1e6]\n", name,
                arg);
        return -EINVAL;
    }
    return 0;
}

static int parse(int argc, char **argv)
{
    static const struct option LONG[] = {
        {"board", required_argument, NULL, 'b'},
        {"robot", required_argument, NULL, 'r'},
        {"ifaces", required_argument, NULL, 'i'},
        {"duration", required_argument, NULL, 'd'},
        {"estop-file", required_argument, NULL, 'e'},
        {"press-estop-at", required_argument, NULL, 'p'},
        {"heartbeat-file", required_argument, NULL, 'H'},
        {"report", required_argument, NULL, 'o'},
        {"bus-off-at", required_argument, NULL, 'B'},
        {"restart-at", required_argument, NULL, 'R'},
        {"help", no_argument, NULL, 'h'},
        {NULL, 0, NULL, 0},
    };
    e.o.press_estop_at_s = e.o.bus_off_at_s = e.o.restart_at_s = -1.0;
    int c;
    while ((c = getopt_long(argc, argv, "h", LONG, NULL)) != -1) {
        int rc = 0;
        switch (c) {
        case 'b':
            e.o.board = optarg;
            break;
        case 'r':
            e.o.robot = optarg;
            break;
        case 'i':
            if ((rc = parse_ifaces(optarg)) < 0)
                fprintf(stderr, "pushstep emulate: --ifaces: '%s': 1..%u names of < %u bytes\n",
                        optarg, PS_MAX_BUSES, PS_NAME_LEN);
            break;
        case 'd':
            rc = parse_seconds(optarg, "--duration", &e.o.duration_s);
            break;
        case 'e':
            e.o.estop_path = optarg;
            break;
        case 'p':
            rc = parse_seconds(optarg, "--press-estop-at", &e.o.press_estop_at_s);
            break;
        case 'H':
            e.o.heartbeat_path = optarg;
            break;
        case 'o':
            e.o.report_path = optarg;
            break;
        case 'B':
            rc = parse_seconds(optarg, "--bus-off-at", &e.o.bus_off_at_s);
            break;
        case 'R':
            rc = parse_seconds(optarg, "--restart-at", &e.o.restart_at_s);
            break;
        case 'h':
            fputs(USAGE, stdout);
            exit(0);
        default:
            rc = -EINVAL;
        }
        if (rc < 0)
            return rc;
    }
    if (optind < argc || e.o.board == NULL || e.o.n_ifaces == 0 ||
        (e.o.press_estop_at_s >= 0.0 && e.o.estop_path == NULL)) {
        fputs(USAGE, stderr);
        return -EINVAL;
    }
    return 0;
}

static int load(const char *data_dir, char *err, size_t len)
{
    char board_path[PATH_MAX], robot_path[PATH_MAX];
    ps_config_resolve(data_dir, e.o.board, "boards", "sim", board_path, sizeof(board_path));
    ps_config_resolve(data_dir, e.o.robot, "robots", "ps1", robot_path, sizeof(robot_path));
    int rc = ps_config_load_board(board_path, &e.board, err, len);
    if (rc == 0)
        rc = ps_config_load_robot_sim(robot_path, &e.robot, &e.robot_sim, err, len);
    if (rc == 0)
        rc = ps_config_check_pair(&e.board, &e.robot, err, len);
    if (rc == 0 && e.o.n_ifaces != e.board.n_buses) {
        snprintf(err, len, "--ifaces names %u interfaces, the board has %u buses", e.o.n_ifaces,
                 e.board.n_buses);
        rc = -PS_ERR_CONFIG;
    }
    if (rc < 0)
        return rc;
    ps_app_sim_robot(&e.robot, &e.robot_sim, &e.sim_robot);
    e.period_ns = PS_NS_PER_S / e.robot.control.servo_hz;
    return 0;
}

static int open_sockets(char *err, size_t len)
{
    for (uint32_t b = 0; b < e.board.n_buses; b++) {
        ps_can_socket_cfg_t c = {.is_fd = e.board.buses[b].is_fd,
                                 .bitrate = e.board.buses[b].bitrate,
                                 .n_filters = 2,
                                 .filters = {{0, 0, false}, {0, 0, true}}}; /* everything */
        snprintf(c.ifname, sizeof(c.ifname), "%s", e.o.ifaces[b]);
        const int rc = ps_can_socket_open(&e.sock[b], &c, err, len);
        if (rc < 0)
            return rc;
        e.n_open = b + 1u;
    }
    return 0;
}

static int open_lines(char *err, size_t len)
{
    e.estop_fd = e.heartbeat_fd = -1;
    e.is_powered = e.o.heartbeat_path == NULL; /* no relay to play: always on */
    if (e.o.estop_path != NULL) {
        e.estop_fd = open(e.o.estop_path, O_WRONLY | O_CLOEXEC);
        const ssize_t w = e.estop_fd < 0
                              ? -1
                              : write(e.estop_fd, e.board.gpio.is_estop_active_low ? "1" : "0", 1);
        if (w != 1) {
            const int er = w < 0 ? errno : EIO; /* a short write sets no errno */
            snprintf(err, len, "--estop-file %s: %s", e.o.estop_path, strerror(er));
            return -er;
        }
    }
    if (e.o.heartbeat_path != NULL) {
        e.heartbeat_fd = open(e.o.heartbeat_path, O_RDONLY | O_CLOEXEC);
        if (e.heartbeat_fd < 0) {
            snprintf(err, len, "--heartbeat-file %s: %s", e.o.heartbeat_path, strerror(errno));
            return -errno;
        }
    }
    ps_hoist_set_power(&e.hoist, e.is_powered);
    return 0;
}

static void press_estop(int64_t now)
{
    if (write(e.estop_fd, e.board.gpio.is_estop_active_low ? "0" : "1", 1) == 1)
        e.estop_press_ns = now;
}

/* The watchdog relay: power while the enable line changed within the timeout. */
static void watch_heartbeat(int64_t now)
{
    char v = 0;
    if (e.heartbeat_fd < 0 || pread(e.heartbeat_fd, &v, 1, 0) != 1)
        return;
    if (v != e.hb_level) {
        if (e.hb_level != 0 && e.hb_first_ns == 0)
            e.hb_first_ns = now;
        e.hb_level = v;
        e.hb_last_change_ns = now;
        e.hb_changes_ns[e.hb_n_changes++ % 8u] = now;
    }
    /* The relay's timeout is 10 periods of a 1 kHz loop; a slower loop (the
     * VM's robot) beats once a tick, so the relay waits 3 of its ticks. */
    const int64_t timeout_ns = PS_GPIO_HEARTBEAT_TIMEOUT_NS > 3 * e.period_ns
                                   ? PS_GPIO_HEARTBEAT_TIMEOUT_NS
                                   : 3 * e.period_ns;
    const bool is_beating = e.hb_first_ns != 0 && now - e.hb_last_change_ns <= timeout_ns;
    if (!is_beating && e.is_powered && e.hb_first_ns != 0 && e.hb_stopped_ns == 0)
        e.hb_stopped_ns = e.hb_last_change_ns; /* the first stop; later beats do not hide it */
    if (is_beating != e.is_powered) {
        e.is_powered = is_beating;
        ps_hoist_set_power(&e.hoist, is_beating);
    }
}

/* What a frame the drive took says: a command answered after our reply
 * (reaction), its spacing (late), and after an e-stop press the first limp
 * or damping command or disable. */
static void account(uint32_t j, const ps_can_frame_t *f, int64_t now)
{
    emu_joint_t *ej = &e.joint[j];
    const ps_devices_actuator_t *a = &e.hoist.act[j];
    const bool is_cmd = a->n_cmd_frames != ej->n_cmd_seen;
    ej->n_cmd_seen = a->n_cmd_frames;
    if (e.estop_press_ns != 0 && e.estop_seen_ns == 0 && f->t_ns >= e.estop_press_ns &&
        ((is_cmd && a->cmd.kp_nm_rad == 0.0f) || !a->is_motor_mode))
        e.estop_seen_ns = f->t_ns;
    if (!is_cmd)
        return;
    const uint32_t b = a->act.bus_idx;
    e.n_cmd[b]++;
    if (e.first_cmd_ns[b] == 0)
        e.first_cmd_ns[b] = f->t_ns;
    e.last_cmd_ns[b] = f->t_ns;
    if (ej->last_reply_ns != 0 && e.n_reaction < MAX_SAMPLES && e.reaction_ns != NULL)
        e.reaction_ns[e.n_reaction++] = f->t_ns - ej->last_reply_ns;
    ej->last_reply_ns = 0;
    const int64_t due_ns = (int64_t)a->act.rate_div * e.period_ns;
    if (ej->last_cmd_ns != 0 && f->t_ns - ej->last_cmd_ns > due_ns + e.period_ns / 2)
        ej->n_late++;
    ej->last_cmd_ns = f->t_ns;
    (void)now;
}

static void serve_bus(uint32_t b)
{
    ps_can_port_t port = ps_can_socket_port(&e.sock[b]);
    ps_can_frame_t rx[PS_CAN_SOCKET_BATCH], tx[PS_CAN_SOCKET_BATCH];
    int n = ps_can_recv_batch(&port, rx, PS_CAN_SOCKET_BATCH);
    if (n < 0) { /* the interface went down or away: say so, stop */
        fprintf(stderr, "pushstep emulate: bus %u %s: %s\n", b, e.o.ifaces[b], strerror(-n));
        g_stop = 1;
        return;
    }
    size_t n_tx = 0;
    int reply_joint[PS_CAN_SOCKET_BATCH];
    for (int i = 0; i < n; i++) {
        int j = -1;
        if (ps_hoist_take_frame(&e.hoist, b, &rx[i], &tx[n_tx], &j) == 1)
            reply_joint[n_tx++] = j;
        if (j >= 0)
            account((uint32_t)j, &rx[i], 0);
    }
    if (n_tx == 0)
        return;
    (void)ps_can_send_batch(&port, tx, n_tx);
    const int64_t sent_ns = ps_clock_now_ns(ps_clock_monotonic());
    for (size_t k = 0; k < n_tx; k++)
        if (reply_joint[k] >= 0)
            e.joint[reply_joint[k]].last_reply_ns = sent_ns;
    e.n_reply[b] += n_tx;
}

/* What a controller reports in an error frame (linux/can/error.h): class
 * bits in the identifier with CAN_ERR_FLAG, details in the data. Written raw
 * on the far end, the runtime's socket takes it as its controller's report. */
static void send_error_report(uint32_t classes)
{
    struct can_frame f;
    memset(&f, 0, sizeof(f));
    f.can_id = CAN_ERR_FLAG | classes;
    f.len = CAN_ERR_DLC;
    (void)write(e.sock[0].fd, &f, sizeof(f));
}

static bool is_due(double at_s, bool *sent, int64_t now)
{
    if (at_s < 0.0 || *sent || now - e.t0_ns < (int64_t)(at_s * 1e9))
        return false;
    *sent = true;
    return true;
}

static void step(int64_t now)
{
    if (e.last_step_ns != 0 && now - e.last_step_ns > e.longest_step_gap_ns)
        e.longest_step_gap_ns = now - e.last_step_ns;
    e.last_step_ns = now;
    if (is_due(e.o.bus_off_at_s, &e.is_bus_off_sent, now))
        send_error_report(CAN_ERR_BUSOFF);
    if (is_due(e.o.restart_at_s, &e.is_restart_sent, now))
        send_error_report(CAN_ERR_RESTARTED);
    ps_can_frame_t imu[PS_IMU_MAX_FRAMES];
    const int n_imu = ps_hoist_step(&e.hoist, now, (double)e.period_ns * 1e-9, imu);
    for (uint32_t j = 0; j < e.hoist.n_joints; j++) {
        ps_can_frame_t report;
        if (ps_devices_take_fault_report(&e.hoist.act[j], now, &report) == 1) {
            ps_can_port_t port = ps_can_socket_port(&e.sock[e.hoist.act[j].act.bus_idx]);
            (void)ps_can_send_batch(&port, &report, 1);
        }
    }
    if (n_imu > 0) {
        ps_can_port_t port = ps_can_socket_port(&e.sock[e.hoist.imu_bus_idx]);
        (void)ps_can_send_batch(&port, imu, (size_t)n_imu);
    }
    bool is_pressed = e.estop_press_ns != 0;
    if (e.estop_fd >= 0 && is_due(e.o.press_estop_at_s, &is_pressed, now))
        press_estop(now);
}

static void run(void)
{
    struct pollfd pfd[PS_MAX_BUSES];
    for (uint32_t b = 0; b < e.n_open; b++)
        pfd[b] = (struct pollfd){.fd = e.sock[b].fd, .events = POLLIN};
    const ps_clock_t *clk = ps_clock_monotonic();
    e.t0_ns = ps_clock_now_ns(clk);
    const int64_t end_ns = e.o.duration_s > 0 ? e.t0_ns + (int64_t)(e.o.duration_s * 1e9) : 0;
    int64_t next_ns = e.t0_ns + e.period_ns;
    int64_t next_hb_ns = e.t0_ns;
    while (!g_stop) {
        int64_t now = ps_clock_now_ns(clk);
        if (end_ns != 0 && now >= end_ns)
            break;
        /* The heartbeat changes once a loop tick: sampled at the loop's own
         * rate it would alias, so the relay looks at it every HB_SAMPLE_NS. */
        if (now >= next_hb_ns) {
            watch_heartbeat(now);
            next_hb_ns = now + HB_SAMPLE_NS;
        }
        if (now >= next_ns) {
            step(now);
            next_ns += e.period_ns;
            if (next_ns < now) /* fell behind (a slow VM): skip, do not burst */
                next_ns = now + e.period_ns;
            continue;
        }
        const int64_t wake_ns = next_ns < next_hb_ns ? next_ns : next_hb_ns;
        const struct timespec timeout = {.tv_sec = 0, .tv_nsec = (long)(wake_ns - now)};
        if (ppoll(pfd, e.n_open, &timeout, NULL) <= 0)
            continue;
        for (uint32_t b = 0; b < e.n_open && !g_stop; b++)
            if (pfd[b].revents & (POLLIN | POLLERR | POLLHUP | POLLNVAL))
                serve_bus(b);
    }
}

/* Commands per second while the runtime was sending: over the span from the
 * bus's first command to its last, not over the emulator's whole run. */
static double cmd_rate(uint32_t b)
{
    const double span_s = (double)(e.last_cmd_ns[b] - e.first_cmd_ns[b]) * 1e-9;
    return span_s > 0.0 ? (double)(e.n_cmd[b] - 1u) / span_s : 0.0;
}

static int cmp_i64(const void *a, const void *b)
{
    const int64_t x = *(const int64_t *)a, y = *(const int64_t *)b;
    return (x > y) - (x < y);
}

static double pct_us(double p)
{
    if (e.n_reaction == 0)
        return 0.0;
    size_t k = (size_t)ceil(p / 100.0 * (double)e.n_reaction);
    k = k == 0 ? 0 : k - 1;
    return (double)e.reaction_ns[k < e.n_reaction ? k : e.n_reaction - 1] * 1e-3;
}

static void report(FILE *out, double elapsed_s)
{
    qsort(e.reaction_ns, e.n_reaction, sizeof(e.reaction_ns[0]), cmp_i64);
    uint64_t late = 0;
    for (uint32_t j = 0; j < e.hoist.n_joints; j++)
        late += e.joint[j].n_late;
    fprintf(out, "emulate: %.3f s, %llu frames in, %llu replies, %llu unclaimed, %llu malformed\n",
            elapsed_s, (unsigned long long)e.hoist.n_frames, (unsigned long long)e.hoist.n_replies,
            (unsigned long long)e.hoist.n_unclaimed, (unsigned long long)e.hoist.n_bad_frames);
    for (uint32_t b = 0; b < e.n_open; b++)
        fprintf(out,
                "emulate: bus %u %s: %llu commands, %.1f/s while the runtime sent, %llu replies\n",
                b, e.o.ifaces[b], (unsigned long long)e.n_cmd[b], cmd_rate(b),
                (unsigned long long)e.n_reply[b]);
    fprintf(out, "emulate: late commands: %llu; longest gap between plant steps %.1f ms\n",
            (unsigned long long)late, (double)e.longest_step_gap_ns * 1e-6);
    fprintf(out,
            "emulate: reaction reply->next command (us): n %zu p50 %.1f p90 %.1f p99 %.1f "
            "p99.9 %.1f max %.1f\n",
            e.n_reaction, pct_us(50), pct_us(90), pct_us(99), pct_us(99.9), pct_us(100));
    if (e.estop_press_ns != 0 && e.estop_seen_ns != 0)
        fprintf(out,
                "emulate: e-stop pressed at %.3f s, first limp/damping command after %.3f ms "
                "(%.1f ticks)\n",
                (double)(e.estop_press_ns - e.t0_ns) * 1e-9,
                (double)(e.estop_seen_ns - e.estop_press_ns) * 1e-6,
                (double)(e.estop_seen_ns - e.estop_press_ns) / (double)e.period_ns);
    else if (e.estop_press_ns != 0)
        fprintf(out, "emulate: e-stop pressed at %.3f s, no limp/damping command seen after it\n",
                (double)(e.estop_press_ns - e.t0_ns) * 1e-9);
    if (e.heartbeat_fd >= 0)
        fprintf(out, "emulate: heartbeat: first beat %.3f s, stopped %s%.3f s\n",
                e.hb_first_ns ? (double)(e.hb_first_ns - e.t0_ns) * 1e-9 : -1.0,
                e.hb_stopped_ns ? "at " : "never: ",
                e.hb_stopped_ns ? (double)(e.hb_stopped_ns - e.t0_ns) * 1e-9 : elapsed_s);
}

static int write_json(double elapsed_s, char *err, size_t len)
{
    FILE *f = fopen(e.o.report_path, "w");
    if (f == NULL) {
        snprintf(err, len, "--report %s: %s", e.o.report_path, strerror(errno));
        return -errno;
    }
    uint64_t late = 0, n_cmd = 0;
    for (uint32_t j = 0; j < e.hoist.n_joints; j++)
        late += e.joint[j].n_late;
    for (uint32_t b = 0; b < e.n_open; b++)
        n_cmd += e.n_cmd[b];
    fprintf(f,
            "{\"duration_s\": %.3f, \"frames_in\": %llu, \"replies\": %llu, \"unclaimed\": %llu, "
            "\"malformed\": %llu, \"commands\": %llu, \"late_commands\": %llu,\n",
            elapsed_s, (unsigned long long)e.hoist.n_frames, (unsigned long long)e.hoist.n_replies,
            (unsigned long long)e.hoist.n_unclaimed, (unsigned long long)e.hoist.n_bad_frames,
            (unsigned long long)n_cmd, (unsigned long long)late);
    fprintf(f, " \"commands_per_s\": [");
    for (uint32_t b = 0; b < e.n_open; b++)
        fprintf(f, "%s%.1f", b ? ", " : "", cmd_rate(b));
    fprintf(f,
            "],\n \"reaction_us\": {\"n\": %zu, \"p50\": %.1f, \"p90\": %.1f, \"p99\": %.1f, "
            "\"p999\": %.1f, \"max\": %.1f},\n",
            e.n_reaction, pct_us(50), pct_us(90), pct_us(99), pct_us(99.9), pct_us(100));
    fprintf(f, " \"longest_step_gap_ms\": %.3f,\n", (double)e.longest_step_gap_ns * 1e-6);
    fprintf(f, " \"estop_reaction_ms\": %.3f, \"heartbeat_stopped_s\": %.3f,\n",
            e.estop_seen_ns && e.estop_press_ns
                ? (double)(e.estop_seen_ns - e.estop_press_ns) * 1e-6
                : -1.0,
            e.hb_stopped_ns ? (double)(e.hb_stopped_ns - e.t0_ns) * 1e-9 : -1.0);
    /* CLOCK_MONOTONIC, for a test that compares with its own events (a kill) */
    fprintf(f,
            " \"heartbeat_last_change_mono_ns\": %lld, \"start_mono_ns\": %lld, "
            "\"estop_press_mono_ns\": %lld,\n",
            (long long)e.hb_last_change_ns, (long long)e.t0_ns, (long long)e.estop_press_ns);
    fprintf(f, " \"heartbeat_changes\": %llu, \"heartbeat_last_changes_mono_ns\": [",
            (unsigned long long)e.hb_n_changes);
    const uint64_t n = e.hb_n_changes < 8u ? e.hb_n_changes : 8u;
    for (uint64_t i = 0; i < n; i++)
        fprintf(f, "%s%lld", i ? ", " : "",
                (long long)e.hb_changes_ns[(e.hb_n_changes - n + i) % 8u]);
    fprintf(f, "]}\n");
    return fclose(f) == 0 ? 0 : -EIO;
}

static void cleanup(void)
{
    for (uint32_t b = 0; b < e.n_open; b++)
        ps_can_socket_close(&e.sock[b]);
    if (e.estop_fd >= 0)
        close(e.estop_fd);
    if (e.heartbeat_fd >= 0)
        close(e.heartbeat_fd);
    free(e.reaction_ns);
}

int ps_emulate_main(int argc, char **argv, const char *data_dir)
{
    memset(&e, 0, sizeof(e));
    e.estop_fd = e.heartbeat_fd = -1;
    if (parse(argc, argv) < 0)
        return 2;
    char err[PS_ERR_MSG_LEN];
    int rc = load(data_dir, err, sizeof(err));
    if (rc < 0) {
        fprintf(stderr, "pushstep emulate: %s\n", err);
        return 2;
    }
    ps_hoist_init(&e.hoist, &e.sim_robot, 1u);
    e.reaction_ns = malloc(MAX_SAMPLES * sizeof(e.reaction_ns[0]));
    rc = e.reaction_ns == NULL ? -ENOMEM : open_sockets(err, sizeof(err));
    if (rc == 0)
        rc = open_lines(err, sizeof(err));
    if (rc < 0) {
        fprintf(stderr, "pushstep emulate: %s\n", rc == -ENOMEM ? "out of memory" : err);
        cleanup();
        return rc == -ENOMEM ? 1 : 2;
    }
    struct sigaction sa = {.sa_handler = on_signal};
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
    printf("emulate: %u joints on %u buses, IMU on bus %u, %.0f Hz\n", e.hoist.n_joints, e.n_open,
           e.hoist.imu_bus_idx, 1e9 / (double)e.period_ns);
    fflush(stdout);
    run();
    const double elapsed_s = (double)(ps_clock_now_ns(ps_clock_monotonic()) - e.t0_ns) * 1e-9;
    report(stdout, elapsed_s);
    rc = e.o.report_path != NULL ? write_json(elapsed_s, err, sizeof(err)) : 0;
    if (rc < 0)
        fprintf(stderr, "pushstep emulate: %s\n", err);
    cleanup();
    return rc < 0 ? 1 : 0;
}
