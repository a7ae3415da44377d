/*
 * pushstep: start-up, wiring and shutdown.
 *
 * This is the one place that knows which implementation sits behind each port:
 * it reads the board file and wires the simulated plant (board kind `sim`) or,
 * later, the SocketCAN and libgpiod drivers (kind `linux`) into the loop.
 * Everything here is INIT or NON-RT; the loop thread runs ps_loop_run only.
 */
#include <errno.h>
#include <getopt.h>
#include <libgen.h>
#include <limits.h>
#include <math.h>
#include <pthread.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <time.h>
#include <unistd.h>

#include "../drivers/ps_candump.h"
#include "../sim/ps_plant.h"
#include "../sim/ps_render.h"
#include "ps_args.h"
#include "ps_app.h"
#include "ps_doctor.h"
#include "ps_camview.h"
#include "ps_emulate.h"
#include "ps_monitor.h"
#include "ps_err.h"
#include "ps_guard.h"
#include "ps_logger.h"
#include "ps_profile.h"
#include "ps_reclog.h"
#include "ps_recorder.h"
#include "ps_rtsetup.h"
#include "ps_summary.h"

#define STACK_PREFAULT    (256u * 1024u)
#define RT_START_LEAD_NS  (20 * PS_NS_PER_MS)
#define LOCKSTEP_START_NS PS_NS_PER_S /* t = 0 means "never" in measurements */
#define TRUTH_POLL_NS     (10 * PS_NS_PER_MS)
/* --candump: 2^16 frames (5.8 MB): the logger drains every 5 ms; a 1 kHz
 * loop moves about 50 frames a tick, lockstep some 13 times as many. */
#define PS_CANDUMP_RING_SLOTS (1u << 16)

typedef struct {
    const char *board;
    const char *robot;
    const char *scenario;
    double duration_s;
    bool has_duration;
    bool is_lockstep;
    bool is_rt_required;
    bool is_quiet;
    const char *summary_path;
    double start_after_s;     /**< real boards: request START after this; < 0 never */
    bool is_profile;          /**< `pushstep profile` */
    const char *out_dir;      /**< profile output folder */
    const char *stress;       /**< profile: stress-ng load, NULL none */
    bool is_trace;            /**< trace_marker points */
    const char *candump_path; /**< --candump: every frame as a candump -L line */
    const char *replay_path;  /**< --replay: buses fed from this candump -L log */
    const char *crowd_log;    /**< --crowd-log: the crowd's measurements per tick, CSV */
    const char *render_dir;   /**< --render: frames, density map, MP4 */
    double render_fps;        /**< --render-fps */
    bool is_view;             /**< --view: live window */
    const char *policy;       /**< --policy: the controller in the policy slot */
    const char *weights;      /**< --weights: the MLP's policy file */
    unsigned hist_us;         /**< wake-up histogram buckets (cyclictest -h N) */
    const char *record_path;  /**< --record: every tick to this MCAP file */
    const char *flight_dir;   /**< --flight: triggered dumps into this folder */
    double flight_pre_s, flight_post_s;
    double record_ring_s; /**< --record-ring; 0: the recorder's default */
    ps_mcap_compression_t compression;
} options_t;

/* Everything the run owns; static because ps_app_t is large and must not
 * live on a thread stack. */
static struct {
    options_t opt;
    char data_dir[PATH_MAX];
    ps_app_t app;
    ps_logger_t logger;
    ps_trace_t trace;
    ps_ring_t frame_ring;
    ps_loop_frame_rec_t *frame_storage; /**< PS_CANDUMP_RING_SLOTS, --candump only */
    ps_logger_frames_t frames;
    ps_recorder_t rec;
    _Atomic bool is_recording; /**< the signal handler may trigger rec */
    pid_t stress_pid;
    int cpu_latency_fd;
    int64_t start_ns, end_ns;
    unsigned rt_missing;
    ps_guard_counts_t guard;
    FILE *crowd_log;
    uint64_t n_crowd_samples;
    ps_render_t *render;
    int loop_rc;
    _Atomic bool is_loop_done;
    _Atomic unsigned n_reloads; /* SIGHUP: configuration reloads asked for (all refused) */
    unsigned n_reloads_told;
} g;

/* Lockstep and replay run on a clock the loop itself moves: no real-time
 * setup, no pacing. */
static bool is_unpaced(void)
{
    return g.opt.is_lockstep || g.opt.replay_path != NULL;
}

