#include "ps_cli.h"

#include <setjmp.h>
#include <spawn.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <sys/wait.h>
#include <unistd.h>

extern char **environ;

#include <cmocka.h>

#include "ps_san.h"

#define JSON_MAX (256 * 1024)

const char *ps_cli_bin(void)
{
    if (ps_san_is_asan()) {
        const char *b = getenv("PUSHSTEP_SAN_BIN");
        return b ? b : "build/san/pushstep";
    }
    const char *b = getenv("PUSHSTEP_BIN");
    return b ? b : "build/pushstep";
}

int ps_cli_spawn_piped(char *const argv[], pid_t *out_pid)
{
    int fds[2];
    assert_int_equal(pipe(fds), 0);
    posix_spawn_file_actions_t fa;
    assert_int_equal(posix_spawn_file_actions_init(&fa), 0);
    assert_int_equal(posix_spawn_file_actions_adddup2(&fa, fds[1], 1), 0);
    assert_int_equal(posix_spawn_file_actions_adddup2(&fa, fds[1], 2), 0);
    assert_int_equal(posix_spawn_file_actions_addclose(&fa, fds[0]), 0);
    assert_int_equal(posix_spawn(out_pid, argv[0], &fa, NULL, argv, environ), 0);
    posix_spawn_file_actions_destroy(&fa);
    close(fds[1]);
    return fds[0];
}

int ps_cli_run(const char *args, char *out, size_t out_len)
{
    char cmd[1024];
    snprintf(cmd, sizeof(cmd), "%s %s 2>&1", ps_cli_bin(), args);
    FILE *p = popen(cmd, "r");
    assert_non_null(p);
    size_t n = fread(out, 1, out_len - 1, p);
    out[n] = '\0';
    int status = pclose(p);
    ps_san_assert_no_report(out);
    assert_true(WIFEXITED(status));
    return WEXITSTATUS(status);
}

void ps_cli_temp_file(char *path, size_t len)
{
    snprintf(path, len, "/tmp/ps_cli_XXXXXX");
    int fd = mkstemp(path);
    assert_true(fd >= 0);
    close(fd);
}

cJSON *ps_cli_read_json(const char *path)
{
    FILE *f = fopen(path, "r");
    assert_non_null(f);
    static char text[JSON_MAX];
    size_t n = fread(text, 1, sizeof(text) - 1, f);
    text[n] = '\0';
    fclose(f);
    cJSON *j = cJSON_Parse(text);
    assert_non_null(j);
    return j;
}

double ps_cli_num(const cJSON *o, const char *key)
{
    const cJSON *v = cJSON_GetObjectItemCaseSensitive(o, key);
    if (!cJSON_IsNumber(v))
        fail_msg("JSON key \"%s\" missing or not a number", key);
    return v->valuedouble;
}

const cJSON *ps_cli_obj(const cJSON *o, const char *key)
{
    const cJSON *v = cJSON_GetObjectItemCaseSensitive(o, key);
    if (v == NULL)
        fail_msg("JSON key \"%s\" missing", key);
    return v;
}

void ps_cli_assert_after_init_clean(const cJSON *summary)
{
    const cJSON *after = ps_cli_obj(summary, "after_init");
    assert_true(cJSON_IsTrue(ps_cli_obj(after, "allocations_counted")));
    const double mallocs = ps_cli_num(after, "mallocs"), frees = ps_cli_num(after, "frees");
    const double locks = ps_cli_num(after, "locks");
    if (mallocs != 0 || frees != 0 || locks != 0)
        fail_msg("after init on the loop thread: %.0f mallocs, %.0f frees, %.0f locks, want 0",
                 mallocs, frees, locks);
    ps_san_assert_zero((uint64_t)ps_cli_num(after, "page_faults"), PS_SAN_PAGE_FAULTS,
                       "the runtime's loop thread after init, page faults");
}
