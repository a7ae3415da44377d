/*
 * Tests of policy/ps_safetensors.c and policy/ps_weights.c: every check of
 * the file format (each malformed file made here, byte by byte), the
 * contract, and the contract against a robot, each refusal naming what is
 * wrong.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../policy/ps_safetensors.h"
#include "../policy/ps_weights.h"
#include "../rt/ps_err.h"

#define GOLDEN "tests/data/policy/golden_base.safetensors"

/* A safetensors image: 8-byte length, header, data. */
static size_t image(uint8_t *buf, const char *header, const void *data, size_t data_len)
{
    const uint64_t n = strlen(header);
    for (int i = 0; i < 8; i++)
        buf[i] = (uint8_t)(n >> (8 * i));
    memcpy(buf + 8, header, n);
    if (data_len)
        memcpy(buf + 8 + n, data, data_len);
    return 8 + n + data_len;
}

static void expect_refused(const char *header, const void *data, size_t len, int want_rc,
                           const char *want_text)
{
    static uint8_t buf[4096];
    const size_t n = image(buf, header, data, len);
    ps_st_file_t st;
    char err[512] = "";
    const int rc = ps_st_parse(&st, buf, n, err, sizeof(err));
    if (rc == 0)
        ps_st_free(&st);
    if (rc != want_rc || strstr(err, want_text) == NULL)
        fail_msg("header %s: rc %d '%s', want %d with '%s'", header, rc, err, want_rc, want_text);
}

static void test_ps_st_parse_refuses_each_malformation(void **st)
{
    (void)st;
    const float two[2] = {1.0f, 2.0f};
    expect_refused("{\"a\":{\"dtype\":\"F32\",\"shape\":[2],\"data_offsets\":[0,8]}}", two, 8, 0,
                   "");
    expect_refused("{\"a\":{\"dtype\":\"F16\",\"shape\":[4],\"data_offsets\":[0,8]}}", two, 8,
                   -ENOTSUP, "dtype F16, only F32");
    expect_refused("{\"a\":{\"dtype\":\"F32\",\"shape\":[3],\"data_offsets\":[0,8]}}", two, 8,
                   -EINVAL, "8 bytes for 3 F32 elements");
    expect_refused("{\"a\":{\"dtype\":\"F32\",\"shape\":[2],\"data_offsets\":[0,16]}}", two, 8,
                   -EINVAL, "beyond the data section");
    expect_refused("{\"a\":{\"dtype\":\"F32\",\"shape\":[2],\"data_offsets\":[0,8]},"
                   "\"b\":{\"dtype\":\"F32\",\"shape\":[1],\"data_offsets\":[4,8]}}",
                   two, 8, -EINVAL, "overlap");
    expect_refused("{\"a\":{\"dtype\":\"F32\",\"shape\":[1],\"data_offsets\":[4,8]}}", two, 8,
                   -EINVAL, "bytes [0, 4) of the data section belong to no tensor");
    expect_refused("{\"a\":{\"dtype\":\"F32\",\"shape\":[1],\"data_offsets\":[0,4]}}", two, 8,
                   -EINVAL, "bytes [4, 8) of the data section belong to no tensor");
    expect_refused("{\"a\":{\"dtype\":\"F32\",\"shape\":[2],\"data_offsets\":[0,8],\"x\":1}}", two,
                   8, -EINVAL, "unknown key 'x'");
    expect_refused("{\"a\":{\"dtype\":\"F32\",\"shape\":[2]}}", two, 8, -EINVAL, "needs dtype");
    expect_refused("{\"a\":{\"dtype\":\"F32\",\"shape\":[-2],\"data_offsets\":[0,8]}}", two, 8,
                   -EINVAL, "shape[0] is not a size");
    expect_refused("{\"a\":{\"dtype\":\"F32\",\"shape\":[2],\"data_offsets\":[8,0]}}", two, 8,
                   -EINVAL, "begin <= end");
    expect_refused("{\"__metadata__\":{\"k\":1},"
                   "\"a\":{\"dtype\":\"F32\",\"shape\":[2],\"data_offsets\":[0,8]}}",
                   two, 8, -EINVAL, "__metadata__.k: value is not a string");
    expect_refused("not json", two, 8, -EINVAL, "not a JSON object");
    /* a header length beyond the file */
    uint8_t b[16] = {0xff, 0xff, 0, 0, 0, 0, 0, 0, '{', '}'};
    ps_st_file_t f;
    char err[512] = "";
    assert_int_equal(ps_st_parse(&f, b, 10, err, sizeof(err)), -EINVAL);
    assert_non_null(strstr(err, "header length 65535: beyond the file"));
    assert_int_equal(ps_st_parse(&f, b, 4, err, sizeof(err)), -EINVAL);
    assert_non_null(strstr(err, "shorter than the 8-byte header length"));
}

