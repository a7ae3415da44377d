/*
 * ps_doctor: the checks of `pushstep doctor`; see ps_doctor.h. Part of the
 * composition root (it plans the robot's buses through rt/ps_app).
 */
#include "ps_doctor.h"

#include <dirent.h>
#include <errno.h>
#include <getopt.h>
#include <inttypes.h>
#include <limits.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "ps_app.h"
#include "ps_err.h"

#define CAP_SYS_NICE_BIT 23u
#define CAP_IPC_LOCK_BIT 14u
#define TEXT_LEN         4096
#define SHORT_LEN        256

/* ---- reading the tree ----------------------------------------------------- */

/* root + an absolute path; root "" or "/" is the live system. */
static void at_root(const ps_doctor_cfg_t *c, const char *abs_path, char *out, size_t len)
{
    const char *root = c->root != NULL && strcmp(c->root, "/") != 0 ? c->root : "";
    (void)snprintf(out, len, "%s%s", root, abs_path);
}

/* The whole file (up to len - 1 bytes), trailing newlines dropped.
 * @return 0 | -errno */
static int read_text(const ps_doctor_cfg_t *c, const char *abs_path, char *out, size_t len)
{
    char path[PATH_MAX];
    at_root(c, abs_path, path, sizeof(path));
    out[0] = '\0';
    FILE *fp = fopen(path, "re");
    if (fp == NULL)
        return -errno;
    const size_t n = fread(out, 1, len - 1u, fp);
    const int is_bad = ferror(fp);
    (void)fclose(fp); /* read-only: nothing to flush */
    if (is_bad)
        return -EIO;
    out[n] = '\0';
    for (size_t k = n; k > 0 && (out[k - 1] == '\n' || out[k - 1] == ' '); k--)
        out[k - 1] = '\0';
    return 0;
}

/* The last component of a symlink's target ("" when it is no link). */
static void link_base(const ps_doctor_cfg_t *c, const char *abs_path, char *out, size_t len)
{
    char path[PATH_MAX], target[PATH_MAX];
    at_root(c, abs_path, path, sizeof(path));
    out[0] = '\0';
    const ssize_t n = readlink(path, target, sizeof(target) - 1u);
    if (n <= 0)
        return;
    target[n] = '\0';
    const char *slash = strrchr(target, '/');
    const char *base = slash != NULL ? slash + 1 : target;
    const size_t k = strlen(base) < len - 1u ? strlen(base) : len - 1u; /* names are short */
    memcpy(out, base, k);
    out[k] = '\0';
}

static bool exists(const ps_doctor_cfg_t *c, const char *abs_path, int mode)
{
    char path[PATH_MAX];
    at_root(c, abs_path, path, sizeof(path));
    return access(path, mode) == 0;
}

/* "0-3,5,7-9" contains cpu? */
static bool cpulist_has(const char *list, int cpu)
{
    const char *p = list;
    while (cpu >= 0 && *p != '\0') {
        char *end = NULL;
        const long lo = strtol(p, &end, 10);
        if (end == p)
            return false;
        long hi = lo;
        p = end;
        if (*p == '-') {
            hi = strtol(p + 1, &end, 10);
            if (end == p + 1)
                return false;
            p = end;
        }
        if (cpu >= lo && cpu <= hi)
            return true;
        if (*p == ',')
            p++;
        else
            break;
    }
    return false;
}

/* The value after "key:" on its line of a /proc/self/status text. */
static void status_field(const char *status, const char *key, char *out, size_t len)
{
    out[0] = '\0';
    const size_t k = strlen(key);
    for (const char *line = status; line != NULL && *line != '\0';) {
        if (strncmp(line, key, k) == 0 && line[k] == ':') {
            const char *v = line + k + 1;
            while (*v == ' ' || *v == '\t')
                v++;
            const char *eol = strchr(v, '\n');
            const size_t n = eol != NULL ? (size_t)(eol - v) : strlen(v);
            (void)snprintf(out, len, "%.*s", (int)n, v);
            return;
        }
        line = strchr(line, '\n');
        line = line != NULL ? line + 1 : NULL;
    }
}

/* The soft limit of a /proc/self/limits row ("Max realtime priority");
 * UINT64_MAX for "unlimited". @return false when the row is missing. */
