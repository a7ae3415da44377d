/*
 * The loader of ps_camera_libcamera's C++ module (see ps_camera_libcamera.h:
 * why it is loaded on first use, and where it is looked for). The module is
 * loaded once and stays loaded for the process's life.
 */
#include "ps_camera_libcamera.h"

#include <dlfcn.h>
#include <errno.h>
#include <libgen.h>
#include <limits.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../rt/ps_err.h"

#define MODULE_NAME "libpushstep-libcamera.so"

static struct {
    pthread_once_t once;
    int rc;
    char why[PS_ERR_MSG_LEN];
    int (*create)(const ps_camera_cfg_t *, ps_camera_libcamera_t **);
    ps_camera_port_t (*port)(ps_camera_libcamera_t *);
    unsigned long (*n_bad)(const ps_camera_libcamera_t *);
    void (*destroy)(ps_camera_libcamera_t *);
} g_mod = {.once = PTHREAD_ONCE_INIT};

/* dlsym hands back an object pointer; POSIX says it converts to a function
 * pointer, C does not: go through memcpy. */
static int find(void *h, const char *name, void *out_fn, size_t fn_size)
{
    void *p = dlsym(h, name);
    if (p == NULL)
        return -ENOENT;
    memcpy(out_fn, &p, fn_size);
    return 0;
}

static void load(void)
{
    char exe[PATH_MAX], dir[PATH_MAX];
    const ssize_t n = readlink("/proc/self/exe", exe, sizeof(exe) - 1);
    exe[n > 0 ? n : 0] = '\0';
    snprintf(dir, sizeof(dir), "%s", n > 0 ? dirname(exe) : ".");
    const char *env = getenv("PUSHSTEP_LIBCAMERA_SO");
    char paths[5][PATH_MAX + 64];
    int n_paths = 0;
    if (env != NULL && env[0] != '\0') { /* set: the only place */
        snprintf(paths[n_paths++], sizeof(paths[0]), "%s", env);
    } else {
        snprintf(paths[n_paths++], sizeof(paths[0]), "%s/" MODULE_NAME, dir);
        snprintf(paths[n_paths++], sizeof(paths[0]), "%s/../" MODULE_NAME, dir);
        snprintf(paths[n_paths++], sizeof(paths[0]), "%s/../../" MODULE_NAME, dir);
        snprintf(paths[n_paths++], sizeof(paths[0]), "%s/../lib/pushstep/" MODULE_NAME, dir);
    }
    void *h = NULL;
    const char *dl_err = "not found";
    for (int i = 0; i < n_paths && h == NULL; i++) {
        if (access(paths[i], R_OK) != 0)
            continue;
        h = dlopen(paths[i], RTLD_NOW | RTLD_LOCAL);
        if (h == NULL)
            dl_err = dlerror();
    }
    if (h == NULL) {
        if (env != NULL && env[0] != '\0')
            ps_err_format(g_mod.why, sizeof(g_mod.why),
                          "camera: libcamera's module %s (PUSHSTEP_LIBCAMERA_SO): %s", env,
                          dl_err);
        else
            ps_err_format(g_mod.why, sizeof(g_mod.why),
                          "camera: libcamera's module %s: %s (looked in %s, its parent folders "
                          "and %s/../lib/pushstep; `make` builds it)",
                          MODULE_NAME, dl_err, dir, dir);
        g_mod.rc = -ENOENT;
        return;
    }
    if (find(h, "ps_camera_libcamera_impl_create", &g_mod.create, sizeof(g_mod.create)) < 0 ||
        find(h, "ps_camera_libcamera_impl_port", &g_mod.port, sizeof(g_mod.port)) < 0 ||
        find(h, "ps_camera_libcamera_impl_n_bad_frames", &g_mod.n_bad, sizeof(g_mod.n_bad)) < 0 ||
        find(h, "ps_camera_libcamera_impl_destroy", &g_mod.destroy, sizeof(g_mod.destroy)) < 0) {
        ps_err_format(g_mod.why, sizeof(g_mod.why), "camera: %s lacks its entry points",
                      MODULE_NAME);
        g_mod.rc = -ENOENT;
    }
}

int ps_camera_libcamera_create(const ps_camera_cfg_t *cfg, ps_camera_libcamera_t **out, char *err,
                               size_t err_len)
{
    if (cfg == NULL || out == NULL)
        return -EINVAL;
    (void)pthread_once(&g_mod.once, load); /* cannot fail with a valid once */
    if (g_mod.rc < 0) {
        ps_err_format(err, err_len, "%s", g_mod.why);
        return g_mod.rc;
    }
    const int rc = g_mod.create(cfg, out);
    if (rc < 0)
        ps_err_format(err, err_len, "camera: %s", ps_strerror(rc));
    return rc;
}

ps_camera_port_t ps_camera_libcamera_port(ps_camera_libcamera_t *c)
{
    return g_mod.port(c);
}

unsigned long ps_camera_libcamera_n_bad_frames(const ps_camera_libcamera_t *c)
{
    return g_mod.n_bad(c);
}

void ps_camera_libcamera_destroy(ps_camera_libcamera_t *c)
{
    if (c != NULL && g_mod.destroy != NULL)
        g_mod.destroy(c);
}
