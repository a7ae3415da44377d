#include "ps_err.h"

#include <stdarg.h>
#include <stdio.h>
#include <string.h>

static const char *const PROJECT_MESSAGES[PS_ERR_END - PS_ERR_BASE] = {
    [PS_ERR_CONFIG - PS_ERR_BASE] = "invalid configuration",
    [PS_ERR_BUS_BUDGET - PS_ERR_BASE] = "CAN bus load over budget",
    [PS_ERR_PROTOCOL - PS_ERR_BASE] = "malformed or unexpected frame",
    [PS_ERR_STALE - PS_ERR_BASE] = "stale device data",
    [PS_ERR_LIMIT - PS_ERR_BASE] = "value outside configured limits",
    [PS_ERR_ILLEGAL_STATE - PS_ERR_BASE] = "request not allowed in this state",
    [PS_ERR_DEADLINE - PS_ERR_BASE] = "real-time deadline missed",
    [PS_ERR_RT_UNAVAILABLE - PS_ERR_BASE] = "real-time setup not permitted",
    [PS_ERR_PLANT - PS_ERR_BASE] = "simulated plant failure",
};

const char *ps_strerror(int code)
{
    if (code < 0)
        code = -code;
    if (code >= PS_ERR_BASE && code < PS_ERR_END)
        return PROJECT_MESSAGES[code - PS_ERR_BASE];
    /* strerror() is not guaranteed thread-safe, but glibc returns static
     * strings for known codes; the RT loop never calls this. */
    return strerror(code);
}

void ps_err_format(char *err, size_t err_len, const char *fmt, ...)
{
    if (err == NULL || err_len == 0)
        return;
    va_list ap;
    va_start(ap, fmt);
    (void)vsnprintf(err, err_len, fmt, ap); /* truncation is acceptable for a message */
    va_end(ap);
}