static bool soft_limit(const char *limits, const char *row, uint64_t *out)
{
    const char *at = strstr(limits, row);
    if (at == NULL)
        return false;
    const char *v = at + strlen(row);
    while (*v == ' ')
        v++;
    if (strncmp(v, "unlimited", 9) == 0) {
        *out = UINT64_MAX;
        return true;
    }
    char *end = NULL;
    const unsigned long long n = strtoull(v, &end, 10);
    if (end == v)
        return false;
    *out = n;
    return true;
}

/* ---- the report ----------------------------------------------------------- */

static void add(ps_doctor_report_t *r, ps_doctor_level_t level, const char *what, const char *fix,
                const char *fmt, ...) __attribute__((format(printf, 5, 6)));
static void add(ps_doctor_report_t *r, ps_doctor_level_t level, const char *what, const char *fix,
                const char *fmt, ...)
{
    if (r->n_items >= PS_DOCTOR_MAX_ITEMS)
        return;
    ps_doctor_item_t *it = &r->items[r->n_items++];
    it->level = level;
    (void)snprintf(it->what, sizeof(it->what), "%s", what);
    va_list ap;
    va_start(ap, fmt);
    (void)vsnprintf(it->found, sizeof(it->found), fmt, ap); /* truncation is acceptable */
    va_end(ap);
    (void)snprintf(it->fix, sizeof(it->fix), "%s", fix != NULL ? fix : "");
    r->n_fail += level == PS_DOCTOR_FAIL;
    r->n_warn += level == PS_DOCTOR_WARN;
    r->n_ok += level == PS_DOCTOR_OK;
}

/* ---- kernel, privileges, CPU ---------------------------------------------- */

static void check_kernel(const ps_doctor_cfg_t *c, ps_doctor_report_t *r)
{
    char rt[16], version[SHORT_LEN * 2];
    const bool has_rt_flag = read_text(c, "/sys/kernel/realtime", rt, sizeof(rt)) == 0 &&
                             strcmp(rt, "1") == 0;
    char release[64] = "(no /proc/version)";
    if (read_text(c, "/proc/version", version, sizeof(version)) == 0)
        (void)sscanf(version, "Linux version %63s", release);
    const char *fix = "Debian 12: `sudo apt install linux-image-rt-$(dpkg --print-architecture)` "
                      "and reboot into it (Raspberry Pi OS, L4T, BeagleBoard: docs/deploy.md)";
    if (has_rt_flag || strstr(version, "PREEMPT_RT") != NULL)
        add(r, PS_DOCTOR_OK, "kernel", NULL, "%s, PREEMPT_RT", release);
    else if (strstr(version, "PREEMPT") != NULL)
        add(r, PS_DOCTOR_WARN, "kernel", fix,
            "%s is PREEMPT but not PREEMPT_RT: wake-up latency of milliseconds under load", release);
    else
        add(r, PS_DOCTOR_WARN, "kernel", fix, "%s has no kernel preemption (not PREEMPT_RT)",
            release);
}