static const char USAGE[] =
    "usage: pushstep [options]\n"
    "       pushstep profile [options] [profile options]\n"
    "       pushstep monitor --board FILE [--log FILE] (see pushstep monitor -h)\n"
    "       pushstep emulate --board FILE --ifaces IF,... (see pushstep emulate -h)\n"
    "       pushstep doctor [--board FILE] (see pushstep doctor -h)\n"
    "       pushstep log FILE.mcap [--csv OUT] [--plot OUT.png] (see pushstep log -h)\n"
    "       pushstep camera --board FILE (see pushstep camera -h)\n"
    "Runs the balance controller's fixed-step loop against a board: real hardware\n"
    "or, for board `sim`, the MuJoCo plant with emulated CAN actuators, IMU and GPIO.\n"
    "\n"
    "  --board NAME|FILE     board file, or NAME for boards/NAME.yaml (default sim)\n"
    "  --robot FILE          robot file: joint map, ranges, gains, limits\n"
    "                        (default robots/ps1.yaml)\n"
    "  --scenario FILE       simulation scenario: the crowd, operator events, pushes,\n"
    "                        faults (default scenarios/crowd.yaml on board sim)\n"
    "  --policy NAME         the controller in the policy slot: stand (ankle\n"
    "                        strategy), capture (capture-point stepping) or mlp\n"
    "                        (the trained policy, capture as its fallback)\n"
    "                        (default: the robot file's policy.controller, else stand)\n"
    "  --weights FILE        --policy mlp: the policy file (safetensors with its\n"
    "                        contract; default: the robot file's policy.weights)\n"
    "  --duration S          run S seconds of loop time, then stop through damping\n"
    "                        (default: the scenario's duration_s; 0 = until Ctrl-C)\n"
    "  --lockstep            simulation only: no real-time pacing; loop and plant\n"
    "                        alternate on simulated time, as fast as the plant allows,\n"
    "                        deterministic for a scenario seed while no tick\n"
    "                        overruns and no policy step is late on CPU time\n"
    "                        (the summary's \"deterministic\")\n"
    "  --summary FILE.json   write the end summary as JSON: ticks, overruns, whether a\n"
    "                        lockstep run was deterministic, latency\n"
    "                        percentiles per stage, state transitions, mallocs,\n"
    "                        page faults and locks after init, bus loads, fall\n"
    "                        detected, how far the simulated plant fell behind,\n"
    "                        the policy slot's controller (mlp: how often its\n"
    "                        fallback took over, and why)\n"
    "  --require-rt          fail instead of warning when mlockall, SCHED_FIFO or CPU\n"
    "                        affinity are not permitted, or (not in profile) when the\n"
    "                        simulated plant falls behind real time\n"
    "  --start-after S       real boards and --replay: request START S seconds after\n"
    "                        start (on board sim the scenario's events do this)\n"
    "  --quiet               no status lines (transitions and the summary still print)\n"
    "  --candump FILE        write every CAN frame the loop reads and sends as a\n"
    "                        candump -L log line (canplayer, log2long read it);\n"
    "                        times are the loop's clock (simulated in lockstep)\n"
    "  --replay FILE.log     feed the loop the replies and IMU frames of a candump -L\n"
    "                        log (interfaces named as the board's buses; any board)\n"
    "                        instead of a plant or the wire: unpaced on the log's time,\n"
    "                        to its last frame or --duration; the loop's commands are\n"
    "                        compared with the logged ones. Open loop: the replies do\n"
    "                        not answer the commands (docs/can-protocols.md, 5)\n"
    "  --crowd-log FILE.csv  simulated crowd: its measurements every tick (time, agents\n"
    "                        fallen and stepping, density around the robot, crowd force\n"
    "                        on the robot and on each of its bodies, transmitted\n"
    "                        impulse, deepest penetration) as CSV\n"
    "  --render DIR          simulation: pictures of the scene into DIR (made if\n"
    "                        missing): frame_NNNNN.png at --render-fps of simulated\n"
    "                        time with the crowd's contact forces on the robot's\n"
    "                        parts, density.png (the crowd from above), crowd.mp4\n"
    "                        (ffmpeg); offscreen (EGL), no display needed\n"
    "  --render-fps N        frames per simulated second (default 25)\n"
    "  --view                simulation: show the scene live in a window (needs a\n"
    "                        display)\n"
    "  --trace               write trace points to ftrace's trace_marker (tick start,\n"
    "                        end, overruns, state changes) for trace-cmd/KernelShark\n"
    "  --record FILE.mcap    flight recorder, continuous: every tick (joints, IMU,\n"
    "                        estimate, state, timing, buses, policy, sim truth,\n"
    "                        events) to an MCAP file (Foxglove, PlotJuggler read it)\n"
    "  --flight DIR          flight recorder, triggered: on e-stop, fall, watchdog,\n"
    "                        overrun burst, the GPIO record button or SIGUSR1, the\n"
    "                        seconds around it to DIR/flight-NNNN.mcap\n"
    "  --flight-pre S        seconds kept before a trigger (default 5, 0..600)\n"
    "  --flight-post S       seconds written after it (default 2, 0..600)\n"
    "  --record-compression zstd|lz4|none  chunk compression (default zstd)\n"
    "  --record-ring S       recorder ring in seconds of ticks, the most a slow disk\n"
    "                        may lag before records are lost (default pre + post + 1,\n"
    "                        at least 2; about 2.5 kB a tick)\n"
    "  -h, --help            this text\n"
    "\n"
    "pushstep profile runs the real loop (any board, sim included; default 30 s) and\n"
    "reports min/avg/p50/p99/p99.9/max per stage (wake-up latency, read, estimate,\n"
    "policy, servo, write, tick, tick on plain and on policy ticks) and overruns:\n"
    "  --out DIR             output folder (default ./profile): profile.json,\n"
    "                        wakeup.hist (cyclictest -h text format), PNG plots\n"
    "                        when gnuplot is installed\n"
    "  --stress cpu|mem|io   run stress-ng (Debian package stress-ng) beside the loop\n"
    "  --hist-us N           wake-up histogram size in 1-us buckets (default 1000,\n"
    "                        at most 10000), like cyclictest -h N\n"
    "\n"
    "Ctrl-C (or the end of --duration) brakes the robot through DAMPING to STANDBY\n"
    "before exiting; a second Ctrl-C while braking requests e-stop. SIGHUP (reload)\n"
    "is refused and logged: the files are read once, at start.\n"
    "A soft fault while ACTIVE (stale reply or IMU, late policy, invalid targets,\n"
    "repeated overruns, refused frames) HOLDs the last safe pose until the operator\n"
    "stops or restarts, a fall, or control.hold_s; see docs/safety.md.\n"
    "Board, robot and scenario NAMEs are looked up in $PUSHSTEP_DATA_DIR, else next\n"
    "to the binary's folder (build/.. = the repository), else in share/pushstep\n"
    "beside it (installed: PREFIX/bin/.. -> PREFIX/share/pushstep), else the\n"
    "current folder.\n"
    "Exit status: 0 ok, 1 runtime failure, 2 bad usage or configuration.\n";

/* ---- options and paths ------------------------------------------------ */

static int parse_seconds(const char *text, const char *what, double *out)
{
    if (ps_args_seconds(text, 0.0, 86400.0, false, out) < 0) {
        fprintf(stderr, "pushstep: %s: \"%s\" is not a number of seconds in [0, 86400]\n", what,
                text);
        return -EINVAL;
    }
    return 0;
}

