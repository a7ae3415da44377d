/*
 * ps_scenario: what a simulated run does over time (scenarios/<name>.yaml):
 * pushes on bodies of the plant, operator requests, e-stop presses, the
 * harness, injected faults. Plain data consumed by sim/ps_sim.c; the config
 * loader (rt/ps_config.c) fills it.
 *
 * Threads: any (data). Allocation: none.
 */
#ifndef PS_SCENARIO_H
#define PS_SCENARIO_H

#include <limits.h>
#include <stdint.h>

#include "../rt/ps_limits.h"

typedef struct {
    float t_s; /**< start, simulated seconds since start */
    float duration_s;
    char body[PS_NAME_LEN]; /**< body of the model the force acts on */
    float force_n[3];       /**< world frame */
    uint32_t body_line;     /**< line of `body` in the scenario file, 0: unknown */
} ps_push_cfg_t;

typedef enum {
    PS_EVENT_START = 0,   /**< operator asks STANDBY -> RAMP */
    PS_EVENT_STOP,        /**< operator asks for damping */
    PS_EVENT_ESTOP_PRESS, /**< e-stop input goes active */
    PS_EVENT_ESTOP_RELEASE,
    PS_EVENT_RESET,           /**< operator resets a latched e-stop */
    PS_EVENT_HARNESS_RELEASE, /**< sim harness lets go of the pelvis */
    PS_EVENT_DROP_REPLIES,    /**< `joint` stops replying for duration_s */
    PS_EVENT_DRIVE_FAULT,     /**< `joint`'s drive latches an over-voltage fault and goes
                                   limp: its replies carry it where their fault field can,
                                   and its own fault report (RobStride type 21) does */
    PS_EVENT_RECORD_BUTTON,   /**< a short press of the flight recorder's GPIO button */
    PS_EVENT_COUNT
} ps_event_kind_t;

typedef struct {
    float t_s;
    ps_event_kind_t kind;
    char joint[PS_NAME_LEN]; /**< for DROP_REPLIES and DRIVE_FAULT */
    float duration_s;
    uint32_t joint_line; /**< line of `joint` in the scenario file, 0: unknown */
} ps_event_cfg_t;

typedef struct {
    char name[PS_NAME_LEN];
    float duration_s; /**< default run length, 0: until Ctrl-C */
    uint32_t seed;    /**< noise seed; same seed, same lockstep run */
    uint32_t n_pushes;
    ps_push_cfg_t pushes[PS_MAX_PUSHES];
    uint32_t n_events;
    ps_event_cfg_t events[PS_MAX_EVENTS];
    char path[PATH_MAX]; /**< file it was loaded from, for messages; "": unknown */
} ps_scenario_cfg_t;

#endif /* PS_SCENARIO_H */