static void check_privileges(const ps_doctor_cfg_t *c, ps_doctor_report_t *r)
{
    const bool is_real = c->board->kind == PS_BOARD_LINUX;
    const ps_doctor_level_t missing = is_real ? PS_DOCTOR_FAIL : PS_DOCTOR_WARN;
    char status[TEXT_LEN], limits[TEXT_LEN], caps[32];
    (void)read_text(c, "/proc/self/status", status, sizeof(status)); /* "" when missing */
    (void)read_text(c, "/proc/self/limits", limits, sizeof(limits));
    status_field(status, "CapEff", caps, sizeof(caps));
    const unsigned long long cap = strtoull(caps, NULL, 16);
    const bool has_nice = (cap >> CAP_SYS_NICE_BIT) & 1u;
    const bool has_ipc_lock = (cap >> CAP_IPC_LOCK_BIT) & 1u;
    const unsigned prio = c->board->rt.priority;
    uint64_t rtprio = 0, memlock = 0;
    const bool has_rtprio_row = soft_limit(limits, "Max realtime priority", &rtprio);
    const bool has_memlock_row = soft_limit(limits, "Max locked memory", &memlock);
    char fix[512];

    if (prio == 0u) {
        add(r, PS_DOCTOR_OK, "rt priority", NULL, "the board asks for no SCHED_FIFO");
    } else if (has_nice || (has_rtprio_row && rtprio >= prio)) {
        add(r, PS_DOCTOR_OK, "rt priority", NULL, "SCHED_FIFO %u permitted (%s)", prio,
            has_nice ? "CAP_SYS_NICE" : "RLIMIT_RTPRIO");
    } else {
        (void)snprintf(fix, sizeof(fix),
                       "run it as the shipped service (LimitRTPRIO=%u): `sudo systemctl start "
                       "pushstep@%s`; for a shell: `echo '@pushstep - rtprio %u' | sudo tee -a "
                       "/etc/security/limits.d/pushstep.conf`, then log in again as a member of "
                       "group pushstep",
                       prio, c->board->name, prio);
        add(r, missing, "rt priority", fix,
            "SCHED_FIFO %u not permitted: no CAP_SYS_NICE, RLIMIT_RTPRIO %" PRIu64, prio,
            has_rtprio_row ? rtprio : 0u);
    }

    if (has_ipc_lock || (has_memlock_row && memlock == UINT64_MAX)) {
        add(r, PS_DOCTOR_OK, "memlock", NULL, "mlockall permitted (%s)",
            has_ipc_lock ? "CAP_IPC_LOCK" : "RLIMIT_MEMLOCK unlimited");
    } else {
        add(r, missing, "memlock",
            "run it as the shipped service (LimitMEMLOCK=infinity): `sudo systemctl start "
            "pushstep@BOARD`; for a shell: `echo '@pushstep - memlock unlimited' | sudo tee -a "
            "/etc/security/limits.d/pushstep.conf`, then log in again",
            "mlockall not permitted: no CAP_IPC_LOCK, RLIMIT_MEMLOCK %" PRIu64
            " bytes (the loop's memory would page)",
            has_memlock_row ? memlock : 0u);
    }
}

/* The CPUs this process may put a thread on: its cgroup's effective cpuset
 * (cgroup v2: /proc/self/cgroup "0::/PATH", the nearest cpuset.cpus.effective
 * from /sys/fs/cgroup/PATH up to the root). Not the affinity mask
 * (Cpus_allowed_list): with isolcpus every task inherits one without the
 * isolated CPUs, and a thread may still pin itself to any CPU of its cpuset,
 * which is what the loop does. "" when no cpuset is found (no limit known). */
static void cpuset_of_self(const ps_doctor_cfg_t *c, char *out, size_t len)
{
    out[0] = '\0';
    char cg[TEXT_LEN], path[PATH_MAX];
    if (read_text(c, "/proc/self/cgroup", cg, sizeof(cg)) < 0)
        return;
    const char *v2 = strstr(cg, "0::");
    if (v2 != NULL && (v2 == cg || v2[-1] == '\n')) {
        const char *p = v2 + 3;
        const char *eol = strchr(p, '\n');
        (void)snprintf(path, sizeof(path), "/sys/fs/cgroup%.*s",
                       (int)(eol != NULL ? (size_t)(eol - p) : strlen(p)), p);
        for (;;) {
            char file[PATH_MAX + 32];
            (void)snprintf(file, sizeof(file), "%s/cpuset.cpus.effective", path);
            if (read_text(c, file, out, len) == 0 && out[0] != '\0')
                return;
            char *slash = strrchr(path, '/');
            if (slash == NULL || strcmp(path, "/sys/fs/cgroup") == 0)
                break;
            *slash = '\0';
        }
    }
    out[0] = '\0';
}

