/* libFuzzer target: policy files, safetensors with the contract in its
 * metadata (policy/ps_safetensors.c, policy/ps_weights.c).
 *
 * The input goes to ps_st_parse from an exact-size heap copy (ASan sees a
 * read past the file) and to ps_weights_load through an in-memory file.
 * Contract: 0 or a documented negative code with a message; a parsed file's
 * tensors lie inside its data section and their element counts match their
 * shapes; every tensor ps_st_copy_f32 accepts is finite; a loaded policy's
 * observation and action sizes match its network, and one forward pass on
 * the normalisation's mean (a zero observation) runs. */
#include <errno.h>

#include "../../policy/ps_safetensors.h"
#include "../../policy/ps_weights.h"
#include "fuzz.h"

static void check_parsed(const ps_st_file_t *st)
{
    FUZZ_CHECK(st->n_tensors <= PS_ST_MAX_TENSORS && st->n_meta <= PS_ST_MAX_META,
               "%u tensors, %u metadata", st->n_tensors, st->n_meta);
    const size_t data_len = st->file_len - st->data_off;
    FUZZ_CHECK(st->data_off <= st->file_len, "data section at %zu of %zu", st->data_off,
               st->file_len);
    for (uint32_t i = 0; i < st->n_tensors; i++) {
        const ps_st_tensor_t *t = &st->tensors[i];
        FUZZ_CHECK(t->begin <= t->end && t->end <= data_len, "tensor %s at [%llu, %llu) of %zu",
                   t->name, (unsigned long long)t->begin, (unsigned long long)t->end, data_len);
        uint64_t n = 1;
        for (uint32_t d = 0; d < t->n_dims && d < PS_ST_MAX_DIMS; d++)
            n *= t->shape[d];
        FUZZ_CHECK(t->n_dims <= PS_ST_MAX_DIMS && n == t->n_elems &&
                       t->end - t->begin == 4u * t->n_elems,
                   "tensor %s: %llu elements in %llu bytes", t->name,
                   (unsigned long long)t->n_elems, (unsigned long long)(t->end - t->begin));
        FUZZ_CHECK(memchr(t->name, '\0', sizeof t->name) != NULL, "name not terminated");
        static float buf[1u << 16];
        char err[256];
        const int n_copied =
            ps_st_copy_f32(st, t, buf, sizeof buf / sizeof buf[0], err, sizeof err);
        FUZZ_CHECK(n_copied >= 0 || n_copied == -ENOSPC || n_copied == -ERANGE,
                   "ps_st_copy_f32 returned %d", n_copied);
        for (int k = 0; k < n_copied; k++)
            FUZZ_CHECK(isfinite(buf[k]), "tensor %s[%d] accepted but not finite", t->name, k);
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    char err[512];
    uint8_t *copy = malloc(size > 0 ? size : 1);
    if (copy == NULL)
        return 0;
    memcpy(copy, data, size);
    ps_st_file_t st;
    memset(&st, 0, sizeof st);
    int rc = ps_st_parse(&st, copy, size, err, sizeof err);
    free(copy);
    FUZZ_CHECK(rc == 0 || rc == -EINVAL || rc == -ENOTSUP || rc == -ENOMEM,
               "ps_st_parse returned %d", rc);
    FUZZ_CHECK(rc == 0 || err[0] != '\0', "refused without a message");
    if (rc == 0)
        check_parsed(&st);
    ps_st_free(&st);

    char path[64];
    const int fd = fuzz_memfd(data, size, path, sizeof path);
    if (fd < 0)
        return 0;
    static ps_weights_t w;
    memset(&w, 0, sizeof w);
    rc = ps_weights_load(&w, path, err, sizeof err);
    close(fd);
    FUZZ_CHECK(rc == 0 || rc == -EINVAL || rc == -ENOTSUP || rc == -ERANGE || rc == -ENOMEM ||
                   rc == -EIO,
               "ps_weights_load returned %d (%s)", rc, err);
    if (rc != 0) {
        FUZZ_CHECK(strncmp(err, path, strlen(path)) == 0, "a message not naming the file: %s", err);
    } else {
        const ps_weights_contract_t *c = &w.contract;
        FUZZ_CHECK(c->n_obs == w.mlp.n_in && c->n_act == w.mlp.n_out && c->n_extra == w.mlp.n_extra,
                   "contract %u obs %u act, network %u in %u out", c->n_obs, c->n_act, w.mlp.n_in,
                   w.mlp.n_out);
        FUZZ_CHECK(c->n_joints <= PS_MAX_JOINTS && c->n_act <= c->n_joints, "%u joints, %u actions",
                   c->n_joints, c->n_act);
        for (uint32_t k = 0; k < c->n_act; k++)
            FUZZ_CHECK(c->act_joint[k] < c->n_joints, "action %u on joint %u", k, c->act_joint[k]);
        static float in[PS_OBS_MAX + 64], extra[PS_OBS_MAX + 64], out[PS_MAX_JOINTS + 64];
        memset(in, 0, sizeof in);
        memset(extra, 0, sizeof extra);
        FUZZ_CHECK(w.mlp.n_in <= sizeof in / sizeof in[0] &&
                       w.mlp.n_extra <= sizeof extra / sizeof extra[0] &&
                       w.mlp.n_out <= sizeof out / sizeof out[0],
                   "network of %u in, %u extra, %u out", w.mlp.n_in, w.mlp.n_extra, w.mlp.n_out);
        FUZZ_CHECK(ps_mlp_forward(&w.mlp, in, w.mlp.n_extra > 0 ? extra : NULL, out) == 0,
                   "forward pass refused");
    }
    ps_weights_free(&w);
    return 0;
}