static int parse_options(int argc, char **argv, options_t *o)
{
    enum {
        O_LOCKSTEP = 256,
        O_SUMMARY,
        O_REQUIRE_RT,
        O_START_AFTER,
        O_QUIET,
        O_OUT,
        O_STRESS,
        O_TRACE,
        O_HIST_US,
        O_CANDUMP,
        O_REPLAY,
        O_CROWD_LOG,
        O_RECORD,
        O_FLIGHT,
        O_FLIGHT_PRE,
        O_FLIGHT_POST,
        O_RECORD_COMPRESSION,
        O_RECORD_RING,
        O_RENDER,
        O_RENDER_FPS,
        O_VIEW,
        O_POLICY,
        O_WEIGHTS
    };
    static const struct option LONG[] = {
        {"board", required_argument, NULL, 'b'},
        {"robot", required_argument, NULL, 'r'},
        {"scenario", required_argument, NULL, 's'},
        {"duration", required_argument, NULL, 'd'},
        {"lockstep", no_argument, NULL, O_LOCKSTEP},
        {"summary", required_argument, NULL, O_SUMMARY},
        {"require-rt", no_argument, NULL, O_REQUIRE_RT},
        {"start-after", required_argument, NULL, O_START_AFTER},
        {"quiet", no_argument, NULL, O_QUIET},
        {"out", required_argument, NULL, O_OUT},
        {"stress", required_argument, NULL, O_STRESS},
        {"trace", no_argument, NULL, O_TRACE},
        {"hist-us", required_argument, NULL, O_HIST_US},
        {"candump", required_argument, NULL, O_CANDUMP},
        {"replay", required_argument, NULL, O_REPLAY},
        {"crowd-log", required_argument, NULL, O_CROWD_LOG},
        {"record", required_argument, NULL, O_RECORD},
        {"flight", required_argument, NULL, O_FLIGHT},
        {"flight-pre", required_argument, NULL, O_FLIGHT_PRE},
        {"flight-post", required_argument, NULL, O_FLIGHT_POST},
        {"record-compression", required_argument, NULL, O_RECORD_COMPRESSION},
        {"record-ring", required_argument, NULL, O_RECORD_RING},
        {"render", required_argument, NULL, O_RENDER},
        {"render-fps", required_argument, NULL, O_RENDER_FPS},
        {"view", no_argument, NULL, O_VIEW},
        {"policy", required_argument, NULL, O_POLICY},
        {"weights", required_argument, NULL, O_WEIGHTS},
        {"help", no_argument, NULL, 'h'},
        {NULL, 0, NULL, 0},
    };
    *o = (options_t){.board = "sim",
                     .start_after_s = -1.0,
                     .out_dir = "profile",
                     .hist_us = 1000,
                     .flight_pre_s = 5.0,
                     .flight_post_s = 2.0,
                     .compression = PS_MCAP_COMPRESS_ZSTD,
                     .render_fps = 25.0};
    if (argc > 1 && strcmp(argv[1], "profile") == 0) {
        o->is_profile = true;
        argv[1] = argv[0]; /* getopt starts after the subcommand */
        argc--;
        argv++;
    }
    bool is_profile_option = false;
    int c;
    while ((c = getopt_long(argc, argv, "h", LONG, NULL)) != -1) {
        switch (c) {
        case 'b':
            o->board = optarg;
            break;
        case 'r':
            o->robot = optarg;
            break;
        case 's':
            o->scenario = optarg;
            break;
        case 'd':
            if (parse_seconds(optarg, "--duration", &o->duration_s) < 0)
                return -EINVAL;
            o->has_duration = true;
            break;
        case O_LOCKSTEP:
            o->is_lockstep = true;
            break;
        case O_SUMMARY:
            o->summary_path = optarg;
            break;
        case O_REQUIRE_RT:
            o->is_rt_required = true;
            break;
        case O_START_AFTER:
            if (parse_seconds(optarg, "--start-after", &o->start_after_s) < 0)
                return -EINVAL;
            break;
        case O_QUIET:
            o->is_quiet = true;
            break;
        case O_CANDUMP:
            o->candump_path = optarg;
            break;
        case O_REPLAY:
            o->replay_path = optarg;
            break;
        case O_CROWD_LOG:
            o->crowd_log = optarg;
            break;
        case O_RENDER:
            o->render_dir = optarg;
            break;
        case O_RENDER_FPS: {
            char *end = NULL;
            o->render_fps = strtod(optarg, &end);
            if (end == optarg || *end != '\0' || !(o->render_fps > 0.0) || o->render_fps > 200.0) {
                fprintf(stderr, "pushstep: --render-fps: \"%s\" is not a rate in (0, 200]\n",
                        optarg);
                return -EINVAL;
            }
            break;
        }
        case O_VIEW:
            o->is_view = true;
            break;
        case O_RECORD:
            o->record_path = optarg;
            break;
        case O_FLIGHT:
            o->flight_dir = optarg;
            break;
        case O_FLIGHT_PRE:
        case O_FLIGHT_POST: {
            double *v = c == O_FLIGHT_PRE ? &o->flight_pre_s : &o->flight_post_s;
            if (parse_seconds(optarg, c == O_FLIGHT_PRE ? "--flight-pre" : "--flight-post", v) <
                    0 ||
                *v > 600.0) {
                fprintf(stderr, "pushstep: %s: at most 600 s\n",
                        c == O_FLIGHT_PRE ? "--flight-pre" : "--flight-post");
                return -EINVAL;
            }
            break;
        }
        case O_RECORD_RING:
            if (parse_seconds(optarg, "--record-ring", &o->record_ring_s) < 0 ||
                o->record_ring_s < 0.1 || o->record_ring_s > 600.0) {
                fprintf(stderr, "pushstep: --record-ring: 0.1 to 600 s\n");
                return -EINVAL;
            }
            break;
        case O_RECORD_COMPRESSION:
            if (ps_mcap_parse_compression(optarg, &o->compression) < 0) {
                fprintf(stderr,
                        "pushstep: --record-compression: \"%s\" is not one of zstd, lz4, none\n",
                        optarg);
                return -EINVAL;
            }
            break;
        case O_POLICY:
            if (ps_config_policy_find(optarg) < 0) {
                fprintf(stderr, "pushstep: --policy: \"%s\" is not one of %s\n", optarg,
                        PS_CONFIG_POLICY_NAMES);
                return -EINVAL;
            }
            o->policy = optarg;
            break;
        case O_WEIGHTS:
            o->weights = optarg;
            break;
        case O_OUT:
            o->out_dir = optarg;
            is_profile_option = true;
            break;
        case O_STRESS:
            if (ps_profile_check_stress(optarg) < 0) {
                fprintf(stderr, "pushstep: --stress: \"%s\" is not one of cpu, mem, io\n", optarg);
                return -EINVAL;
            }
            o->stress = optarg;
            is_profile_option = true;
            break;
        case O_TRACE:
            o->is_trace = true;
            break;
        case O_HIST_US: {
            char *end = NULL;
            unsigned long n = strtoul(optarg, &end, 10);
            if (end == optarg || *end != '\0' || n < 1 || n > PS_PERF_US_BUCKETS) {
                fprintf(stderr, "pushstep: --hist-us: \"%s\" is not a number in [1, %u]\n", optarg,
                        PS_PERF_US_BUCKETS);
                return -EINVAL;
            }
            o->hist_us = (unsigned)n;
            is_profile_option = true;
            break;
        }
        case 'h':
            fputs(USAGE, stdout);
            exit(0);
        default:
            fputs(USAGE, stderr);
            return -EINVAL;
        }
    }
    if (is_profile_option && !o->is_profile) {
        fprintf(stderr, "pushstep: --out, --stress and --hist-us belong to `pushstep profile`\n");
        return -EINVAL;
    }
    if (o->is_profile && o->is_lockstep) {
        fprintf(stderr, "pushstep: profile measures the real loop; --lockstep does not apply\n");
        return -EINVAL;
    }
    if (o->replay_path != NULL && (o->is_profile || o->is_lockstep || o->scenario != NULL)) {
        fprintf(stderr, "pushstep: --replay runs unpaced on the log's time and has no plant: "
                        "it does not go with profile, --lockstep or --scenario\n");
        return -EINVAL;
    }
    if (o->is_profile && !o->has_duration) {
        o->duration_s = 30.0;
        o->has_duration = true;
    }
    if (optind < argc) {
        fprintf(stderr, "pushstep: unexpected argument \"%s\"\n%s", argv[optind], USAGE);
        return -EINVAL;
    }
    return 0;
}

/* Where boards/, robots/, scenarios/ and sim/models/ are: $PUSHSTEP_DATA_DIR,
 * else one level above the binary (build/pushstep -> repository root) when
 * boards/ is there, else share/pushstep beside the binary's folder (an
 * installed PREFIX/bin/pushstep -> PREFIX/share/pushstep), else the current
 * directory. */
static void find_data_dir(char *out, size_t len)
{
    const char *env = getenv("PUSHSTEP_DATA_DIR");
    if (env != NULL && env[0] != '\0') {
        snprintf(out, len, "%s", env);
        return;
    }
    char exe[PATH_MAX];
    ssize_t n = readlink("/proc/self/exe", exe, sizeof(exe) - 1);
    if (n > 0) {
        exe[n] = '\0';
        static const char *const BESIDE[] = {"..", "../share/pushstep"};
        const char *bin_dir = dirname(exe);
        for (size_t i = 0; i < sizeof(BESIDE) / sizeof(BESIDE[0]); i++) {
            snprintf(out, len, "%s/%s", bin_dir, BESIDE[i]);
            char probe[PATH_MAX + 16];
            snprintf(probe, sizeof(probe), "%s/boards", out);
            if (access(probe, R_OK) == 0)
                return;
        }
    }
    snprintf(out, len, ".");
}

/* ---- real-time setup -------------------------------------------------- */

/* A sanitizer's shadow memory spans terabytes, reserved but never backed:
 * locking or prefaulting it would exhaust the machine. Such a build (make
 * test's ThreadSanitizer runtime, tests/test_tsan_threads.sh) runs without
 * either, reported as mlockall missing. */
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define PS_IS_SANITIZED 1
#else
#define PS_IS_SANITIZED 0
#endif

static int setup_process_rt(void)
{
    g.cpu_latency_fd = -1;
    if (!is_unpaced() && ps_rtsetup_hold_cpu_latency(&g.cpu_latency_fd) < 0)
        g.rt_missing |= PS_RT_MISSING_CPU_LATENCY;
    if (PS_IS_SANITIZED) {
        g.rt_missing |= PS_RT_MISSING_MLOCK;
        return 0;
    }
    int rc = ps_rtsetup_lock_memory();
    if (rc < 0) {
        g.rt_missing |= PS_RT_MISSING_MLOCK;
        long pages = ps_rtsetup_prefault_maps();
        (void)pages; /* best effort: only lowers the odds of later faults */
    }
    return 0;
}

static void report_rt(void)
{
    if (g.rt_missing == 0)
        return;
    char what[200];
    ps_rtsetup_describe(g.rt_missing, what, sizeof(what));
    bool is_fatal =
        g.opt.is_rt_required && (g.rt_missing & ~(unsigned)PS_RT_MISSING_CPU_LATENCY) != 0;
    if (is_fatal)
        fprintf(stderr, "pushstep: real-time setup not permitted: %s\n", what);
    else if (g.opt.is_rt_required)
        fprintf(stderr, "pushstep: warning: %s; --require-rt does not require it, running on\n",
                what);
    else
        fprintf(stderr,
                "pushstep: warning: real-time setup incomplete: %s; running on without "
                "(--require-rt makes this fatal)\n",
                what);
}