static void check_cpu(const ps_doctor_cfg_t *c, ps_doctor_report_t *r)
{
    const int cpu = c->board->rt.loop_cpu;
    char online[SHORT_LEN], allowed[SHORT_LEN], fix[512];
    if (read_text(c, "/sys/devices/system/cpu/online", online, sizeof(online)) < 0)
        (void)snprintf(online, sizeof(online), "?");
    cpuset_of_self(c, allowed, sizeof(allowed));
    const bool is_real = c->board->kind == PS_BOARD_LINUX;
    if (cpu < 0) {
        add(r, PS_DOCTOR_NOTE, "loop cpu", NULL, "the board pins the loop to no CPU");
        return;
    }
    if (!cpulist_has(online, cpu)) {
        (void)snprintf(fix, sizeof(fix), "set rt.loop_cpu in the board file to one of %s",
                       online);
        add(r, is_real ? PS_DOCTOR_FAIL : PS_DOCTOR_WARN, "loop cpu", fix,
            "the board pins the loop to CPU %d; online here: %s", cpu, online);
        return;
    }
    if (allowed[0] != '\0' && !cpulist_has(allowed, cpu)) {
        (void)snprintf(fix, sizeof(fix),
                       "include CPU %d in AllowedCPUs= of the unit (or of the cgroup it runs "
                       "in: `systemctl show -p AllowedCPUs`)",
                       cpu);
        add(r, is_real ? PS_DOCTOR_FAIL : PS_DOCTOR_WARN, "loop cpu", fix,
            "CPU %d is online but not in this process's cpuset (%s)", cpu, allowed);
    } else {
        add(r, PS_DOCTOR_OK, "loop cpu", NULL, "CPU %d online and allowed (online %s)", cpu,
            online);
    }

    char isolated[SHORT_LEN], nohz[SHORT_LEN];
    (void)read_text(c, "/sys/devices/system/cpu/isolated", isolated, sizeof(isolated));
    (void)read_text(c, "/sys/devices/system/cpu/nohz_full", nohz, sizeof(nohz));
    const bool is_nohz = cpulist_has(nohz, cpu);
    if (cpulist_has(isolated, cpu)) {
        add(r, PS_DOCTOR_OK, "isolation", NULL, "CPU %d isolated (isolcpus)%s", cpu,
            is_nohz ? ", nohz_full" : "; not nohz_full");
    } else {
        (void)snprintf(fix, sizeof(fix),
                       "add `isolcpus=%d nohz_full=%d rcu_nocbs=%d irqaffinity=0` to the kernel "
                       "command line (Debian: GRUB_CMDLINE_LINUX in /etc/default/grub, then `sudo "
                       "update-grub`; Raspberry Pi: /boot/firmware/cmdline.txt; Jetson: APPEND in "
                       "/boot/extlinux/extlinux.conf) and reboot",
                       cpu, cpu, cpu);
        add(r, PS_DOCTOR_WARN, "isolation", fix,
            "CPU %d is not isolated (isolated: \"%s\"): other tasks and interrupts share it",
            cpu, isolated);
    }

    char gov_path[96], gov[64];
    (void)snprintf(gov_path, sizeof(gov_path), "/sys/devices/system/cpu/cpu%d/cpufreq", cpu);
    const bool has_cpufreq = exists(c, gov_path, F_OK);
    (void)snprintf(gov_path, sizeof(gov_path),
                   "/sys/devices/system/cpu/cpu%d/cpufreq/scaling_governor", cpu);
    if (!has_cpufreq) {
        add(r, PS_DOCTOR_OK, "governor", NULL, "no cpufreq on CPU %d: its clock does not change",
            cpu);
    } else if (read_text(c, gov_path, gov, sizeof(gov)) == 0 && strcmp(gov, "performance") == 0) {
        add(r, PS_DOCTOR_OK, "governor", NULL, "CPU %d: performance", cpu);
    } else {
        (void)snprintf(fix, sizeof(fix),
                       "`echo performance | sudo tee %s` (at every boot: docs/deploy.md)",
                       gov_path);
        add(r, PS_DOCTOR_WARN, "governor", fix,
            "CPU %d: governor \"%s\": the clock drops when idle and ticks wake slower", cpu, gov);
    }
}

static void check_clock(const ps_doctor_cfg_t *c, ps_doctor_report_t *r)
{
    static const char DIR[] = "/sys/devices/system/clocksource/clocksource0/";
    char path[128], cur[64], avail[SHORT_LEN], fix[512];
    (void)snprintf(path, sizeof(path), "%scurrent_clocksource", DIR);
    if (read_text(c, path, cur, sizeof(cur)) < 0) {
        add(r, PS_DOCTOR_NOTE, "clock source", NULL, "cannot read %s", path);
        return;
    }
    (void)snprintf(path, sizeof(path), "%savailable_clocksource", DIR);
    (void)read_text(c, path, avail, sizeof(avail));
    if (strcmp(cur, "tsc") == 0 || strcmp(cur, "arch_sys_counter") == 0) {
        add(r, PS_DOCTOR_OK, "clock source", NULL, "%s", cur);
        return;
    }
    if (strcmp(cur, "kvm-clock") == 0) {
        add(r, PS_DOCTOR_OK, "clock source", NULL, "kvm-clock (a virtual machine's)");
        return;
    }
    const char *better = strstr(avail, "tsc") != NULL                ? "tsc"
                         : strstr(avail, "arch_sys_counter") != NULL ? "arch_sys_counter"
                                                                     : NULL;
    if (better != NULL)
        (void)snprintf(fix, sizeof(fix), "`echo %s | sudo tee %scurrent_clocksource`", better,
                       DIR);
    else
        (void)snprintf(fix, sizeof(fix),
                       "none better on offer (available: %s); check the firmware's timers", avail);
    add(r, PS_DOCTOR_WARN, "clock source", fix, "%s: slow to read or coarse (available: %s)", cur,
        avail);
}