static void test_ps_st_copy_f32_refuses_nan_and_inf(void **st)
{
    (void)st;
    static uint8_t buf[512];
    const float v[3] = {1.0f, NAN, INFINITY};
    const size_t n =
        image(buf, "{\"w\":{\"dtype\":\"F32\",\"shape\":[3],\"data_offsets\":[0,12]}}", v, 12);
    ps_st_file_t f;
    char err[512] = "";
    assert_int_equal(ps_st_parse(&f, buf, n, err, sizeof(err)), 0);
    float out[3];
    assert_int_equal(ps_st_copy_f32(&f, ps_st_find(&f, "w"), out, 3, err, sizeof(err)), -ERANGE);
    assert_string_equal(err, "tensor w: element 1 is NaN");
    assert_int_equal(ps_st_copy_f32(&f, ps_st_find(&f, "w"), out, 2, err, sizeof(err)), -ENOSPC);
    ps_st_free(&f);
    ps_st_free(&f); /* twice is safe */
    assert_int_equal(ps_st_load(&f, "tests/data/policy/nope.safetensors", err, sizeof(err)),
                     -ENOENT);
}

/* ---- policy files: the golden base, then edited copies ------------------ */

static char g_dir[64];

static int setup(void **st)
{
    (void)st;
    snprintf(g_dir, sizeof(g_dir), "/tmp/ps_test_weights.XXXXXX");
    return mkdtemp(g_dir) != NULL ? 0 : -1;
}

static int teardown(void **st)
{
    (void)st;
    char cmd[128];
    snprintf(cmd, sizeof(cmd), "rm -rf %s", g_dir);
    return system(cmd) == 0 ? 0 : -1;
}

/* Policy file src with its contract's text edited: "from" -> "to", written
 * to path (src may be path: it is read whole first). */
static void edited_from(const char *src, const char *from, const char *to, char *path, size_t len)
{
    FILE *f = fopen(src, "rb");
    assert_non_null(f);
    static uint8_t raw[1 << 16];
    const size_t n = fread(raw, 1, sizeof(raw), f);
    fclose(f);
    uint64_t h = 0;
    for (int i = 7; i >= 0; i--)
        h = (h << 8) | raw[i];
    static char header[1 << 14];
    memcpy(header, raw + 8, h);
    header[h] = '\0';
    char *at = strstr(header, from);
    if (at == NULL)
        fail_msg("'%s' not in the header", from);
    static char out_h[1 << 14];
    snprintf(out_h, sizeof(out_h), "%.*s%s%s", (int)(at - header), header, to, at + strlen(from));
    snprintf(path, len, "%s/edited.safetensors", g_dir);
    static uint8_t img[1 << 16];
    const size_t m = image(img, out_h, raw + 8 + h, n - 8 - h);
    f = fopen(path, "wb");
    assert_non_null(f);
    assert_int_equal(fwrite(img, 1, m, f), m);
    fclose(f);
}

