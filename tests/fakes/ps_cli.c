#include "ps_cli.h"

#include <setjmp.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmocka.h>

#define JSON_MAX (256 * 1024)

const char *ps_cli_bin(void)
{
    const char *b = getenv("PUSHSTEP_BIN");
    return b ? b : "build/pushstep";
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
