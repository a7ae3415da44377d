/*
 * ps_args: see ps_args.h.
 */
#include "ps_args.h"

#include <errno.h>
#include <math.h>
#include <stdlib.h>

int ps_args_seconds(const char *text, double min_s, double max_s, bool is_min_open, double *out_s)
{
    if (text == NULL || out_s == NULL)
        return -EINVAL;
    char *end = NULL;
    errno = 0;
    const double v = strtod(text, &end);
    if (errno != 0 || end == text || *end != '\0' || !isfinite(v))
        return -EINVAL;
    if (v < min_s || (is_min_open && v == min_s) || v > max_s)
        return -EINVAL;
    *out_s = v;
    return 0;
}