/* The golden base file with its contract's text edited: "from" -> "to". */
static void edited(const char *from, const char *to, char *path, size_t len)
{
    edited_from(GOLDEN, from, to, path, len);
}

static void expect_load_refused(const char *from, const char *to, int want_rc, const char *text)
{
    char path[128], err[512] = "";
    edited(from, to, path, sizeof(path));
    ps_weights_t w;
    const int rc = ps_weights_load(&w, path, err, sizeof(err));
    if (rc != want_rc || strstr(err, text) == NULL || strstr(err, path) != err)
        fail_msg("'%s' -> '%s': rc %d '%s', want %d with '%s'", from, to, rc, err, want_rc, text);
}

static void test_ps_weights_load_golden_contract(void **st)
{
    (void)st;
    ps_weights_t w;
    char err[512];
    if (ps_weights_load(&w, GOLDEN, err, sizeof(err)) != 0)
        fail_msg("%s", err);
    const ps_weights_contract_t *c = &w.contract;
    assert_int_equal(c->version, 1);
    assert_int_equal(c->policy_hz, 50);
    assert_int_equal(c->n_joints, 4);
    assert_string_equal(c->joint_name[2], "j2");
    assert_int_equal(c->n_obs, 15);
    assert_int_equal(c->n_act, 4);
    assert_int_equal(c->fields[1], PS_OBS_JOINT_POS);
    assert_float_equal(c->stance_rad[3], 0.2f, 1e-7);
    assert_float_equal(c->act_scale[0], 0.5f, 0.0);
    assert_int_equal(c->act_base, PS_WEIGHTS_BASE_STANCE); /* no action.base */
    assert_int_equal(w.mlp.n_layers, 3);
    ps_weights_free(&w);
    ps_weights_free(&w);
}

/* action.base: "stance" or "capture" (a residual policy) load; anything
 * else is refused, named. */
static void test_ps_weights_action_base(void **st)
{
    (void)st;
    static const struct {
        const char *base;
        ps_weights_base_t want;
    } OK[] = {{"stance", PS_WEIGHTS_BASE_STANCE}, {"capture", PS_WEIGHTS_BASE_CAPTURE}};
    static const char SCALE[] = "\\\"scale\\\": [0.5, 0.5, 0.5, 0.5]";
    for (size_t i = 0; i < sizeof(OK) / sizeof(OK[0]); i++) {
        char to[128], path[128], err[512] = "";
        snprintf(to, sizeof(to), "%s, \\\"base\\\": \\\"%s\\\"", SCALE, OK[i].base);
        edited(SCALE, to, path, sizeof(path));
        ps_weights_t w;
        if (ps_weights_load(&w, path, err, sizeof(err)) != 0)
            fail_msg("base %s: %s", OK[i].base, err);
        assert_int_equal(w.contract.act_base, OK[i].want);
        ps_weights_free(&w);
    }
    expect_load_refused(SCALE, "\\\"scale\\\": [0.5, 0.5, 0.5, 0.5], \\\"base\\\": \\\"crowd\\\"",
                        -EINVAL, "action.base crowd is not \"stance\" or \"capture\"");
    expect_load_refused(SCALE, "\\\"scale\\\": [0.5, 0.5, 0.5, 0.5], \\\"base\\\": 1", -EINVAL,
                        "action.base (not a string) is not");
    /* the base_action observation field: only with a base to observe */
    expect_load_refused("\\\"prev_action\\\"]", "\\\"base_action\\\"]", -EINVAL,
                        "observation.fields[3] 'base_action' needs action.base \"capture\"");
}

