/*
 * ps_scene: the scene the plant loads when a scenario has a crowd. MuJoCo
 * 2.2.2 cannot add bodies to a loaded model, so at start-up this module
 * places the agents (from the scenario's groups and seed) and writes one MJCF
 * document that <include>s the robot's model file unchanged and adds the
 * agents, the arena's walls, the obstacles and the moving walls, with
 * contact and constraint capacity (<size nconmax njmax>) derived from the
 * agent count. The plant loads it through MuJoCo's virtual file system.
 *
 * Names in the scene (sim/ps_crowd.c binds them): bodies "agentI" (slide
 * joints "agentI_x", "agentI_y", hinges "agentI_tx", "agentI_ty", capsule
 * geom "agentI_body") and its jointless child "agentI_ring" (sphere geom
 * "agentI_ring" at the torso's centre of mass);
 * static bodies "wallK_S" (segment S of wall K, box geom of the same name)
 * and "obstacleK"; body "arena" with the arena's drawn sides "arena_wallK"
 * (no contact: sim/ps_crowd.c pushes agents out of them); mocap bodies
 * "crowd_wallE" for moving-wall event E.
 * Tags (the plant chooses who, ps_scene_choose_tagged): sites
 * "agentI_tag_left" and "agentI_tag_right" on body "agentI", box plates with
 * the material "tag36h11_<id>" (a texture of that name, which
 * sim/ps_camera_sim fills with the tag), ids 2k and 2k + 1 for agent k,
 * counted past the robot model's own tags (rt/ps_neighbours.h).
 * Collision bits (contype/conaffinity): capsule 8/2|16 (the robot and the
 * walls; the crowd zeroes them while nothing is near, sim/ps_crowd.h), ring
 * 4/4 (other rings), walls and obstacles 16/1|2. Solver: Newton, pyramidal
 * cone, sparse Jacobian, whatever the robot model says. The robot
 * model keeps its own (ps1: robot 2/1, floor 1/1), so agents never touch
 * the floor.
 *
 * Threads: any (INIT). Allocation: ps_scene_write_mjcf returns a malloc'd
 * string.
 */
#ifndef PS_SCENE_H
#define PS_SCENE_H

#include <stddef.h>
#include <stdint.h>

#include "ps_crowd.h"

/** tag36h11's ids (libapriltag 3.3: 587 codes): enough for 293 people. */
#define PS_SCENE_TAG_IDS 587u
/** Textures a model may have and still be drawn: MuJoCo 2.2.2's mjrContext
 *  keeps them in arrays of 100 (textureType[100], texture[100]) while
 *  mjr_makeContext checks against mjMAXTEXTURE, 1000, and writes past the
 *  arrays into the rest of the context beyond 100. So at most
 *  (100 - the robot model's textures) / 2 people wear tags. */
#define PS_SCENE_MAX_TEXTURES 100u
/** A tag texture's edge in texels: 8 per cell of the tag's 10 (black
 *  square 8, white border 1 each side), 19.2 KB of RGB per tag. */
#define PS_SCENE_TAG_TEX_PX 80

/** Place every group's agents: lattice, random or line layouts, sizes drawn
 *  from the group's distributions with a generator seeded by seed; none
 *  closer than the group's clear_m to robot_xy, none inside an obstacle, none
 *  overlapping another (random layout). Same cfg and seed, same agents.
 *  @post out[0..*out_n) written
 *  @return 0 | -PS_ERR_CONFIG (more agents than max, or a group whose region
 *          cannot hold its count; err names the group)  @rt INIT */
int ps_scene_place(const ps_crowd_cfg_t *cfg, uint32_t seed, const double robot_xy[2],
                   ps_crowd_agent_spec_t *out, uint32_t max, uint32_t *out_n, char *err,
                   size_t err_len);

/** nconmax and njmax for a scene of n agents over the robot model's own
 *  (2.2.2 allocates njmax^2 doubles: kept to what a packed crowd uses).
 *  @rt any */
void ps_scene_sizes(uint32_t n_agents, int robot_nconmax, int robot_njmax, int *out_nconmax,
                    int *out_njmax);

/** Who wears tags: of the agents whose ids fit tag36h11 (agent k wears
 *  first_id + 2k and first_id + 2k + 1, both below PS_SCENE_TAG_IDS), the
 *  max_people nearest robot_xy (a camera on the robot sees those; ties go
 *  to the lower index). O(n^2), n <= PS_CROWD_MAX_AGENTS.
 *  @pre first_id even  @post out_tag_id[0..n_agents): the left tag's id, or -1
 *  @return how many wear tags  @rt INIT */
uint32_t ps_scene_choose_tagged(const ps_crowd_agent_spec_t *agents, uint32_t n_agents,
                                const double robot_xy[2], uint32_t first_id, uint32_t max_people,
                                int32_t *out_tag_id);

/** The scene document: robot model (by absolute path) plus crowd. Agent k
 *  wears tags tag_id[k] (left) and tag_id[k] + 1 (right) where tag_id[k] >= 0
 *  (ps_scene_choose_tagged); tag_id NULL: nobody.
 *  @pre robot_model_path readable; robot_nconmax/njmax the robot model's
 *  @post *out_xml malloc'd, NUL-terminated; the caller frees it
 *  @return 0 | -ENOMEM | -EINVAL (NULL, a tag id odd or past tag36h11)  @rt INIT */
int ps_scene_write_mjcf(const ps_crowd_cfg_t *cfg, const ps_crowd_agent_spec_t *agents,
                        uint32_t n_agents, const char *robot_model_path, int robot_nconmax,
                        int robot_njmax, const int32_t *tag_id, char **out_xml, char *err,
                        size_t err_len);

#endif /* PS_SCENE_H */
