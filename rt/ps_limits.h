/*
 * ps_limits: compile-time sizes shared by every layer (base). Fixed tables
 * everywhere are sized from these, so memory is known at start-up.
 *
 * Includes nothing of the project. Threads: any. Allocation: none.
 */
#ifndef PS_LIMITS_H
#define PS_LIMITS_H

#define PS_NAME_LEN    32u  /**< names of joints, buses, boards, robots, bodies */
#define PS_PATH_LEN    256u /**< file paths in configuration */
#define PS_MAX_JOINTS  32u  /**< actuated joints of one robot */
#define PS_MAX_BUSES   8u   /**< CAN buses of one board */
#define PS_MAX_PUSHES  64u  /**< pushes in one scenario */
#define PS_MAX_EVENTS  1024u /**< timed events in one scenario (a soak has hundreds) */
#define PS_ERR_MSG_LEN 512u /**< one-line error messages */

#endif /* PS_LIMITS_H */