/* A residual policy may observe its base (base_action, A floats). */
static void test_ps_weights_base_action_field_with_capture(void **st)
{
    (void)st;
    char path[128], err[512] = "";
    edited("\\\"prev_action\\\"]", "\\\"base_action\\\"]", path, sizeof(path));
    edited_from(path, "\\\"clip\\\": 10.0}, \\\"activations",
                "\\\"clip\\\": 10.0, \\\"base\\\": \\\"capture\\\"}, \\\"activations", path,
                sizeof(path));
    ps_weights_t w;
    if (ps_weights_load(&w, path, err, sizeof(err)) != 0)
        fail_msg("%s", err);
    assert_int_equal(w.contract.fields[3], PS_OBS_BASE_ACTION);
    assert_int_equal(w.contract.n_obs, 15);
    assert_int_equal(w.contract.act_base, PS_WEIGHTS_BASE_CAPTURE);
    ps_weights_free(&w);
}

static void test_ps_weights_load_refuses_bad_contracts(void **st)
{
    (void)st;
    expect_load_refused("\\\"version\\\": 1", "\\\"version\\\": 2", -EINVAL,
                        "version 2, this runtime reads version 1");
    expect_load_refused("\\\"gravity_body\\\"", "\\\"gravity\\\"", -EINVAL,
                        "observation.fields[0] 'gravity' is not a field");
    expect_load_refused("\\\"prev_action\\\"", "\\\"com_vel\\\"", -EINVAL,
                        "observation.mean has 15 entries, want 14");
    expect_load_refused("\\\"elu\\\", \\\"elu\\\", ", "\\\"elu\\\", \\\"gelu\\\", ", -EINVAL,
                        "activations[1] 'gelu' is not an activation");
    expect_load_refused("\\\"elu\\\", \\\"elu\\\", ", "\\\"elu\\\", ", -EINVAL,
                        "2 activations for 3 base layers");
    expect_load_refused("\\\"kp\\\": [100.0, 100.0, 100.0, 100.0]", "\\\"kp\\\": [100.0]", -EINVAL,
                        "kp has 1 entries, want 4");
    expect_load_refused("\\\"j3\\\"], \\\"scale\\\"", "\\\"jx\\\"], \\\"scale\\\"", -EINVAL,
                        "action.joints[3] 'jx' is not in joints");
    expect_load_refused("pushstep.contract", "other.key", -EINVAL,
                        "no metadata pushstep.contract: not a pushstep policy file");
    expect_load_refused("\"base.1.bias\"", "\"extra.1.bias\"", -EINVAL,
                        "tensor extra.1.bias: not a layer of a policy file");
    expect_load_refused("\"base.1.weight\"", "\"adapt.1.weight\"", -EINVAL,
                        "tensor base.1.weight is missing");
}

/* contract "groups": one whole number per base layer; a grouped layer's
 * weight is [out, in / G], so its input is G times its weight's width. */
static void test_ps_weights_groups(void **st)
{
    (void)st;
    static const char ACT[] = "\\\"activations\\\"";
    char path[128], err[512] = "";
    edited(ACT, "\\\"groups\\\": [1, 1, 1], \\\"activations\\\"", path, sizeof(path));
    ps_weights_t w;
    if (ps_weights_load(&w, path, err, sizeof(err)) != 0)
        fail_msg("%s", err);
    assert_int_equal(w.mlp.base[1].n_groups, 1);
    assert_int_equal(w.mlp.base[1].n_in, 64);
    ps_weights_free(&w);
    static const struct {
        const char *groups, *text;
    } BAD[] = {
        {"[1, 0, 1]", "contract: groups[1] is 0, not a whole number >= 1"},
        {"[1, 1.5, 1]", "contract: groups[1] is 1.5, not a whole number >= 1"},
        {"[1, 1]", "contract: 2 groups for 3 base layers"},
        {"\\\"x\\\"", "contract: groups is not a list"},
        /* base.1.weight [64, 64] in 3 groups: 192 inputs, 64 outputs not a multiple */
        {"[1, 3, 1]", "tensor base.1.weight: [64, 64] in 3 groups (inputs 192"},
        /* in 2 groups it takes 128 inputs, where base.0 gives 64 */
        {"[1, 2, 1]", "the layers do not chain"},
    };
    for (size_t i = 0; i < sizeof(BAD) / sizeof(BAD[0]); i++) {
        char to[128];
        snprintf(to, sizeof(to), "\\\"groups\\\": %s, \\\"activations\\\"", BAD[i].groups);
        expect_load_refused(ACT, to, -EINVAL, BAD[i].text);
    }
}

