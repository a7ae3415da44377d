/*
 * ps_config_sim: the configuration that fills sim/'s structs: the scenario
 * file (scenarios/<name>.yaml) and the robot file's `sim:` section, plus the
 * check of a scenario against a robot.
 *
 * Layering: includes sim/ headers, so only the composition root (rt/main.c,
 * rt/ps_app.c/h) and tests include it; application modules include
 * rt/ps_config.h, which includes nothing of sim/.
 *
 * Threads: INIT only (main thread). Allocation: as rt/ps_config.h.
 */
#ifndef PS_CONFIG_SIM_H
#define PS_CONFIG_SIM_H

#include <stddef.h>

#include "../sim/ps_devices.h"
#include "../sim/ps_scenario.h"
#include "ps_config.h"

/** ps_config_load_robot, and the `sim:` section of the same file from the
 *  same single load. @pre path, out, out_sim != NULL
 *  @post *out and *out_sim fully written on success, both untouched on failure
 *  @return 0 | -PS_ERR_CONFIG | -ENOENT | -EINVAL | -ENOMEM  @rt INIT */
int ps_config_load_robot_sim(const char *path, ps_robot_cfg_t *out, ps_sim_devices_cfg_t *out_sim,
                             char *err, size_t err_len);

/** Load and check a scenario file. out->path and each event's joint_line and
 *  push's body_line record where they are, for the checks against the robot
 *  (ps_config_check_scenario) and the model (the sim, at create).
 *  @pre path != NULL  @post as ps_config_load_board
 *  @return 0 | -PS_ERR_CONFIG | -ENOENT | -EINVAL | -ENOMEM  @rt INIT */
int ps_config_load_scenario(const char *path, ps_scenario_cfg_t *out, char *err, size_t err_len);

/** Every drop_replies joint of the scenario is a joint of the robot. A message
 *  names the scenario file and the line of the field, e.g.
 *    scenarios/x.yaml:7: events[2].joint: no joint "r_ankle" in robot tiny
 *  or "scenario NAME: ..." when s->path is empty. (Push bodies name bodies of
 *  the model: ps_sim_create checks them, with the same file and line.)
 *  @pre r, s loaded  @post err holds a message on failure
 *  @return 0 | -PS_ERR_CONFIG | -EINVAL (r or s NULL)  @rt INIT */
int ps_config_check_scenario(const ps_robot_cfg_t *r, const ps_scenario_cfg_t *s, char *err,
                             size_t err_len);

/** Name of an event kind as written in scenario files, for logs; "unknown"
 *  outside the enum. @rt RT-SAFE */
const char *ps_config_event_name(ps_event_kind_t k);

#endif /* PS_CONFIG_SIM_H */
