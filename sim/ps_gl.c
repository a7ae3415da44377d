#include "ps_gl.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <EGL/egl.h>
#include <EGL/eglext.h>
#include <GLFW/glfw3.h>

#include "../rt/ps_err.h"

int ps_gl_open_offscreen(ps_gl_t *g, char *err, size_t err_len)
{
    memset(g, 0, sizeof(*g));
    /* Mesa's surfaceless platform needs no display and no GPU; ask for it
     * by name where the extension is there, else the default display (which
     * EGL_PLATFORM=surfaceless selects). */
    PFNEGLGETPLATFORMDISPLAYEXTPROC get_display =
        (PFNEGLGETPLATFORMDISPLAYEXTPROC)eglGetProcAddress("eglGetPlatformDisplayEXT");
    EGLDisplay dpy = get_display != NULL
                         ? get_display(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, NULL)
                         : eglGetDisplay(EGL_DEFAULT_DISPLAY);
    EGLint major = 0, minor = 0;
    if (dpy == EGL_NO_DISPLAY || eglInitialize(dpy, &major, &minor) != EGL_TRUE) {
        ps_err_format(err, err_len,
                      "offscreen rendering: no EGL display (error 0x%x); it needs Mesa's "
                      "libegl-mesa0 and libgl1-mesa-dri",
                      (unsigned)eglGetError());
        return -EIO;
    }
    const EGLint attrs[] = {EGL_RED_SIZE,     8,  EGL_GREEN_SIZE,      8,
                            EGL_BLUE_SIZE,    8,  EGL_DEPTH_SIZE,      24,
                            EGL_SURFACE_TYPE, EGL_PBUFFER_BIT, EGL_RENDERABLE_TYPE,
                            EGL_OPENGL_BIT,   EGL_NONE};
    EGLConfig conf;
    EGLint n_conf = 0;
    if (eglChooseConfig(dpy, attrs, &conf, 1, &n_conf) != EGL_TRUE || n_conf < 1 ||
        eglBindAPI(EGL_OPENGL_API) != EGL_TRUE) {
        ps_err_format(err, err_len, "offscreen rendering: no EGL OpenGL config (error 0x%x)",
                      (unsigned)eglGetError());
        /* (no eglTerminate: the display is shared, see ps_gl_close) */
        return -EIO;
    }
    EGLContext ctx = eglCreateContext(dpy, conf, EGL_NO_CONTEXT, NULL);
    if (ctx == EGL_NO_CONTEXT ||
        eglMakeCurrent(dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, ctx) != EGL_TRUE) {
        ps_err_format(err, err_len, "offscreen rendering: no EGL context (error 0x%x)",
                      (unsigned)eglGetError());
        if (ctx != EGL_NO_CONTEXT)
            (void)eglDestroyContext(dpy, ctx);
        /* (no eglTerminate: the display is shared, see ps_gl_close) */
        return -EIO;
    }
    g->egl_display = dpy;
    g->egl_context = ctx;
    return 0;
}

static char glfw_error[256];

static void on_glfw_error(int code, const char *what)
{
    (void)code;
    (void)snprintf(glfw_error, sizeof(glfw_error), "%s", what != NULL ? what : "?");
}

int ps_gl_open_window(ps_gl_t *g, int w, int h, const char *title, char *err, size_t err_len)
{
    memset(g, 0, sizeof(*g));
    const char *x11 = getenv("DISPLAY"), *wl = getenv("WAYLAND_DISPLAY");
    if ((x11 == NULL || x11[0] == '\0') && (wl == NULL || wl[0] == '\0')) {
        ps_err_format(err, err_len,
                      "the live viewer needs a display (DISPLAY and WAYLAND_DISPLAY are unset); "
                      "--render DIR renders without one");
        return -ENXIO;
    }
    glfw_error[0] = '\0';
    (void)glfwSetErrorCallback(on_glfw_error);
    if (glfwInit() != GLFW_TRUE) {
        ps_err_format(err, err_len, "the live viewer cannot reach the display: %s",
                      glfw_error[0] ? glfw_error : "glfwInit failed");
        return -ENXIO;
    }
    glfwWindowHint(GLFW_SAMPLES, 4);
    glfwWindowHint(GLFW_VISIBLE, GLFW_TRUE);
    GLFWwindow *win = glfwCreateWindow(w, h, title, NULL, NULL);
    if (win == NULL) {
        ps_err_format(err, err_len, "the live viewer: no window: %s",
                      glfw_error[0] ? glfw_error : "glfwCreateWindow failed");
        glfwTerminate();
        return -EIO;
    }
    glfwMakeContextCurrent(win);
    glfwSwapInterval(0);
    g->window = win;
    return 0;
}

int ps_gl_make_current(ps_gl_t *g)
{
    if (g->window != NULL) {
        glfwMakeContextCurrent(g->window);
        return 0;
    }
    if (g->egl_display != NULL &&
        eglMakeCurrent(g->egl_display, EGL_NO_SURFACE, EGL_NO_SURFACE, g->egl_context) ==
            EGL_TRUE)
        return 0;
    return -EIO;
}

void ps_gl_release(ps_gl_t *g)
{
    if (g->window != NULL)
        glfwMakeContextCurrent(NULL);
    else if (g->egl_display != NULL)
        (void)eglMakeCurrent(g->egl_display, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
}

bool ps_gl_show(ps_gl_t *g)
{
    if (g->window == NULL)
        return false;
    glfwSwapBuffers(g->window);
    glfwPollEvents();
    return glfwWindowShouldClose(g->window) == 0;
}

void ps_gl_window_size(const ps_gl_t *g, int *out_w, int *out_h)
{
    *out_w = *out_h = 0;
    if (g->window != NULL)
        glfwGetFramebufferSize(g->window, out_w, out_h);
}

void ps_gl_close(ps_gl_t *g)
{
    if (g->window != NULL) {
        glfwDestroyWindow(g->window);
        glfwTerminate();
    }
    if (g->egl_display != NULL) {
        (void)eglMakeCurrent(g->egl_display, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
        if (g->egl_context != NULL)
            (void)eglDestroyContext(g->egl_display, g->egl_context);
        /* No eglTerminate: Mesa's surfaceless display is one per process
         * (every eglGetPlatformDisplayEXT returns it; eglInitialize again
         * does nothing) and one eglTerminate would end it for every context
         * on it, the renderer's and the simulated camera's alike, each on
         * its own thread. It lives until the process ends. */
    }
    memset(g, 0, sizeof(*g));
}