/* ---- the loop thread -------------------------------------------------- */

static void *loop_thread_main(void *arg)
{
    (void)arg;
    if (!is_unpaced())
        g.rt_missing |= ps_rtsetup_thread(g.app.board.rt.priority, g.app.board.rt.loop_cpu);
    report_rt(); /* still INIT: the loop has not started */
    /* The PM QoS request lowers latency but is not a precondition of real
     * time: it warns, never fails the run. */
    if (g.opt.is_rt_required && (g.rt_missing & ~(unsigned)PS_RT_MISSING_CPU_LATENCY) != 0) {
        g.loop_rc = -PS_ERR_RT_UNAVAILABLE;
        atomic_store(&g.is_loop_done, true);
        return NULL;
    }
    ps_rtsetup_prefault_stack(STACK_PREFAULT);
    ps_guard_arm();
    g.loop_rc = ps_loop_run(&g.app.loop, g.start_ns, g.end_ns);
    ps_guard_disarm(&g.guard);
    atomic_store(&g.is_loop_done, true);
    return NULL;
}

static void on_signal(int sig)
{
    (void)sig;
    ps_loop_request_stop(&g.app.loop);
}

/* SIGHUP, the usual "reload your configuration": refused, in every state
 * (the loop runs on the files it started with; docs/safety.md). Without a
 * handler it would end the process unbraked. Told on the main thread. */
static void on_reload_signal(int sig)
{
    (void)sig;
    atomic_fetch_add(&g.n_reloads, 1u);
}

static void tell_reloads_refused(void)
{
    const unsigned n = atomic_load(&g.n_reloads);
    if (n == g.n_reloads_told)
        return;
    g.n_reloads_told = n;
    printf("config reload refused (SIGHUP) in %s: board, robot and scenario are read once, at "
           "start; stop the robot and restart pushstep to use changed files\n",
           ps_sm_state_name(ps_loop_get_state(&g.app.loop)));
    fflush(stdout);
}

/* SIGUSR1: a flight-recorder trigger (installed only when recording). */
static void on_trigger_signal(int sig)
{
    (void)sig;
    if (atomic_load(&g.is_recording))
        ps_recorder_trigger(&g.rec, PS_REC_TRIG_SIGNAL);
}

/* --record / --flight, once the configuration is good: the ring (touched
 * now), the files checked, the loop tapped. */
static int setup_recorder(char *err, size_t len)
{
    ps_recorder_cfg_t rc_cfg = {
        .path = g.opt.record_path,
        .dir = g.opt.flight_dir,
        .pre_s = g.opt.flight_pre_s,
        .post_s = g.opt.flight_post_s,
        .ring_s = g.opt.record_ring_s,
        .compression = g.opt.compression,
        .is_sync_chunks = true,
        .cpu = g.app.board.rt.worker_cpu,
        .is_lossless = is_unpaced(), /* no deadline to keep: wait for the writer */
    };
    ps_app_recorder_cfg(&g.app, &rc_cfg);
    int rc = ps_recorder_init(&g.rec, &rc_cfg, err, len);
    if (rc < 0)
        return rc;
    ps_app_attach_recorder(&g.app, &g.rec);
    atomic_store(&g.is_recording, true); /* SIGUSR1 triggers from now on */
    return 0;
}

/* With --record or --flight, from the start of main: SIGUSR1 asks for a dump
 * (ignored until the recorder is ready, instead of killing a process that
 * is still loading its model), and a file size limit fails writes instead
 * of the process (SIGXFSZ ignored). */
static int install_recorder_signals(void)
{
    struct sigaction sa;
    memset(&sa, 0, sizeof(sa));
    sa.sa_handler = on_trigger_signal;
    sigemptyset(&sa.sa_mask);
    struct sigaction ign;
    memset(&ign, 0, sizeof(ign));
    ign.sa_handler = SIG_IGN;
    sigemptyset(&ign.sa_mask);
    if (sigaction(SIGUSR1, &sa, NULL) < 0 || sigaction(SIGXFSZ, &ign, NULL) < 0)
        return -errno;
    return 0;
}

/* SIGINT, SIGTERM and SIGHUP are blocked from the start of main until the
 * loop is initialised, with the handlers already installed: a signal during start-up
 * (loading the model takes a while) stays pending instead of killing the
 * process unbraked or being lost to ps_loop_init's zeroing, and is acted on
 * (a stop request) the moment it is unblocked. Threads start after that and
 * inherit the unblocked mask. */
static int block_stop_signals(int how)
{
    sigset_t set;
    sigemptyset(&set);
    sigaddset(&set, SIGINT);
    sigaddset(&set, SIGTERM);
    sigaddset(&set, SIGHUP);
    return -pthread_sigmask(how, &set, NULL);
}

static int install_signals(void)
{
    struct sigaction sa;
    memset(&sa, 0, sizeof(sa));
    sa.sa_handler = on_signal;
    sigemptyset(&sa.sa_mask);
    if (sigaction(SIGINT, &sa, NULL) < 0 || sigaction(SIGTERM, &sa, NULL) < 0)
        return -errno;
    sa.sa_handler = on_reload_signal;
    if (sigaction(SIGHUP, &sa, NULL) < 0)
        return -errno;
    return 0;
}

static int64_t wall_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * PS_NS_PER_S + ts.tv_nsec;
}

/* --candump, before the loop is built: the ring it fills, touched now so
 * that the loop's first pushes do not fault pages in. */
static int alloc_candump_ring(char *err, size_t len)
{
    const size_t bytes = PS_CANDUMP_RING_SLOTS * sizeof(ps_loop_frame_rec_t);
    g.frame_storage = malloc(bytes);
    if (g.frame_storage == NULL) {
        ps_err_format(err, len, "no memory for the frame ring (%zu bytes)", bytes);
        return -ENOMEM;
    }
    memset(g.frame_storage, 0, bytes);
    g.frames.ring = &g.frame_ring;
    return ps_ring_init(&g.frame_ring, g.frame_storage, PS_CANDUMP_RING_SLOTS,
                        sizeof(ps_loop_frame_rec_t));
}

/* --candump, once the configuration is good (an existing log is not
 * truncated by a run that never starts): every bus name must fit a candump
 * line, then the file is made. */
static int open_candump_file(char *err, size_t len)
{
    for (uint32_t b = 0; b < g.app.board.n_buses; b++) {
        const char *name = g.app.board.buses[b].ifname;
        if (!ps_candump_is_valid_ifname(name)) {
            ps_err_format(err, len,
                          "%s: buses[%u].ifname \"%s\" does not fit a candump line (1..15 "
                          "bytes, no blanks)",
                          g.app.board_path, b, name);
            return -EINVAL;
        }
        g.frames.ifname[b] = name;
    }
    g.frames.n_buses = g.app.board.n_buses;
    g.frames.out = fopen(g.opt.candump_path, "w");
    if (g.frames.out == NULL) {
        const int e = errno;
        ps_err_format(err, len, "%s: %s", g.opt.candump_path, strerror(e));
        return -e;
    }
    return 0;
}

/* Report what the log holds and what it lost; -EIO when the file could not
 * be written in full. */