static void check_cpu_latency(const ps_doctor_cfg_t *c, ps_doctor_report_t *r)
{
    if (!exists(c, "/dev/cpu_dma_latency", F_OK))
        add(r, PS_DOCTOR_WARN, "cpu latency", "a kernel with CONFIG_PM_QOS (every Debian kernel)",
            "no /dev/cpu_dma_latency: deep C-states cannot be held off");
    else if (!exists(c, "/dev/cpu_dma_latency", W_OK))
        add(r, PS_DOCTOR_WARN, "cpu latency",
            "install the shipped udev rules (group pushstep may write it): `sudo make install` "
            "or the .deb, then `sudo udevadm trigger`",
            "/dev/cpu_dma_latency not writable: the loop cannot hold off deep C-states");
    else
        add(r, PS_DOCTOR_OK, "cpu latency", NULL, "/dev/cpu_dma_latency writable");
}

/* ---- CAN ------------------------------------------------------------------ */

static void describe_iface(const ps_can_socket_iface_t *i, char *out, size_t len)
{
    if (!i->exists) {
        (void)snprintf(out, len, "absent");
        return;
    }
    int n = snprintf(out, len, "%s%s%s, mtu %u, txqueuelen %u", i->is_up ? "up" : "down",
                     i->kind[0] ? ", " : "", i->kind, i->mtu, i->txqueuelen);
    if (i->has_bittiming && n > 0 && (size_t)n < len)
        n += snprintf(out + n, len - (size_t)n, ", %u bit/s%s, restart-ms %u", i->bitrate,
                      i->is_fd_mode ? " FD" : "", i->restart_ms);
    if (i->has_bittiming && i->is_fd_mode && n > 0 && (size_t)n < len)
        (void)snprintf(out + n, len - (size_t)n, ", data %u bit/s", i->data_bitrate);
}

static void check_can_driver(const ps_doctor_cfg_t *c, uint32_t b, ps_doctor_report_t *r)
{
    const ps_canbus_bus_cfg_t *bus = &c->board->buses[b];
    const ps_canbus_ctrl_info_t *ci = ps_canbus_ctrl_info(bus->controller);
    char what[32], path[128], driver[64], device[64], fix[512];
    (void)snprintf(what, sizeof(what), "%s driver", bus->ifname);
    if (ci->driver == NULL)
        return; /* virtual or not stated: nothing to compare */
    (void)snprintf(path, sizeof(path), "/sys/class/net/%s", bus->ifname);
    if (!exists(c, path, F_OK))
        return; /* the interface item already says it is missing */
    (void)snprintf(path, sizeof(path), "/sys/class/net/%s/device", bus->ifname);
    link_base(c, path, device, sizeof(device));
    (void)snprintf(path, sizeof(path), "/sys/class/net/%s/device/driver", bus->ifname);
    link_base(c, path, driver, sizeof(driver));
    if (strcmp(driver, ci->driver) == 0) {
        add(r, PS_DOCTOR_OK, what, NULL, "%s on %s, as the board's %s", driver, device, ci->name);
        return;
    }
    (void)snprintf(fix, sizeof(fix),
                   "interfaces are numbered in probe order: name them by device with the udev "
                   "rules of docs/deploy.md (`ls -l /sys/class/net/*/device` shows which is "
                   "which), or correct buses[%u].controller",
                   b);
    add(r, PS_DOCTOR_FAIL, what, fix, "%s is driven by %s%s%s, the board wants %s (%s)",
        bus->ifname, driver[0] ? driver : "no driver (a virtual interface?)",
        device[0] ? " on " : "", device, ci->driver, ci->name);
}

