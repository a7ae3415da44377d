#include "ps_profile.h"

#include <errno.h>
#include <signal.h>
#include <spawn.h>
#include <stdio.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include "ps_err.h"

extern char **environ;

/* Margin so the load outlasts the loop's damping phase after the end. */
#define STRESS_MARGIN_S 10.0

int ps_profile_check_stress(const char *kind)
{
    static const char *const KINDS[] = {"cpu", "mem", "io"};
    for (size_t i = 0; i < sizeof(KINDS) / sizeof(KINDS[0]); i++)
        if (strcmp(kind, KINDS[i]) == 0)
            return 0;
    return -EINVAL;
}

static int spawn_wait(char *const argv[])
{
    pid_t pid;
    int rc = posix_spawnp(&pid, argv[0], NULL, NULL, argv, environ);
    if (rc != 0)
        return -rc;
    int status = 0;
    if (waitpid(pid, &status, 0) < 0)
        return -errno;
    return (WIFEXITED(status) && WEXITSTATUS(status) == 0) ? 0 : -ECHILD;
}

static bool has_program(const char *name)
{
    char cmd[128];
    snprintf(cmd, sizeof(cmd), "command -v %s >/dev/null 2>&1", name);
    char *const argv[] = {"sh", "-c", cmd, NULL};
    return spawn_wait(argv) == 0;
}

int ps_profile_start_stress(const char *kind, double duration_s, pid_t *out_pid, char *err,
                            size_t err_len)
{
    if (ps_profile_check_stress(kind) < 0) {
        ps_err_format(err, err_len, "--stress: \"%s\" is not one of cpu, mem, io", kind);
        return -EINVAL;
    }
    if (!has_program("stress-ng")) {
        ps_err_format(err, err_len,
                      "--stress needs stress-ng: apt-get install stress-ng (or make deps-bench)");
        return -ENOENT;
    }
    char timeout[32];
    snprintf(timeout, sizeof(timeout), "%.0fs", duration_s + STRESS_MARGIN_S);
    /* One worker per CPU ("0"); mem and io workers bounded so the machine
     * stays usable. */
    char *const cpu[] = {"stress-ng", "--cpu", "0", "--timeout", timeout, "--quiet", NULL};
    char *const mem[] = {"stress-ng", "--vm",  "0",       "--vm-bytes", "25%",
                         "--timeout", timeout, "--quiet", NULL};
    char *const io[] = {"stress-ng", "--hdd",     "0",     "--hdd-bytes", "64M", "--temp-path",
                        "/tmp",      "--timeout", timeout, "--quiet",     NULL};
    char *const *argv = strcmp(kind, "cpu") == 0 ? cpu : strcmp(kind, "mem") == 0 ? mem : io;
    int rc = posix_spawnp(out_pid, argv[0], NULL, NULL, argv, environ);
    if (rc != 0) {
        ps_err_format(err, err_len, "cannot start stress-ng: %s", strerror(rc));
        return -rc;
    }
    return 0;
}

void ps_profile_stop_stress(pid_t pid)
{
    if (pid <= 0)
        return;
    (void)kill(pid, SIGTERM); /* it may have ended by its own timeout */
    (void)waitpid(pid, NULL, 0);
}

static int write_hist(const char *path, const ps_perf_us_hist_t *wake, char *err, size_t len)
{
    FILE *f = fopen(path, "w");
    int rc = f ? ps_perf_us_write_cyclictest(wake, f) : -errno;
    if (f != NULL && fclose(f) != 0 && rc == 0)
        rc = -errno;
    if (rc < 0)
        ps_err_format(err, len, "cannot write %s: %s", path, strerror(-rc));
    return rc;
}

int ps_profile_write(const char *dir, const ps_summary_t *sum, const ps_perf_us_hist_t *wake,
                     char *err, size_t err_len)
{
    if (mkdir(dir, 0755) < 0 && errno != EEXIST) {
        ps_err_format(err, err_len, "cannot create %s: %s", dir, strerror(errno));
        return -errno;
    }
    char path[4096];
    snprintf(path, sizeof(path), "%s/profile.json", dir);
    int rc = ps_summary_write_json(sum, path, err, err_len);
    snprintf(path, sizeof(path), "%s/wakeup.hist", dir);
    if (rc == 0)
        rc = write_hist(path, wake, err, err_len);
    return rc;
}

int ps_profile_plot(const char *dir, const char *data_dir, char *err, size_t err_len)
{
    if (!has_program("gnuplot")) {
        ps_err_format(err, err_len, "no plots: gnuplot is not installed (make deps-bench)");
        return -ENOENT;
    }
    char path[4096];
    snprintf(path, sizeof(path), "%s/tools/plot-profile.sh", data_dir);
    char *const argv[] = {"bash", path, (char *)dir, NULL};
    if (spawn_wait(argv) < 0) {
        ps_err_format(err, err_len, "plots: %s %s failed", path, dir);
        return -ECHILD;
    }
    return 0;
}
