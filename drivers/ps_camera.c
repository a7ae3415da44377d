#include "ps_camera.h"

#include <errno.h>
#include <string.h>

static const char *const FORMAT_NAMES[PS_PIX_COUNT] = {
    [PS_PIX_R8] = "R8",         [PS_PIX_YUV420] = "YUV420", [PS_PIX_NV12] = "NV12",
    [PS_PIX_RGB888] = "RGB888", [PS_PIX_BGR888] = "BGR888", [PS_PIX_XRGB8888] = "XRGB8888",
};
static const uint32_t FORMAT_BPP[PS_PIX_COUNT] = {
    [PS_PIX_R8] = 1,     [PS_PIX_YUV420] = 1, [PS_PIX_NV12] = 1,
    [PS_PIX_RGB888] = 3, [PS_PIX_BGR888] = 3, [PS_PIX_XRGB8888] = 4,
};
static const char *const SOURCE_NAMES[PS_CAMERA_SRC_COUNT] = {
    [PS_CAMERA_SRC_LIBCAMERA] = "libcamera",
    [PS_CAMERA_SRC_FILES] = "files",
    [PS_CAMERA_SRC_SIM] = "sim",
};

const char *ps_camera_format_name(ps_camera_format_t f)
{
    return (unsigned)f < PS_PIX_COUNT ? FORMAT_NAMES[f] : "?";
}

int ps_camera_format_from_name(const char *name)
{
    for (int f = 0; name != NULL && f < PS_PIX_COUNT; f++)
        if (strcmp(name, FORMAT_NAMES[f]) == 0)
            return f;
    return -ENOENT;
}

uint32_t ps_camera_format_bpp(ps_camera_format_t f)
{
    return (unsigned)f < PS_PIX_COUNT ? FORMAT_BPP[f] : 0u;
}

const char *ps_camera_source_name(ps_camera_source_t s)
{
    return (unsigned)s < PS_CAMERA_SRC_COUNT ? SOURCE_NAMES[s] : "?";
}

/* BT.601 luma in 8.8 fixed point: 0.299 R + 0.587 G + 0.114 B. */
static inline uint8_t luma(unsigned r, unsigned g, unsigned b)
{
    return (uint8_t)((77u * r + 150u * g + 29u * b + 128u) >> 8);
}

int ps_camera_to_grey(const ps_camera_frame_t *f, uint8_t *out, size_t out_len)
{
    if (f == NULL || out == NULL || (unsigned)f->format >= PS_PIX_COUNT || f->data == NULL)
        return -EINVAL;
    const size_t w = f->width, h = f->height, bpp = FORMAT_BPP[f->format];
    if (w == 0 || h == 0 || out_len < w * h || f->stride < w * bpp ||
        f->n_bytes < (h - 1u) * (size_t)f->stride + w * bpp)
        return -EINVAL;
    for (size_t y = 0; y < h; y++) {
        const uint8_t *row = f->data + y * f->stride;
        uint8_t *o = out + y * w;
        switch (f->format) {
        case PS_PIX_R8:
        case PS_PIX_YUV420:
        case PS_PIX_NV12:
            memcpy(o, row, w);
            break;
        case PS_PIX_RGB888: /* B G R */
            for (size_t x = 0; x < w; x++)
                o[x] = luma(row[3 * x + 2], row[3 * x + 1], row[3 * x]);
            break;
        case PS_PIX_BGR888: /* R G B */
            for (size_t x = 0; x < w; x++)
                o[x] = luma(row[3 * x], row[3 * x + 1], row[3 * x + 2]);
            break;
        case PS_PIX_XRGB8888: /* B G R X */
            for (size_t x = 0; x < w; x++)
                o[x] = luma(row[4 * x + 2], row[4 * x + 1], row[4 * x]);
            break;
        case PS_PIX_COUNT:
            return -EINVAL;
        }
    }
    return 0;
}