static void check_can(const ps_doctor_cfg_t *c, ps_doctor_report_t *r)
{
    for (uint32_t b = 0; b < c->board->n_buses; b++) {
        const ps_canbus_bus_cfg_t *bus = &c->board->buses[b];
        char what[32], why[768], note[160], got[SHORT_LEN];
        (void)snprintf(what, sizeof(what), "can %s", bus->ifname);
        if (c->ops.can_query == NULL) {
            add(r, PS_DOCTOR_NOTE, what, NULL, "not queried (rtnetlink: the live system only)");
        } else {
            ps_can_socket_iface_t info;
            int rc = c->ops.can_query(c->ops.ctx, bus->ifname, &info, why, sizeof(why));
            if (rc < 0) {
                add(r, PS_DOCTOR_FAIL, what, "check that rtnetlink answers (`ip -details link`)",
                    "%s", why);
            } else {
                describe_iface(&info, got, sizeof(got));
                rc = ps_can_socket_check_iface(bus, &info, c->min_txqueuelen[b], why, sizeof(why),
                                               note, sizeof(note));
                if (rc < 0)
                    add(r, PS_DOCTOR_FAIL, what, why, "%s", got);
                else
                    add(r, PS_DOCTOR_OK, what, NULL, "%s%s%s", got, note[0] ? "; " : "", note);
            }
        }
        check_can_driver(c, b, r);
        if (c->plan != NULL && ps_canbus_rx_risk(bus, c->plan, b, note, sizeof(note)) > 0) {
            (void)snprintf(what, sizeof(what), "%s receive", bus->ifname);
            add(r, PS_DOCTOR_WARN, what,
                "run the controller's interrupt threads above the loop's priority (`ps -eLo "
                "pid,rtprio,comm | grep irq/`, then `sudo chrt -f -p 90 PID`), or use a controller "
                "with an RX FIFO (MCP2518FD: boards/rpi5.yaml)",
                "%s", note);
        }
    }
}

/* ---- GPIO and camera ------------------------------------------------------ */

static void check_gpio(const ps_doctor_cfg_t *c, ps_doctor_report_t *r)
{
    const ps_gpio_cfg_t *g = &c->board->gpio;
    if (c->ops.gpio_probe == NULL) {
        add(r, PS_DOCTOR_NOTE, "gpio", NULL, "chip %s not queried (the live system only)",
            g->chip);
        return;
    }
    ps_gpio_gpiod_probe_t p;
    char why[384];
    if (c->ops.gpio_probe(c->ops.ctx, g, &p, why, sizeof(why)) < 0) {
        add(r, PS_DOCTOR_FAIL, "gpio",
            "`gpiodetect` lists the chips: correct gpio.chip; permissions: the shipped udev rules "
            "give group pushstep the chips",
            "%s", why);
        return;
    }
    for (int i = 0; i < 3; i++) {
        const ps_gpio_gpiod_line_info_t *li = &p.lines[i];
        char what[32], fix[256];
        (void)snprintf(what, sizeof(what), "gpio %s", li->role);
        if (!li->is_found) {
            add(r, PS_DOCTOR_FAIL, what,
                "correct the line's name or offset in the board file (`gpioinfo` lists them)", "%s",
                li->why);
        } else if (li->is_used) {
            const bool is_ours = strncmp(li->consumer, "pushstep", 8) == 0;
            (void)snprintf(fix, sizeof(fix), "%s",
                           is_ours ? "pushstep already runs: `systemctl status 'pushstep@*'`"
                                   : "free it (the overlay or program holding it) or pick a free "
                                     "line in the board file");
            add(r, PS_DOCTOR_FAIL, what, fix, "%s [%s] line %u \"%s\" is in use by \"%s\"",
                p.chip_name, p.chip_label, li->offset, li->name, li->consumer);
        } else {
            add(r, PS_DOCTOR_OK, what, NULL, "%s [%s] line %u \"%s\", free", p.chip_name,
                p.chip_label, li->offset, li->name);
        }
    }
}