enum { MEMBERS_MAX = 8 };

/* The recorded policy files policy/weights/ps1_stage1.members lists (its
 * second column; '#' starts a comment line): the count, or fails. */
static int shipped_members(char (*path)[256])
{
    FILE *f = fopen("policy/weights/ps1_stage1.members", "r");
    if (f == NULL)
        fail_msg("policy/weights/ps1_stage1.members: %s", strerror(errno));
    char line[512];
    int n = 0;
    while (fgets(line, sizeof(line), f) != NULL) {
        int seed;
        char file[256];
        if (line[strspn(line, " \t")] == '#' || sscanf(line, "%d %255s", &seed, file) != 2)
            continue;
        if (n == MEMBERS_MAX)
            fail_msg("ps1_stage1.members: more than %d members", MEMBERS_MAX);
        snprintf(path[n++], 256, "%s", file);
    }
    fclose(f);
    return n;
}

/* The shipped policy is the mean of the members policy/weights/
 * ps1_stage1.members lists (make train's runs, recorded in bench/results:
 * docs/policy.md), its hidden layer grouped: run in this engine, on
 * observations around the first member's mean, it gives the mean of the
 * members' actions, each member normalising the observation its own way
 * (policy/train/ensemble.py folds that into the first layer). */
static void test_ps_weights_shipped_file_is_the_mean_of_its_members(void **st)
{
    (void)st;
    static char path[MEMBERS_MAX][256];
    static ps_weights_t ens, mem[MEMBERS_MAX];
    const int n = shipped_members(path);
    assert_true(n >= 2);
    char err[512];
    if (ps_weights_load(&ens, "policy/weights/ps1_stage1.safetensors", err, sizeof(err)) != 0)
        fail_msg("%s", err);
    for (int k = 0; k < n; k++)
        if (ps_weights_load(&mem[k], path[k], err, sizeof(err)) != 0)
            fail_msg("%s", err);
    assert_int_equal(ens.mlp.base[1].n_groups, n);
    assert_int_equal(ens.mlp.base[1].n_in, n * mem[0].mlp.base[1].n_in);
    const ps_weights_contract_t *c0 = &ens.contract;
    uint32_t seed = 3u;
    double worst = 0.0, spread = 0.0;
    for (int r = 0; r < 50; r++) {
        float x[PS_OBS_MAX], z[PS_OBS_MAX], out[PS_MAX_JOINTS], mean[PS_MAX_JOINTS] = {0};
        for (uint32_t i = 0; i < c0->n_obs; i++) {
            seed = seed * 1664525u + 1013904223u;
            const float u = (float)((int32_t)(seed >> 8) % 2001 - 1000) * 2e-3f; /* +-2 */
            x[i] = c0->obs_mean[i] + c0->obs_std[i] * u;
            z[i] = u;
        }
        assert_int_equal(ps_mlp_forward(&ens.mlp, z, NULL, out), 0);
        for (int k = 0; k < n; k++) {
            float zk[PS_OBS_MAX], ok[PS_MAX_JOINTS];
            for (uint32_t i = 0; i < c0->n_obs; i++)
                zk[i] = (x[i] - mem[k].contract.obs_mean[i]) / mem[k].contract.obs_std[i];
            assert_int_equal(ps_mlp_forward(&mem[k].mlp, zk, NULL, ok), 0);
            for (uint32_t o = 0; o < c0->n_act; o++) {
                mean[o] += ok[o] / (float)n;
                spread = fmax(spread, fabs((double)ok[o] - (double)out[o]));
            }
        }
        for (uint32_t o = 0; o < c0->n_act; o++)
            worst = fmax(worst, fabs((double)out[o] - (double)mean[o]));
    }
    if (!(worst < 1e-5) || !(spread > 1e-2))
        fail_msg("ensemble against the members' mean: worst %g (want < 1e-5); a member "
                 "alone differs by up to %g (want > 1e-2)",
                 worst, spread);
    for (int k = 0; k < n; k++)
        ps_weights_free(&mem[k]);
    ps_weights_free(&ens);
}

