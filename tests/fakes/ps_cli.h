/*
 * Helpers of the command-line tests (tests/test_e2e_*.c): run the binary the
 * Makefile built ($PUSHSTEP_BIN, default build/pushstep) from the repository
 * root and capture its output, temporary files, and the JSON it writes.
 * Failures are cmocka assertions. Threads: the test's. Allocation: cJSON's.
 */
#ifndef PS_CLI_H
#define PS_CLI_H

#include <stddef.h>
#include <sys/types.h>

#include <cjson/cJSON.h>

/** @return $PUSHSTEP_BIN, or build/pushstep; in a build with ASan (the
 *  end-to-end tests' sanitized build) the sanitized runtime instead:
 *  $PUSHSTEP_SAN_BIN, or build/san/pushstep */
const char *ps_cli_bin(void);

/** Run `bin args` with stdout and stderr captured into out (NUL-terminated,
 *  cut at out_len - 1). @return its exit status (asserts it exited, and
 *  that the output holds no sanitizer report) */
int ps_cli_run(const char *args, char *out, size_t out_len);

/** Start argv (argv[0] the binary) in the background, its stdout and
 *  stderr into a pipe. @return the pipe's read end (asserts the spawn) */
int ps_cli_spawn_piped(char *const argv[], pid_t *out_pid);

/** An empty file under /tmp (its path into path). */
void ps_cli_temp_file(char *path, size_t len);

/** A JSON file parsed (asserts it parses); the caller cJSON_Deletes it. */
cJSON *ps_cli_read_json(const char *path);

/** o's member key: a number (asserts it is one), an object or any item
 *  (asserts it is there). */
double ps_cli_num(const cJSON *o, const char *key);
const cJSON *ps_cli_obj(const cJSON *o, const char *key);

/** A summary's after_init (the loop thread after init): allocations and
 *  locks counted, no malloc, free or lock; no page fault (reported, not
 *  asserted, in the sanitized build: tests/fakes/ps_san.h). */
void ps_cli_assert_after_init_clean(const cJSON *summary);

#endif /* PS_CLI_H */