static void check_camera(const ps_doctor_cfg_t *c, ps_doctor_report_t *r)
{
    if (!c->board->has_camera) {
        add(r, PS_DOCTOR_NOTE, "camera", NULL, "the board states no camera");
        return;
    }
    const char *sensor = c->board->camera.sensor;
    char dir_path[PATH_MAX], seen[SHORT_LEN] = "";
    at_root(c, "/sys/class/video4linux", dir_path, sizeof(dir_path));
    DIR *d = opendir(dir_path);
    size_t n_seen = 0;
    for (struct dirent *e = d != NULL ? readdir(d) : NULL; e != NULL; e = readdir(d)) {
        if (e->d_name[0] == '.')
            continue;
        char path[PATH_MAX], name[128], dev[PATH_MAX];
        (void)snprintf(path, sizeof(path), "/sys/class/video4linux/%.64s/name", e->d_name);
        if (read_text(c, path, name, sizeof(name)) < 0)
            continue;
        if (strcasestr(name, sensor) == NULL) {
            if (n_seen < sizeof(seen))
                n_seen += (size_t)snprintf(seen + n_seen, sizeof(seen) - n_seen, "%s%s: \"%s\"",
                                           n_seen ? ", " : "", e->d_name, name);
            continue;
        }
        (void)snprintf(dev, sizeof(dev), "/dev/%.64s", e->d_name);
        if (!exists(c, dev, R_OK | W_OK))
            add(r, PS_DOCTOR_WARN, "camera",
                "`sudo usermod -aG video pushstep` (the video group owns /dev/video*)",
                "%s \"%s\" found, but %s is not readable and writable here", e->d_name, name, dev);
        else
            add(r, PS_DOCTOR_OK, "camera", NULL, "%s: \"%s\" (%s)", e->d_name, name, dev);
        (void)closedir(d);
        return;
    }
    if (d != NULL)
        (void)closedir(d);
    add(r, PS_DOCTOR_WARN, "camera",
        "connect and enable it (Raspberry Pi: camera_auto_detect=1 in "
        "/boot/firmware/config.txt), then `v4l2-ctl --list-devices`",
        "no V4L2 device named like \"%s\"%s%s", sensor, n_seen ? "; seen: " : " (none at all)",
        seen);
}

/* ---- run, print, main ------------------------------------------------------ */

int ps_doctor_run(const ps_doctor_cfg_t *cfg, ps_doctor_report_t *out)
{
    memset(out, 0, sizeof(*out));
    check_kernel(cfg, out);
    check_privileges(cfg, out);
    check_cpu(cfg, out);
    check_clock(cfg, out);
    check_cpu_latency(cfg, out);
    if (cfg->board->kind == PS_BOARD_LINUX) {
        check_can(cfg, out);
        check_gpio(cfg, out);
    } else {
        add(out, PS_DOCTOR_NOTE, "can, gpio", NULL,
            "board %s is simulated: no interfaces or lines to check", cfg->board->name);
    }
    check_camera(cfg, out);
    return (int)out->n_fail;
}

static int query_live(void *ctx, const char *ifname, ps_can_socket_iface_t *out, char *err,
                      size_t err_len)
{
    (void)ctx;
    return ps_can_socket_query(ifname, out, err, err_len);
}

static int probe_live(void *ctx, const ps_gpio_cfg_t *cfg, ps_gpio_gpiod_probe_t *out, char *err,
                      size_t err_len)
{
    (void)ctx;
    return ps_gpio_gpiod_probe(cfg, out, err, err_len);
}

const ps_doctor_ops_t PS_DOCTOR_LIVE_OPS = {query_live, probe_live, NULL};

void ps_doctor_print(const ps_doctor_report_t *r, FILE *out)
{
    static const char *const LABEL[] = {"ok     ", "note   ", "TO FIX ", "TO FIX "};
    for (uint32_t i = 0; i < r->n_items; i++) {
        const ps_doctor_item_t *it = &r->items[i];
        fprintf(out, "  %s %s: %s%s\n", LABEL[it->level], it->what, it->found,
                it->level == PS_DOCTOR_FAIL ? " (required)" : "");
        if (it->fix[0] != '\0')
            fprintf(out, "          fix: %s\n", it->fix);
    }
    fprintf(out, "%u fine, %u to fix (%u required)\n", r->n_ok, r->n_fail + r->n_warn, r->n_fail);
}