static int close_candump(void)
{
    if (g.frames.out == NULL)
        return 0;
    const uint64_t n_dropped = ps_ring_dropped(&g.frame_ring);
    const bool is_bad = ferror(g.frames.out) != 0;
    const bool is_closed = fclose(g.frames.out) == 0;
    g.frames.out = NULL;
    free(g.frame_storage);
    g.frame_storage = NULL;
    printf("candump: %llu frames to %s", (unsigned long long)g.frames.n_lines, g.opt.candump_path);
    if (n_dropped > 0 || g.frames.n_refused > 0)
        printf(" (WARNING: %llu frames lost: the ring was full; %llu refused)",
               (unsigned long long)n_dropped, (unsigned long long)g.frames.n_refused);
    printf("\n");
    if (is_bad || !is_closed) {
        fprintf(stderr, "pushstep: --candump: writing %s failed\n", g.opt.candump_path);
        return -EIO;
    }
    return 0;
}

/* A recording asked for that could not be written (a file that failed):
 * the run's outputs are incomplete. Records lost to a slow disk are only
 * reported (the summary says how many). */
static bool recorder_failed(void)
{
    const ps_recorder_stats_t *s = &g.rec.stats;
    if (s->cont.err != 0)
        fprintf(stderr, "pushstep: --record %s: %s; %llu records not written\n", s->cont.path,
                strerror(-s->cont.err), (unsigned long long)s->cont.n_lost_io);
    if (s->n_dumps_failed > 0)
        fprintf(stderr, "pushstep: --flight %s: %u of %u dumps failed\n", g.opt.flight_dir,
                s->n_dumps_failed, s->n_dumps);
    return s->cont.err != 0 || s->n_dumps_failed > 0;
}

/* Wait for the loop thread to end. (The lowest CoM while the controller is in
 * charge is recorded by the plant on simulated time, ps_sim_truth_t.) */
static void drain_crowd_log(void)
{
    ps_sim_crowd_sample_t cs;
    while (g.app.sim != NULL && ps_sim_take_crowd_sample(g.app.sim, &cs) == 0) {
        g.n_crowd_samples++;
        if (g.crowd_log == NULL)
            continue;
        fprintf(g.crowd_log, "%.4f,%u,%u,%.3f,%.2f,%.4f,%.5f", cs.t_s, cs.n_fallen, cs.n_stepping,
                (double)cs.local_density_m2, (double)cs.robot_force_n,
                (double)cs.transmitted_impulse_ns, (double)cs.penetration_m);
        for (uint32_t k = 0; k < cs.n_parts && k < PS_CROWD_MAX_PARTS; k++)
            fprintf(g.crowd_log, ",%.2f", (double)cs.part_force_n[k]);
        fputc('\n', g.crowd_log);
    }
}

static void watch_truth(ps_summary_t *sum)
{
    (void)sum;
    const struct timespec poll = {0, TRUTH_POLL_NS};
    while (!atomic_load(&g.is_loop_done)) {
        nanosleep(&poll, NULL);
        drain_crowd_log();
        tell_reloads_refused();
    }
    drain_crowd_log();
}

/* The crowd on the status line: agents, fallen, density around the robot,
 * crowd force on the robot. */
static void crowd_status(void *ctx, char *buf, size_t len)
{
    ps_sim_t *sim = ctx;
    ps_sim_truth_t t;
    ps_sim_get_truth(sim, &t);
    if (t.has_crowd)
        snprintf(buf, len, "crowd=%u(%u down) rho=%.1f/m2 F=%.0fN", t.crowd.n_agents,
                 t.crowd.n_fallen, t.crowd.local_density_m2, t.crowd.robot_force_n);
}

/* ---- pictures (--render, --view) ---------------------------------------- */

static void on_frame(void *ctx, const struct ps_plant *p)
{
    ps_render_offer(ctx, ps_plant_data(p));
}

static int open_render(char *err, size_t len)
{
    if (g.opt.render_dir == NULL && !g.opt.is_view)
        return 0;
    if (g.app.sim == NULL) {
        snprintf(err, len, "only the simulation (board sim) has a scene to show");
        return -EINVAL;
    }
    const ps_crowd_cfg_t *cc = &g.app.scenario.crowd;
    const double rx = g.app.scenario.robot_xy_m[0], ry = g.app.scenario.robot_xy_m[1];
    const ps_render_cfg_t rc = {
        .dir = g.opt.render_dir,
        .fps = g.opt.render_fps,
        .width = 960,
        .height = 540,
        .is_view = g.opt.is_view,
        .is_lockstep = g.opt.is_lockstep,
        .robot_root = "pelvis",
        .area_m = {cc->is_enabled ? cc->arena.x_min_m : rx - 3.0,
                   cc->is_enabled ? cc->arena.y_min_m : ry - 3.0,
                   cc->is_enabled ? cc->arena.x_max_m : rx + 3.0,
                   cc->is_enabled ? cc->arena.y_max_m : ry + 3.0},
    };
    const struct ps_plant *plant = ps_sim_plant(g.app.sim);
    int rc_ = ps_render_create(&rc, ps_plant_model(plant), &g.render, err, len);
    if (rc_ == 0)
        rc_ = ps_render_start(g.render, err, len);
    const int64_t frame_ns = (int64_t)llround(1e9 / g.opt.render_fps);
    if (rc_ == 0 && ps_sim_set_frame_hook(g.app.sim, frame_ns, on_frame, g.render) < 0) {
        snprintf(err, len, "--render-fps %g: a frame every %lld ns is not a whole number of "
                 "physics steps", g.opt.render_fps, (long long)frame_ns);
        rc_ = -EINVAL;
    }
    if (rc_ < 0) {
        ps_render_destroy(g.render);
        g.render = NULL;
    }
    return rc_;
}

static int close_render(void)
{
    if (g.render == NULL)
        return 0;
    ps_render_result_t res;
    char err[PS_ERR_MSG_LEN] = "";
    const int rc = ps_render_finish(g.render, &res, err, sizeof(err));
    if (g.opt.render_dir != NULL)
        printf("render: %llu frames (%llu dropped) to %s: frame_*.png%s%s\n",
               (unsigned long long)res.n_frames, (unsigned long long)res.n_dropped,
               g.opt.render_dir, res.is_density ? ", density.png" : "",
               res.is_mp4 ? ", crowd.mp4" : "");
    if (rc < 0)
        fprintf(stderr, "pushstep: --render: %s\n", err);
    ps_render_destroy(g.render);
    g.render = NULL;
    return rc;
}

static int open_crowd_log(char *err, size_t len)
{
    if (g.opt.crowd_log == NULL)
        return 0;
    if (g.app.sim == NULL || !g.app.scenario.crowd.is_enabled) {
        snprintf(err, len, "the scenario has no crowd");
        return -EINVAL;
    }
    g.crowd_log = fopen(g.opt.crowd_log, "w");
    if (g.crowd_log == NULL) {
        snprintf(err, len, "%s: %s", g.opt.crowd_log, strerror(errno));
        return -errno;
    }
    ps_sim_truth_t t;
    ps_sim_get_truth(g.app.sim, &t);
    fprintf(g.crowd_log, "t_s,fallen,stepping,local_density_m2,robot_force_n,"
                         "transmitted_impulse_ns,penetration_m");
    for (uint32_t k = 0; k < t.crowd.n_parts; k++)
        fprintf(g.crowd_log, ",force_n_%s", t.crowd.part_name[k]);
    fputc('\n', g.crowd_log);
    return 0;
}

static int close_crowd_log(void)
{
    if (g.crowd_log == NULL)
        return 0;
    const bool is_bad = ferror(g.crowd_log) != 0;
    const bool is_closed = fclose(g.crowd_log) == 0;
    g.crowd_log = NULL;
    printf("crowd log: %llu ticks to %s", (unsigned long long)g.n_crowd_samples, g.opt.crowd_log);
    if (ps_sim_crowd_samples_dropped(g.app.sim) > 0)
        printf(" (WARNING: %llu ticks lost: the ring was full)",
               (unsigned long long)ps_sim_crowd_samples_dropped(g.app.sim));
    printf("\n");
    if (is_bad || !is_closed) {
        fprintf(stderr, "pushstep: --crowd-log: writing %s failed\n", g.opt.crowd_log);
        return -EIO;
    }
    return 0;
}

