/*
 * fuzz_config: the YAML loaders (rt/ps_config_*.c, libcyaml with a libyaml
 * position tree) under one harness: fuzz_config_board.c, fuzz_config_robot.c,
 * fuzz_config_scenario.c.
 *
 * The input is the file (an in-memory memfd, tests/fuzz/fuzz.h), loaded by
 * the real entry point. Contract: 0, or a negative code with a message that
 * names the file ("FILE[:LINE]: ...", NUL-terminated inside the buffer);
 * a loaded file's values validated (each target checks what it can recheck
 * independently); nothing leaks (LeakSanitizer).
 */
#ifndef PS_FUZZ_CONFIG_H
#define PS_FUZZ_CONFIG_H

#include <errno.h>

#include "../../rt/ps_err.h"
#include "fuzz.h"

#define FUZZ_CONFIG_ERR_LEN 512u

static void fuzz_config_check_err(int rc, const char *path, const char *err)
{
    FUZZ_CHECK(rc <= 0, "loader returned %d", rc);
    FUZZ_CHECK(memchr(err, '\0', FUZZ_CONFIG_ERR_LEN) != NULL, "message not terminated");
    if (rc == 0)
        return;
    FUZZ_CHECK(rc == -PS_ERR_CONFIG || rc == -ENOENT || rc == -EINVAL || rc == -ENOMEM ||
                   rc == -EIO,
               "loader returned %d (%s)", rc, err);
    if (rc == -PS_ERR_CONFIG)
        FUZZ_CHECK(strncmp(err, path, strlen(path)) == 0 && err[strlen(path)] != '\0',
                   "a refusal without a message naming the file: \"%s\"", err);
}

#endif /* PS_FUZZ_CONFIG_H */