static const char DOCTOR_USAGE[] =
    "usage: pushstep doctor [--board NAME|FILE] [--robot FILE] [--root DIR]\n"
    "Checks this machine for what the loop needs on that board: kernel (PREEMPT_RT),\n"
    "real-time priority and memory locking, the loop's CPU (online, allowed,\n"
    "isolated, governor), clock source, /dev/cpu_dma_latency, each CAN interface\n"
    "(up, bitrate, FD, restart-ms, txqueuelen, kernel driver), the GPIO lines\n"
    "(present and free) and the camera. Each item is fine or to fix, with the\n"
    "command that fixes it.\n"
    "\n"
    "  --board NAME|FILE  board file, or NAME for boards/NAME.yaml (default sim)\n"
    "  --robot FILE       robot file, for each bus's traffic (default robots/ps1.yaml)\n"
    "  --root DIR         read /proc, /sys and /dev under DIR instead of / (a copy of\n"
    "                     a target's files, the tests' fake trees); CAN interfaces\n"
    "                     and GPIO lines are then not queried\n"
    "  -h, --help         this text\n"
    "Run it as the service's user with the service's limits to see what the\n"
    "service gets: `sudo systemd-run --pty --uid=pushstep -p LimitRTPRIO=95\n"
    "-p LimitMEMLOCK=infinity pushstep doctor --board NAME` (docs/deploy.md).\n"
    "Exit status: 0 nothing required missing, 1 something required missing,\n"
    "2 bad usage or configuration.\n";

int ps_doctor_main(int argc, char **argv, const char *data_dir)
{
    static const struct option LONG[] = {
        {"board", required_argument, NULL, 'b'},
        {"robot", required_argument, NULL, 'r'},
        {"root", required_argument, NULL, 'R'},
        {"help", no_argument, NULL, 'h'},
        {NULL, 0, NULL, 0},
    };
    const char *board_arg = NULL, *robot_arg = NULL, *root = NULL;
    optind = 1;
    int ch;
    while ((ch = getopt_long(argc, argv, "h", LONG, NULL)) != -1) {
        switch (ch) {
        case 'b':
            board_arg = optarg;
            break;
        case 'r':
            robot_arg = optarg;
            break;
        case 'R':
            root = optarg;
            break;
        case 'h':
            fputs(DOCTOR_USAGE, stdout);
            return 0;
        default:
            fputs(DOCTOR_USAGE, stderr);
            return 2;
        }
    }
    if (optind < argc) {
        fprintf(stderr, "pushstep doctor: unexpected argument \"%s\"\n%s", argv[optind],
                DOCTOR_USAGE);
        return 2;
    }
    static ps_board_cfg_t board; /* large: not on the stack */
    static ps_robot_cfg_t robot;
    static ps_canbus_plan_t plan;
    char board_path[PATH_MAX], robot_path[PATH_MAX], err[PS_ERR_MSG_LEN];
    ps_config_resolve(data_dir, board_arg, "boards", "sim", board_path, sizeof(board_path));
    ps_config_resolve(data_dir, robot_arg, "robots", "ps1", robot_path, sizeof(robot_path));
    int rc = ps_config_load_board(board_path, &board, err, sizeof(err));
    if (rc == 0)
        rc = ps_config_load_robot(robot_path, &robot, err, sizeof(err));
    if (rc == 0)
        rc = ps_config_check_pair(&board, &robot, err, sizeof(err));
    if (rc == 0)
        rc = ps_app_plan_buses(&board, &robot, &plan, err, sizeof(err));
    if (rc < 0) {
        fprintf(stderr, "pushstep doctor: %s\n", err[0] ? err : ps_strerror(rc));
        return 2;
    }
    ps_doctor_cfg_t cfg = {.root = root, .board = &board, .plan = &plan};
    if (root == NULL)
        cfg.ops = PS_DOCTOR_LIVE_OPS;
    for (uint32_t b = 0; b < board.n_buses; b++)
        cfg.min_txqueuelen[b] = ps_app_min_txqueuelen(&robot, b);
    printf("pushstep doctor: board %s (%s), robot %s (%s), uid %u%s%s\n", board.name, board_path,
           robot.name, robot_path, (unsigned)getuid(), root != NULL ? ", root " : "",
           root != NULL ? root : "");
    static ps_doctor_report_t report;
    rc = ps_doctor_run(&cfg, &report);
    ps_doctor_print(&report, stdout);
    return rc > 0 ? 1 : 0;
}