static int run_loop(ps_summary_t *sum)
{
    double duration_s = g.opt.has_duration ? g.opt.duration_s : g.app.scenario.duration_s;
    const ps_clock_t *clock = g.app.loop.cfg.clock;
    g.start_ns = g.app.is_replay     ? ps_can_replay_start_ns(&g.app.replay)
                 : g.opt.is_lockstep ? LOCKSTEP_START_NS
                                     : ps_clock_now_ns(clock) + RT_START_LEAD_NS;
    g.end_ns = duration_s > 0 ? g.start_ns + ps_s_to_ns(duration_s) : 0;
    if (g.app.is_replay) { /* the log's last frame, or --duration if sooner */
        int64_t log_end_ns = ps_can_replay_last_ns(&g.app.replay);
        log_end_ns = log_end_ns > g.start_ns ? log_end_ns : g.start_ns + 1; /* one tick */
        g.end_ns = g.end_ns > 0 && g.end_ns < log_end_ns ? g.end_ns : log_end_ns;
        duration_s = ps_ns_to_s(g.end_ns - g.start_ns);
    }
    if (g.opt.start_after_s >= 0)
        ps_app_request_start_at(&g.app, g.start_ns + ps_s_to_ns(g.opt.start_after_s));
    if (g.app.sim != NULL && g.app.scenario.crowd.is_enabled) {
        g.logger.status_extra = crowd_status;
        g.logger.status_extra_ctx = g.app.sim;
    }
    int rc =
        ps_logger_start(&g.logger, &g.app.loop, &g.app.ring, stdout, g.start_ns, g.opt.is_quiet,
                        g.app.board.rt.worker_cpu, g.frames.out != NULL ? &g.frames : NULL);
    if (rc < 0)
        return rc;
    if (atomic_load(&g.is_recording) && (rc = ps_recorder_start(&g.rec)) < 0) {
        ps_logger_stop(&g.logger);
        return rc;
    }
    rc = g.app.sim != NULL ? ps_sim_start(g.app.sim, g.start_ns) : 0; /* real boards: none */
    if (rc < 0) {
        ps_recorder_stop(&g.rec);
        ps_logger_stop(&g.logger);
        return rc;
    }
    char length[48];
    if (duration_s > 0)
        snprintf(length, sizeof(length), "%.1f s", duration_s);
    else
        snprintf(length, sizeof(length), "until Ctrl-C");
    char mode[PATH_MAX + 16];
    snprintf(mode, sizeof(mode), "%s%s",
             g.app.is_replay     ? "a replay of "
             : g.opt.is_lockstep ? "lockstep"
                                 : "in real time",
             g.app.is_replay ? g.opt.replay_path : "");
    printf("running %s on board %s (%s), robot %s, %s\n", mode, g.app.board.name, g.app.board_path,
           g.app.robot.name, length);
    fflush(stdout);
    pthread_t th;
    int64_t wall0 = wall_ns();
    rc = -pthread_create(&th, NULL, loop_thread_main, NULL);
    /* The main thread (truth sampling, summary) is not real-time: keep it off
     * the loop's CPU, with the logger. Only now, so that no thread or child
     * process (stress-ng) inherits its CPU mask. */
    if (rc == 0 && !is_unpaced())
        (void)ps_rtsetup_thread_best_effort(0, g.app.board.rt.worker_cpu);
    if (rc == 0) {
        watch_truth(sum);
        (void)pthread_join(th, NULL); /* the thread always ends */
        rc = g.loop_rc;
    }
    sum->wall_s = ps_ns_to_s(wall_ns() - wall0);
    ps_sim_stop(g.app.sim);
    ps_recorder_stop(&g.rec); /* writes what the ring still holds, closes the files */
    ps_logger_stop(&g.logger);
    return rc;
}

/* Did the plant's first fall happen while the controller was in charge:
 * in ACTIVE or HOLD, or in the DAMPING that the loop's own fall detection
 * started (the estimator sees the tilt before a body touches the floor)?
 * Both times count from the start of the run. */
static bool fell_while_active(double first_fall_t_s)
{
    if (first_fall_t_s < 0)
        return false;
    const ps_logger_t *lg = &g.logger;
    uint32_t n = lg->n_transitions < PS_LOGGER_MAX_TRANSITIONS ? lg->n_transitions
                                                               : PS_LOGGER_MAX_TRANSITIONS;
    double since = -1;
    for (uint32_t i = 0; i < n; i++) {
        const ps_logger_transition_t *t = &lg->transitions[i];
        const bool is_from_charge = t->from == PS_SM_ACTIVE || t->from == PS_SM_HOLD;
        bool is_fall_damping = is_from_charge && t->to == PS_SM_DAMPING && (t->cond & PS_SM_C_FALL);
        if (t->to == PS_SM_ACTIVE || t->to == PS_SM_HOLD) {
            if (since < 0)
                since = t->t_s;
        } else if (since >= 0 && !is_fall_damping) {
            if (first_fall_t_s >= since && first_fall_t_s <= t->t_s)
                return true;
            since = -1;
        }
    }
    return since >= 0 && first_fall_t_s >= since;
}

static ps_summary_policy_t summary_policy(const ps_app_t *app)
{
    const bool is_mlp = strcmp(app->policy_name, "mlp") == 0;
    return (ps_summary_policy_t){.name = app->policy_name[0] ? app->policy_name : NULL,
                                 .weights_path = is_mlp ? app->weights_path : NULL,
                                 .mlp = is_mlp ? &app->mlp : NULL,
                                 .start_ns = g.start_ns};
}

