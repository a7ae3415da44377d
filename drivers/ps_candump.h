/*
 * ps_candump: one CAN frame as a line of can-utils' log format (`candump -L`,
 * read by canplayer, log2long, log2asc), and back.
 *
 *   (SSSSSSSSSS.UUUUUU) IFNAME ID#DATA          classical frame
 *   (SSSSSSSSSS.UUUUUU) IFNAME ID##FDATA        CAN FD frame, F = flags nibble
 *
 * ID is 3 hex digits for an 11-bit id and 8 for a 29-bit one; DATA is two
 * upper-case hex digits a byte (a '.' between bytes is accepted when read);
 * F has bit 0 for bit rate switch (BRS) and bit 1 for ESI (read, not kept).
 * The time is seconds and microseconds of whatever clock the writer used; the
 * runtime writes CLOCK_MONOTONIC (or simulated) time, candump the wall clock.
 *
 * Refused when read, with the column and what is wrong: remote frames
 * ("ID#R"), error frames (the CAN_ERR_FLAG bit 0x20000000 in an 8-digit id),
 * an 11-bit id above 0x7ff, an id of other than 3 or 8 digits, a payload
 * length a frame cannot carry, a timestamp without six microsecond digits,
 * an interface name longer than 15 bytes, and trailing text. Only data frames
 * reach the loop (drivers/ps_can.h), so only they are replayed.
 *
 * Threads: any (pure). Allocation: none.
 */
#ifndef PS_CANDUMP_H
#define PS_CANDUMP_H

#include <stdbool.h>
#include <stddef.h>

#include "ps_can.h"

#define PS_CANDUMP_IFNAME_MAX 16u /**< IFNAMSIZ: 15 bytes and the NUL */

/** Room for the longest line ps_candump_format writes, newline and NUL
 *  included: "(" 10-digit seconds (an int64_t of ns has at most 10) "." 6
 *  ") " ifname " " 8-digit id "##" F 128 data digits "\n". */
#define PS_CANDUMP_LINE_MAX (1u + 10u + 1u + 6u + 2u + 15u + 1u + 8u + 2u + 1u + 128u + 2u)

/** @return true if ifname can stand in a line: 1..15 bytes, no blank, no '('
 *  @rt RT-SAFE, any thread */
bool ps_candump_is_valid_ifname(const char *ifname);

/** Write f as one log line (ending in '\n') into buf; the time is f->t_ns
 *  truncated to microseconds.
 *  @pre f, ifname, buf non-NULL
 *  @return characters written without the NUL | -EINVAL (negative time, an
 *  ifname of 0 or more than 15 bytes or with a space, an 11-bit id above
 *  0x7ff, a 29-bit id above 0x1fffffff, a length the frame kind cannot carry)
 *  | -ENOSPC (buf shorter than the line)
 *  @rt RT-SAFE (no allocation, no locale), any thread */
int ps_candump_format(const ps_can_frame_t *f, const char *ifname, char *buf, size_t len);

/** Read one log line (a trailing '\n' or "\r\n" is allowed) into *out and
 *  the interface name into ifname.
 *  @pre line, out, ifname non-NULL, ifname_len >= PS_CANDUMP_IFNAME_MAX
 *  @return 0 | -PS_ERR_PROTOCOL with "column N: what" in err (1-based)
 *  @rt INIT / NON-RT (formats its error with vsnprintf), any thread */
int ps_candump_parse(const char *line, ps_can_frame_t *out, char *ifname, size_t ifname_len,
                     char *err, size_t err_len);

#endif /* PS_CANDUMP_H */
