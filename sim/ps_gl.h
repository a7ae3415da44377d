/*
 * ps_gl: an OpenGL context for MuJoCo's renderer, either offscreen with no
 * display at all (EGL on Mesa's surfaceless platform, its software
 * rasteriser: libegl-mesa0, libgl1-mesa-dri) or in a window on a display
 * (GLFW, for the live viewer). MuJoCo renders offscreen in either (its own
 * framebuffer object); the window also shows frames.
 *
 * A context is current on the thread that opened it, or on the one that
 * called ps_gl_make_current last; one thread at a time. Window events are
 * polled by ps_gl_poll (on X11 from any one thread).
 *
 * Threads: any, one at a time per context; offscreen contexts may be opened
 * and closed from several threads (the renderer's, the simulated camera's):
 * they share EGL's one display, which stays initialised until exit.
 * Allocation: open (EGL, GLFW).
 */
#ifndef PS_GL_H
#define PS_GL_H

#include <stdbool.h>
#include <stddef.h>

typedef struct {
    void *egl_display; /**< EGLDisplay, offscreen; NULL when none */
    void *egl_context; /**< EGLContext */
    void *window;      /**< GLFWwindow, live viewer; NULL when none */
} ps_gl_t;

/** Offscreen context (EGL surfaceless), current on the calling thread.
 *  @post *g open on success, zeroed on failure
 *  @return 0 | -EIO (no EGL display, config or context; err says which and
 *          what to install)  @rt NON-RT */
int ps_gl_open_offscreen(ps_gl_t *g, char *err, size_t err_len);

/** A window of w x h on the display, its context current on the calling
 *  thread. Refuses without one (DISPLAY and WAYLAND_DISPLAY unset, or GLFW
 *  cannot reach it) rather than failing later.
 *  @return 0 | -ENXIO (no display; err says so) | -EIO  @rt NON-RT */
int ps_gl_open_window(ps_gl_t *g, int w, int h, const char *title, char *err, size_t err_len);

/** Make g's context current on the calling thread (after another thread
 *  released it).  @return 0 | -EIO  @rt NON-RT */
int ps_gl_make_current(ps_gl_t *g);

/** Release the context from the calling thread.  @rt NON-RT */
void ps_gl_release(ps_gl_t *g);

/** Window: show what was drawn to it, handle events.  @return false once
 *  the user closed it (or for no window)  @rt NON-RT */
bool ps_gl_show(ps_gl_t *g);

/** Window size in pixels (0 x 0 for none).  @rt NON-RT */
void ps_gl_window_size(const ps_gl_t *g, int *out_w, int *out_h);

/** Safe on a zeroed or closed g.  @rt NON-RT */
void ps_gl_close(ps_gl_t *g);

#endif /* PS_GL_H */