static void servo_of(const ps_weights_contract_t *c, ps_servo_joint_cfg_t *s,
                     char (*names)[PS_NAME_LEN])
{
    for (uint32_t j = 0; j < c->n_joints; j++) {
        memset(&s[j], 0, sizeof(s[j]));
        s[j].kp_nm_rad = c->kp_nm_rad[j];
        s[j].kd_nm_s_rad = c->kd_nm_s_rad[j];
        s[j].stance_rad = c->stance_rad[j];
        snprintf(names[j], PS_NAME_LEN, "%s", c->joint_name[j]);
    }
}

static void test_ps_weights_check_robot_names_each_difference(void **st)
{
    (void)st;
    ps_weights_t w;
    char err[512];
    assert_int_equal(ps_weights_load(&w, GOLDEN, err, sizeof(err)), 0);
    const ps_weights_contract_t *c = &w.contract;
    ps_servo_joint_cfg_t s[PS_MAX_JOINTS];
    char names[PS_MAX_JOINTS][PS_NAME_LEN];
    servo_of(c, s, names);
    assert_int_equal(ps_weights_check_robot(c, 4, names, s, 50, err, sizeof(err)), 0);
    /* another joint order: never moves the robot */
    snprintf(names[1], PS_NAME_LEN, "j2");
    snprintf(names[2], PS_NAME_LEN, "j1");
    assert_int_equal(ps_weights_check_robot(c, 4, names, s, 50, err, sizeof(err)), -PS_ERR_CONFIG);
    assert_string_equal(err, "joints[1]: policy has j1, robot file has j2 (trained for another "
                             "joint order or robot)");
    servo_of(c, s, names);
    assert_int_equal(ps_weights_check_robot(c, 3, names, s, 50, err, sizeof(err)), -PS_ERR_CONFIG);
    assert_string_equal(err, "joints: policy has 4 joints, robot file 3");
    s[2].kp_nm_rad = 150.0f;
    assert_int_equal(ps_weights_check_robot(c, 4, names, s, 50, err, sizeof(err)), -PS_ERR_CONFIG);
    assert_string_equal(err,
                        "joints[2] j2: kp_nm_rad: policy trained with 100, robot file has 150");
    servo_of(c, s, names);
    s[3].stance_rad = 0.25f;
    assert_int_equal(ps_weights_check_robot(c, 4, names, s, 50, err, sizeof(err)), -PS_ERR_CONFIG);
    assert_non_null(strstr(err, "stance_rad: policy trained with 0.2, robot file has 0.25"));
    servo_of(c, s, names);
    assert_int_equal(ps_weights_check_robot(c, 4, names, s, 100, err, sizeof(err)), -PS_ERR_CONFIG);
    assert_string_equal(err, "policy_hz: policy trained at 50 Hz, robot file runs 100 Hz");
    ps_weights_free(&w);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_ps_st_parse_refuses_each_malformation),
        cmocka_unit_test(test_ps_st_copy_f32_refuses_nan_and_inf),
        cmocka_unit_test(test_ps_weights_load_golden_contract),
        cmocka_unit_test(test_ps_weights_load_refuses_bad_contracts),
        cmocka_unit_test(test_ps_weights_action_base),
        cmocka_unit_test(test_ps_weights_base_action_field_with_capture),
        cmocka_unit_test(test_ps_weights_check_robot_names_each_difference),
        cmocka_unit_test(test_ps_weights_groups),
        cmocka_unit_test(test_ps_weights_shipped_file_is_the_mean_of_its_members),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