static void finish_summary(ps_summary_t *sum)
{
    sum->board_path = g.app.board_path;
    sum->robot_path = g.app.robot_path;
    sum->scenario_path = g.app.scenario_path[0] ? g.app.scenario_path : NULL;
    sum->is_lockstep = is_unpaced(); /* a replay runs as lockstep does */
    /* loop time from the schedule, so deadlines skipped by overruns count */
    sum->loop_s = ps_ns_to_s(g.app.loop.pacer.next_ns - g.start_ns);
    sum->loop = &g.app.loop;
    sum->policy = summary_policy(&g.app);
    sum->logger = &g.logger;
    sum->guard = g.guard;
    sum->is_guard_exact = ps_guard_counts_allocs() && ps_guard_counts_locks(); /* not under TSan */
    sum->rt_missing = g.rt_missing;
    sum->priority = g.app.board.rt.priority;
    sum->loop_cpu = g.app.board.rt.loop_cpu;
    sum->period_ns = g.app.loop.period_ns;
    sum->is_profile = g.opt.is_profile;
    sum->stress = g.opt.stress;
    sum->hist_us = g.opt.hist_us;
    sum->plan = &g.app.plan;
    sum->board = &g.app.board;
    sum->recorder = atomic_load(&g.is_recording) ? &g.rec.stats : NULL;
    for (uint32_t b = 0; b < g.app.board.n_buses; b++)
        if (ps_can_get_state(&g.app.loop.cfg.buses[b], &sum->bus_states[b]) < 0)
            memset(&sum->bus_states[b], 0, sizeof(sum->bus_states[b]));
    if (g.app.sim != NULL) {
        ps_sim_truth_t t;
        ps_sim_get_truth(g.app.sim, &t);
        sum->has_truth = true;
        sum->truth_fell_while_active = fell_while_active(t.first_fall_t_s);
        sum->truth_first_fall_t_s = t.first_fall_t_s;
        sum->truth_cmd_out_of_limits = t.n_cmd_out_of_limits;
        sum->truth_plant_overruns = t.n_plant_overruns;
        sum->truth_min_com_height_active_m =
            t.min_com_height_active_m >= 0 ? t.min_com_height_active_m : 0.0;
        sum->truth_plant_max_lag_ms = (double)t.max_plant_lag_ns * 1e-6;
        sum->truth_plant_err = t.plant_err;
        sum->truth_plant_err_reason = t.plant_err_reason;
        sum->truth_plant_err_t_s = t.plant_err_t_s;
        static ps_sim_truth_t crowd_truth; /* the summary points into it */
        crowd_truth = t;
        if (t.has_crowd) {
            const ps_crowd_stats_t *c = &crowd_truth.crowd;
            _Static_assert(PS_CROWD_MAX_PARTS <= PS_SUMMARY_MAX_PARTS, "parts fit the summary");
            _Static_assert(PS_NAME_LEN == 32u, "part names as the summary takes them");
            sum->has_crowd = true;
            sum->crowd = (ps_summary_crowd_t){
                .n_agents = c->n_agents,
                .n_fallen = c->n_fallen,
                .n_steps_taken = (unsigned long long)c->n_steps_taken,
                .local_density_m2 = c->local_density_m2,
                .local_density_max_m2 = crowd_truth.crowd_local_density_max_m2,
                .robot_force_max_n = c->robot_force_max_n,
                .transmitted_impulse_ns = c->transmitted_impulse_ns,
                .penetration_max_m = c->penetration_max_m,
                .n_parts = c->n_parts,
                .part_name = c->part_name,
                .part_force_max_n = c->part_force_max_n,
                .part_impulse_ns = c->part_impulse_ns,
            };
        }
        sum->truth_heading_dev_deg = t.heading_dev_max_rad * 180.0 / 3.14159265358979;
        sum->truth_foot_slide_m = t.foot_slide_m;
        sum->truth_kinetic_max_j = t.kinetic_energy_max_j;
    }
}

static void print_plan(const ps_app_t *app)
{
    const ps_canbus_plan_t *p = &app->plan;
    for (uint32_t b = 0; b < p->n_buses; b++)
        printf("bus %s: %u sources, worst tick %u of %u bits (%.1f%%), average %.1f%%, "
               "budget %.0f%%\n",
               app->board.buses[b].ifname, p->n_sources[b], p->tick_bits_max[b],
               p->tick_capacity_bits[b], p->load_peak[b] * 100, p->load_avg[b] * 100,
               (double)app->board.bus_budget * 100);
    for (uint32_t b = 0; b < p->n_buses; b++) {
        char risk[200]; /* a controller that may drop what the plan has it receive */
        if (ps_canbus_rx_risk(&app->board.buses[b], p, b, risk, sizeof(risk)) > 0)
            printf("warning: bus %s\n", risk);
    }
}

/* --replay: what the log fed, what the loop sent, and how the loop's
 * commands compare with the logged ones (drivers/ps_can_replay.h). */
static void report_replay(void)
{
    if (!g.app.is_replay)
        return;
    ps_can_replay_stats_t st;
    ps_can_replay_get_stats(&g.app.replay, &st);
    printf("replay: %llu frames fed on %u buses, %llu commands sent, %llu expected commands in "
           "the log, %llu unknown frames skipped",
           (unsigned long long)st.n_fed, st.n_buses_fed, (unsigned long long)st.n_sent,
           (unsigned long long)st.n_expected, (unsigned long long)st.n_unknown);
    if (st.n_fed < st.n_fed_logged)
        printf(" (%llu logged replies and IMU frames after the run's end)",
               (unsigned long long)(st.n_fed_logged - st.n_fed));
    printf("\n");
    const float *d = st.max_diff, *l = st.max_diff_lsb;
    printf("replay: %llu sent frames matched a logged one within a tick, %llu did not, %llu "
           "differ in kind; largest difference of %llu commands: q %.3g rad (%.1f LSB), qd "
           "%.3g rad/s (%.1f LSB), kp %.3g Nm/rad (%.1f LSB), kd %.3g Nm s/rad (%.1f LSB), tau "
           "%.3g Nm (%.1f LSB)\n",
           (unsigned long long)st.n_matched, (unsigned long long)st.n_unmatched,
           (unsigned long long)st.n_differ, (unsigned long long)st.n_cmd_compared,
           (double)d[PS_CAN_REPLAY_Q], (double)l[PS_CAN_REPLAY_Q], (double)d[PS_CAN_REPLAY_QD],
           (double)l[PS_CAN_REPLAY_QD], (double)d[PS_CAN_REPLAY_KP], (double)l[PS_CAN_REPLAY_KP],
           (double)d[PS_CAN_REPLAY_KD], (double)l[PS_CAN_REPLAY_KD], (double)d[PS_CAN_REPLAY_TAU],
           (double)l[PS_CAN_REPLAY_TAU]);
}

/* Camera perception beside the loop: what the perception thread did and
 * what the loop took from it. */
static void report_camera(void)
{
    if (!g.app.has_perception)
        return;
    ps_perception_stats_t st;
    ps_perception_get_stats(&g.app.perception, &st);
    const double span_s = ps_ns_to_s(st.t_last_mono_ns - st.t_first_mono_ns);
    const ps_loop_counters_t *c = &g.app.loop.counters;
    printf("camera: %llu frames (%.1f/s), %llu tags, exposure to mailbox p50/p99/max "
           "%.1f/%.1f/%.1f ms, %llu errors; the loop took %llu lists, %llu of %llu ticks without "
           "a fresh one\n",
           (unsigned long long)st.n_frames,
           span_s > 0 ? (double)(st.n_published - 1u) / span_s : 0.0,
           (unsigned long long)st.n_tags, ps_perf_quantile_ns(&st.latency, 0.5) * 1e-6,
           ps_perf_quantile_ns(&st.latency, 0.99) * 1e-6, (double)st.latency.max_ns * 1e-6,
           (unsigned long long)st.n_errors, (unsigned long long)c->n_neighbour_lists,
           (unsigned long long)c->n_neighbour_stale, (unsigned long long)c->n_ticks);
}

/* Profile outputs; plots are a convenience: without them the run still counts. */
static int finish_profile(const ps_summary_t *sum)
{
    char err[PS_ERR_MSG_LEN];
    if (ps_profile_write(g.opt.out_dir, sum, &g.app.loop.wake_us, err, sizeof(err)) < 0) {
        fprintf(stderr, "pushstep: profile: %s\n", err);
        return -EIO;
    }
    bool has_plots = ps_profile_plot(g.opt.out_dir, g.data_dir, err, sizeof(err)) == 0;
    if (!has_plots)
        fprintf(stderr, "pushstep: profile: %s\n", err);
    printf("profile written to %s/: profile.json, wakeup.hist%s\n", g.opt.out_dir,
           has_plots ? ", wakeup.png, stages.png" : "");
    return 0;
}

