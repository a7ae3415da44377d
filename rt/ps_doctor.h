/*
 * ps_doctor: `pushstep doctor`, a check of a target machine for what the
 * loop needs, item by item, each fine or to fix with the command that fixes
 * it:
 *
 *   kernel        PREEMPT_RT (/sys/kernel/realtime, /proc/version)
 *   rt priority   SCHED_FIFO at the board's priority permitted
 *                 (CAP_SYS_NICE in /proc/self/status, or RLIMIT_RTPRIO in
 *                 /proc/self/limits)
 *   memlock       mlockall permitted (CAP_IPC_LOCK, or RLIMIT_MEMLOCK unlimited)
 *   loop cpu      the board's loop CPU online and in this process's cgroup
 *                 cpuset (cpuset.cpus.effective)
 *   isolation     the loop CPU in /sys/devices/system/cpu/isolated (and nohz_full)
 *   governor      cpufreq governor `performance` on the loop CPU (or no cpufreq)
 *   clock source  tsc / arch_sys_counter (kvm-clock in a VM)
 *   cpu latency   /dev/cpu_dma_latency writable (deep C-states held off)
 *   can IFACE     per bus: rtnetlink state checked by the runtime's own
 *                 start-up check (drivers/ps_can_socket: up, bitrate, FD,
 *                 restart-ms, txqueuelen), the kernel driver under
 *                 /sys/class/net/IFACE/device against the board's controller,
 *                 and the plan's received-frame risk (ps_canbus_rx_risk)
 *   gpio          chip and lines present and free (drivers/ps_gpio_gpiod probe)
 *   camera        a V4L2 device whose name contains the board's camera.sensor,
 *                 and its /dev node accessible
 *
 * Everything under /proc, /sys and /dev is read through a root prefix, so
 * tests point it at fake trees (tests/data/doctor/). The two things no file
 * tree holds, rtnetlink's answer about a CAN interface and a GPIO chip's
 * line info, come through ps_doctor_ops_t: the live ones by default, fakes
 * in tests; tests/hw/ checks the live ones in the VM.
 *
 * Levels: required items (what the runtime refuses to run without on a real
 * board, or runs badly without: RT privileges, the loop CPU, CAN, GPIO) are
 * FAIL when missing; recommended ones (PREEMPT_RT, isolation, governor,
 * clock source, cpu latency, camera) are WARN. On board `sim` the RT items
 * are WARN too and there is no CAN or GPIO to check.
 *
 * Threads: main thread. Allocation: none (the report is the caller's).
 */
#ifndef PS_DOCTOR_H
#define PS_DOCTOR_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#include "../drivers/ps_can_socket.h"
#include "../drivers/ps_canbus.h"
#include "../drivers/ps_gpio_gpiod.h"
#include "ps_config.h"

#define PS_DOCTOR_MAX_ITEMS 48u

typedef enum {
    PS_DOCTOR_OK = 0, /**< fine */
    PS_DOCTOR_NOTE,   /**< nothing to fix, worth knowing (not checked, and why) */
    PS_DOCTOR_WARN,   /**< to fix: recommended */
    PS_DOCTOR_FAIL,   /**< to fix: required */
} ps_doctor_level_t;

typedef struct {
    ps_doctor_level_t level;
    char what[32];    /**< "kernel", "can can0", ... */
    char found[512];  /**< what was found */
    char fix[512];    /**< the command(s) that fix it; "" when fine */
} ps_doctor_item_t;

typedef struct {
    uint32_t n_items;
    ps_doctor_item_t items[PS_DOCTOR_MAX_ITEMS];
    uint32_t n_fail, n_warn, n_ok;
} ps_doctor_report_t;

/** What the file tree cannot hold. NULL members: not checked (a NOTE says so). */
typedef struct {
    /** rtnetlink about one interface (ps_can_socket_query's contract) */
    int (*can_query)(void *ctx, const char *ifname, ps_can_socket_iface_t *out, char *err,
                     size_t err_len);
    /** the chip's lines (ps_gpio_gpiod_probe's contract) */
    int (*gpio_probe)(void *ctx, const ps_gpio_cfg_t *cfg, ps_gpio_gpiod_probe_t *out, char *err,
                      size_t err_len);
    void *ctx;
} ps_doctor_ops_t;

/** The live system's: ps_can_socket_query and ps_gpio_gpiod_probe. */
extern const ps_doctor_ops_t PS_DOCTOR_LIVE_OPS;

typedef struct {
    const char *root;             /**< prefix of /proc, /sys, /dev; "" or "/": the live system */
    const ps_board_cfg_t *board;  /**< loaded */
    const ps_canbus_plan_t *plan; /**< the default robot's plan on it (rx risk), or NULL */
    uint32_t min_txqueuelen[PS_MAX_BUSES]; /**< per bus, as start-up requires it */
    ps_doctor_ops_t ops;
} ps_doctor_cfg_t;

/** Run every check. @pre cfg->board loaded  @post *out holds every item
 *  @return number of required items missing (n_fail), >= 0  @rt INIT */
int ps_doctor_run(const ps_doctor_cfg_t *cfg, ps_doctor_report_t *out);

/** Print the report: one line per item ("  ok      what: found" or
 *  "  TO FIX  what: found" and "          fix: ..."), then a total line.
 *  @rt INIT */
void ps_doctor_print(const ps_doctor_report_t *r, FILE *out);

/** `pushstep doctor` (argv[0] = "doctor"): parse, load the board and robot
 *  (data_dir as for the other sub-commands), run, print.
 *  @return process exit status: 0 nothing required missing, 1 something
 *          required missing, 2 usage or configuration  @rt INIT */
int ps_doctor_main(int argc, char **argv, const char *data_dir);

#endif /* PS_DOCTOR_H */
