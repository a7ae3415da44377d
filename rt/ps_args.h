/*
 * ps_args: parsing of command-line values shared by the subcommands.
 *
 * Each subcommand (pushstep, emulate, monitor, camera, log) prints its own
 * message naming its option; this module only decides whether the text is a
 * valid value, so that every option that takes seconds accepts and refuses
 * the same things: a whole decimal or floating-point number, nothing after
 * it, finite, within the caller's range. Threads: any. Allocation: none.
 */
#ifndef PS_ARGS_H
#define PS_ARGS_H

#include <stdbool.h>

/** Seconds from text, inside [min_s, max_s] (or (min_s, max_s] when
 *  is_min_open).
 *  @return 0 with *out_s set | -EINVAL (empty, trailing text, not finite,
 *  out of range; *out_s untouched)  @rt NON-RT (strtod), any thread */
int ps_args_seconds(const char *text, double min_s, double max_s, bool is_min_open, double *out_s);

#endif /* PS_ARGS_H */