int main(int argc, char **argv)
{
    g.cpu_latency_fd = -1;
    /* Line-buffered even into a pipe: whoever reads the output (tee, a
     * supervisor, the tests) sees each transition when it happens. */
    (void)setvbuf(stdout, NULL, _IOLBF, 0); /* before any output: cannot fail */
    /* Offscreen rendering (the simulated camera, --render) goes through
     * Mesa's llvmpipe, which starts rasteriser threads on every CPU, the
     * loop's too (bench/camera.sh: the loop's p99 wake-up 5.4x, overruns 65
     * against 6 without perception). With none it rasterises on the
     * rendering thread, on the worker CPU. Set before any thread starts
     * (setenv is not safe beside getenv); a user's own setting wins. */
    (void)setenv("LP_NUM_THREADS", "0", 0);
    if (argc > 1 && strcmp(argv[1], "log") == 0)
        return ps_reclog_main(argc - 1, argv + 1);
    if (argc > 1 && strcmp(argv[1], "camera") == 0) {
        find_data_dir(g.data_dir, sizeof(g.data_dir));
        return ps_camview_main(argc - 1, argv + 1, g.data_dir);
    }
    if (argc > 1 && (strcmp(argv[1], "emulate") == 0 || strcmp(argv[1], "monitor") == 0)) {
        find_data_dir(g.data_dir, sizeof(g.data_dir));
        return argv[1][0] == 'e' ? ps_emulate_main(argc - 1, argv + 1, g.data_dir)
                                 : ps_monitor_main(argc - 1, argv + 1, g.data_dir);
    }
    if (argc > 1 && strcmp(argv[1], "doctor") == 0) {
        find_data_dir(g.data_dir, sizeof(g.data_dir));
        return ps_doctor_main(argc - 1, argv + 1, g.data_dir);
    }
    if (block_stop_signals(SIG_BLOCK) < 0 || install_signals() < 0) {
        fprintf(stderr, "pushstep: cannot install the SIGINT/SIGTERM/SIGHUP handlers\n");
        return 1;
    }
    if (parse_options(argc, argv, &g.opt) < 0)
        return 2;
    if ((g.opt.record_path != NULL || g.opt.flight_dir != NULL) && install_recorder_signals() < 0) {
        fprintf(stderr, "pushstep: cannot install the SIGUSR1/SIGXFSZ handlers\n");
        return 1;
    }
    find_data_dir(g.data_dir, sizeof(g.data_dir));
    char err[PS_ERR_MSG_LEN];
    if (g.opt.candump_path != NULL && alloc_candump_ring(err, sizeof(err)) < 0) {
        fprintf(stderr, "pushstep: --candump: %s\n", err);
        return 2;
    }
    ps_app_opts_t ao = {
        .data_dir = g.data_dir,
        .board = g.opt.board,
        .robot = g.opt.robot,
        .scenario = g.opt.scenario,
        .is_lockstep = g.opt.is_lockstep,
        .wake_hist_us = g.opt.hist_us,
        .trace = g.opt.is_trace ? &g.trace : NULL,
        .frame_ring = g.frames.ring,
        .replay_path = g.opt.replay_path,
        .policy = g.opt.policy,
        .weights = g.opt.weights,
    };
    ps_trace_init(&g.trace);
    if (g.opt.is_trace && ps_trace_open(&g.trace, NULL, err, sizeof(err)) < 0) {
        fprintf(stderr, "pushstep: --trace: cannot open trace_marker: %s\n", err);
        return 2;
    }
    int rc = ps_app_init(&g.app, &ao, err, sizeof(err));
    if (g.app.plan.n_buses > 0)
        print_plan(&g.app); /* also when wiring failed after the plan */
    if (rc < 0) {
        fprintf(stderr, "pushstep: %s\n", err);
        ps_app_deinit(&g.app);
        ps_trace_close(&g.trace);
        return 2;
    }
    if (g.app.notes[0] != '\0')
        printf("note: %s\n", g.app.notes);
    if (open_crowd_log(err, sizeof(err)) < 0) {
        fprintf(stderr, "pushstep: --crowd-log: %s\n", err);
        ps_app_deinit(&g.app);
        ps_trace_close(&g.trace);
        return 2;
    }
    if (open_render(err, sizeof(err)) < 0) {
        fprintf(stderr, "pushstep: %s: %s\n", g.opt.is_view ? "--view" : "--render", err);
        (void)close_crowd_log();
        ps_app_deinit(&g.app);
        ps_trace_close(&g.trace);
        return 2;
    }
    if (g.opt.candump_path != NULL && open_candump_file(err, sizeof(err)) < 0) {
        fprintf(stderr, "pushstep: --candump: %s\n", err);
        ps_app_deinit(&g.app);
        ps_trace_close(&g.trace);
        return 2;
    }
    if ((g.opt.record_path != NULL || g.opt.flight_dir != NULL) &&
        setup_recorder(err, sizeof(err)) < 0) {
        fprintf(stderr, "pushstep: %s\n", err);
        ps_recorder_deinit(&g.rec);
        ps_app_deinit(&g.app);
        ps_trace_close(&g.trace);
        return 2;
    }
    rc = setup_process_rt();
    if (rc == 0)
        rc = block_stop_signals(SIG_UNBLOCK); /* the loop exists: pending stops land */
    if (rc == 0 && g.opt.stress != NULL) {
        rc = ps_profile_start_stress(g.opt.stress, g.opt.duration_s, &g.stress_pid, err,
                                     sizeof(err));
        if (rc < 0) {
            fprintf(stderr, "pushstep: %s\n", err);
            ps_rtsetup_release_cpu_latency(g.cpu_latency_fd);
            ps_app_deinit(&g.app);
            ps_trace_close(&g.trace);
            return 2;
        }
        printf("load: stress-ng --%s on every CPU\n", g.opt.stress);
    }
    ps_summary_t sum;
    memset(&sum, 0, sizeof(sum));
    if (rc == 0)
        rc = run_loop(&sum);
    ps_profile_stop_stress(g.stress_pid);
    ps_rtsetup_release_cpu_latency(g.cpu_latency_fd);
    if (rc == -PS_ERR_RT_UNAVAILABLE)
        fprintf(stderr, "pushstep: --require-rt: %s\n", ps_strerror(rc));
    else if (rc < 0)
        fprintf(stderr, "pushstep: loop failed: %s\n", ps_strerror(rc));
    if (g.app.loop.counters.n_ticks > 0) {
        finish_summary(&sum);
        ps_summary_print(&sum, stdout);
        report_replay();
        report_camera();
        if (g.opt.summary_path != NULL &&
            ps_summary_write_json(&sum, g.opt.summary_path, err, sizeof(err)) < 0) {
            fprintf(stderr, "pushstep: %s\n", err);
            rc = -EIO;
        }
        if (g.opt.is_profile)
            rc = finish_profile(&sum) < 0 ? -EIO : rc;
        /* `profile` measures the loop, often under a deliberate load
         * (--stress, make bench) that slows the plant: there the lag is
         * reported in the summary but is not what --require-rt guards. */
        if (g.opt.is_rt_required && !g.opt.is_profile && sum.has_truth &&
            (sum.truth_plant_overruns > 0 || sum.truth_plant_max_lag_ms > 0)) {
            fprintf(stderr,
                    "pushstep: --require-rt: the simulation fell behind real time (%llu plant "
                    "periods skipped, up to %.1f ms behind)\n",
                    (unsigned long long)sum.truth_plant_overruns, sum.truth_plant_max_lag_ms);
            if (rc == 0)
                rc = -PS_ERR_RT_UNAVAILABLE;
        }
        if (sum.has_truth && sum.truth_plant_err != 0) {
            /* the physics stopped: what the run shows after it is not a robot */
            fprintf(stderr, "pushstep: simulation failed at t=%.4f s: %s\n",
                    sum.truth_plant_err_t_s,
                    sum.truth_plant_err_reason ? sum.truth_plant_err_reason
                                               : ps_strerror(sum.truth_plant_err));
            if (rc == 0)
                rc = sum.truth_plant_err;
        }
    }
    if (close_candump() < 0 && rc == 0)
        rc = -EIO;
    if (close_crowd_log() < 0 && rc == 0)
        rc = -EIO;
    if (close_render() < 0 && rc == 0)
        rc = -EIO;
    if (atomic_load(&g.is_recording) && recorder_failed() && rc == 0)
        rc = -EIO;
    ps_recorder_deinit(&g.rec);
    ps_trace_close(&g.trace);
    ps_app_deinit(&g.app);
    return rc < 0 ? 1 : 0;
}
