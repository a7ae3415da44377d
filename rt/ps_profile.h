/*
 * ps_profile: the NON-RT side of `pushstep profile`: an optional stress-ng
 * load running beside the loop, and the output folder (profile.json, the
 * wake-up histogram in cyclictest's `-h` text format, PNG plots drawn by
 * tools/plot-profile.sh when gnuplot is installed).
 *
 * Threads: main thread, before the loop starts and after it stopped.
 * Allocation: yes (NON-RT).
 */
#ifndef PS_PROFILE_H
#define PS_PROFILE_H

#include <stddef.h>
#include <sys/types.h>

#include "ps_perf.h"
#include "ps_summary.h"

/** @return 0 if kind is "cpu", "mem" or "io", else -EINVAL */
int ps_profile_check_stress(const char *kind);

/** Start stress-ng for duration_s (+ a margin) with a load of `kind` on every
 *  CPU. @post *out_pid is the child  @return 0 | -ENOENT (stress-ng not
 *  installed: err says which package) | -errno  @rt NON-RT */
int ps_profile_start_stress(const char *kind, double duration_s, pid_t *out_pid, char *err,
                            size_t err_len);

/** Stop and reap the stress child. Safe with pid <= 0. @rt NON-RT */
void ps_profile_stop_stress(pid_t pid);

/** Write dir/profile.json and dir/wakeup.hist. Creates dir.
 *  @post err says what failed  @return 0 | -errno  @rt NON-RT */
int ps_profile_write(const char *dir, const ps_summary_t *sum, const ps_perf_us_hist_t *wake,
                     char *err, size_t err_len);

/** Draw the PNG plots into dir with data_dir/tools/plot-profile.sh (gnuplot).
 *  @return 0 | -ENOENT gnuplot missing | -ECHILD the script failed (err says)  @rt NON-RT */
int ps_profile_plot(const char *dir, const char *data_dir, char *err, size_t err_len);

#endif /* PS_PROFILE_H */
