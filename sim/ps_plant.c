#include "ps_plant.h"

#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include <mujoco/mujoco.h>

#include "../rt/ps_err.h"
#include "../rt/ps_limits.h"
#include "ps_scene.h"

/* Harness gains: a gantry holding the limp 38 kg robot. 343 N of weight on
 * 20 kN/m sags 1.7 cm at worst; the damping is near critical for the whole
 * body on the translational spring (2*sqrt(k*m) = 1.7 kN s/m). */
#define PS_PLANT_MAX_NV 4096u /* kinetic energy's scratch */
#define HARNESS_K_N_M      20000.0
#define HARNESS_C_N_S_M    1500.0
#define HARNESS_K_NM_RAD   1500.0
#define HARNESS_C_NM_S_RAD 100.0

#define IMU_SITE_NAME    "imu"
#define IMU_GYRO_NAME    "imu_gyro"
#define IMU_ACCEL_NAME   "imu_accel"
#define HEAD_BODY_NAME   "head"
#define FOOT_NAME_SUFFIX "foot"
#define SCENE_VFS_NAME   "pushstep-scene.xml"

struct ps_plant {
    mjModel *m;
    mjData *d;
    int n_joints;
    int qpos_adr[PS_MAX_JOINTS];
    int dof_adr[PS_MAX_JOINTS];
    int act_id[PS_MAX_JOINTS];
    int root_body;     /**< body carrying the free joint (pelvis) */
    int root_qpos_adr; /**< free joint: 3 position + 4 quaternion */
    int root_dof_adr;  /**< free joint: 3 linear (world) + 3 angular (local) */
    int head_body;
    int gyro_adr, accel_adr; /**< sensordata addresses */
    bool is_harness_engaged;
    double anchor_pos_m[3];
    double anchor_quat[4];
    double *ext_force_n;     /**< nbody x 3, caller's pushes (world) */
    unsigned char *is_foot;  /**< nbody, 1 for robot bodies named *foot */
    unsigned char *is_robot; /**< nbody, 1 for the root body and its descendants */
    int n_bad_warnings;      /**< MuJoCo's bad-qpos/qvel/qacc count at last check */
    int n_full_warnings;     /**< MuJoCo's contact/constraint-full count at last check */
    const char *err_reason;  /**< why the last failing step failed (static), NULL: none */
    ps_crowd_t *crowd;       /**< NULL: no crowd */
    int64_t crowd_ns;        /**< time in the crowd's work, all steps */
    int64_t mujoco_ns;       /**< time in mj_step, all steps */
    double *mass0, *inertia0, *ipos0, *friction0; /**< as loaded (nbody, 3 nbody, 3 ngeom) */
};

static int64_t mono_ns(void)
{
    struct timespec ts;
    (void)clock_gettime(CLOCK_MONOTONIC, &ts); /* cannot fail for this clock */
    return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}

/* MuJoCo's parser messages span lines; logs want one line. */
static void one_line(char *s)
{
    size_t n = strlen(s);
    while (n > 0 && (s[n - 1] == '\n' || s[n - 1] == ' '))
        s[--n] = '\0';
    for (size_t i = 0; i < n; i++)
        if (s[i] == '\n')
            s[i] = ' ';
}

/* MuJoCo's default warning handler prints to stdout and appends to
 * MUJOCO_LOG.TXT in the working directory; the library prints nothing and
 * detects instability through mjData.warning counters instead. */
static void quiet_warning(const char *msg)
{
    (void)msg;
}

static int bad_warning_count(const mjData *d)
{
    return d->warning[mjWARN_BADQPOS].number + d->warning[mjWARN_BADQVEL].number +
           d->warning[mjWARN_BADQACC].number;
}

/* Contacts beyond nconmax and constraints beyond njmax are dropped by MuJoCo
 * with only a warning: the physics is then wrong (a body sinks through the
 * floor), so the plant reports them as errors. */
static int full_warning_count(const mjData *d)
{
    return d->warning[mjWARN_CONTACTFULL].number + d->warning[mjWARN_CNSTRFULL].number;
}

/* Which warning is new since the contact-full and constraint-full counts
 * were taken (else a bad-number warning). */
static const char *warning_reason(const mjData *d, int contact_full, int cnstr_full)
{
    if (d->warning[mjWARN_CONTACTFULL].number != contact_full)
        return "contacts beyond the model's nconmax were dropped (mjWARN_CONTACTFULL)";
    if (d->warning[mjWARN_CNSTRFULL].number != cnstr_full)
        return "constraints beyond the model's njmax were dropped (mjWARN_CNSTRFULL)";
    return "bad qpos/qvel/qacc: MuJoCo reset the state (mjWARN_BADQPOS/QVEL/QACC)";
}

static bool ends_with(const char *s, const char *suffix)
{
    const size_t n = strlen(s);
    const size_t k = strlen(suffix);
    return n >= k && strcmp(s + n - k, suffix) == 0;
}

/* Lowest world z over the corners (boxes) or lowest points (spheres,
 * capsules) of every geom of a foot body. Needs mj_kinematics. */
static double foot_min_z(const ps_plant_t *p)
{
    const mjModel *m = p->m;
    const mjData *d = p->d;
    double min_z = INFINITY;
    for (int g = 0; g < m->ngeom; g++) {
        if (!p->is_foot[m->geom_bodyid[g]])
            continue;
        const mjtNum *pos = d->geom_xpos + 3 * g;
        const mjtNum *R = d->geom_xmat + 9 * g; /* row-major, local -> world */
        const mjtNum *s = m->geom_size + 3 * g;
        double z;
        if (m->geom_type[g] == mjGEOM_BOX) {
            /* lowest corner: each half-extent along the sign that lowers z */
            z = pos[2] - fabs(R[6]) * s[0] - fabs(R[7]) * s[1] - fabs(R[8]) * s[2];
        } else if (m->geom_type[g] == mjGEOM_SPHERE) {
            z = pos[2] - s[0];
        } else if (m->geom_type[g] == mjGEOM_CAPSULE) {
            z = pos[2] - fabs(R[8]) * s[1] - s[0];
        } else {
            z = pos[2];
        }
        if (z < min_z)
            min_z = z;
    }
    return min_z;
}

/* Put "FILE:LINE: FIELD: " (the robot file's place of what err is about)
 * before err, and the model's path after it when err does not name it. */
static void prefix_robot_source(const ps_plant_cfg_t *robot, uint32_t line, const char *field,
                                char *err, size_t err_len)
{
    if (robot->src_path == NULL || robot->src_path[0] == '\0' || line == 0 || err == NULL ||
        err_len == 0)
        return;
    char msg[PS_ERR_MSG_LEN];
    const bool names_model = strstr(err, robot->model_path) != NULL;
    ps_err_format(msg, sizeof(msg), "%s:%u: %s: %s%s%s%s", robot->src_path, line, field, err,
                  names_model ? "" : " (model ", names_model ? "" : robot->model_path,
                  names_model ? "" : ")");
    ps_err_format(err, err_len, "%s", msg);
}

/* One joint of the robot file: a hinge of the model and the motor driving it. */
static int map_joint(ps_plant_t *p, const ps_plant_cfg_t *robot, int i, char *err, size_t err_len)
{
    const mjModel *m = p->m;
    const char *name = robot->joint_name[i];
    const int j = mj_name2id(m, mjOBJ_JOINT, name);
    if (j < 0) {
        ps_err_format(err, err_len, "joint '%s' not found in the model", name);
        return -PS_ERR_CONFIG;
    }
    if (m->jnt_type[j] != mjJNT_HINGE) {
        ps_err_format(err, err_len, "joint '%s' is not a hinge", name);
        return -PS_ERR_CONFIG;
    }
    const int a = mj_name2id(m, mjOBJ_ACTUATOR, name);
    if (a < 0) {
        ps_err_format(err, err_len, "actuator '%s' not found in the model", name);
        return -PS_ERR_CONFIG;
    }
    if (m->actuator_trntype[a] != mjTRN_JOINT || m->actuator_trnid[2 * a] != j) {
        ps_err_format(err, err_len, "actuator '%s' does not drive joint '%s'", name, name);
        return -PS_ERR_CONFIG;
    }
    p->qpos_adr[i] = m->jnt_qposadr[j];
    p->dof_adr[i] = m->jnt_dofadr[j];
    p->act_id[i] = a;
    return 0;
}

static int map_joints(ps_plant_t *p, const ps_plant_cfg_t *robot, char *err, size_t err_len)
{
    if (robot->n_joints > PS_MAX_JOINTS) {
        ps_err_format(err, err_len, "robot has %u joints, at most %u", robot->n_joints,
                      PS_MAX_JOINTS);
        return -PS_ERR_CONFIG;
    }
    p->n_joints = (int)robot->n_joints;
    for (int i = 0; i < p->n_joints; i++) {
        const int rc = map_joint(p, robot, i, err, err_len);
        if (rc < 0) {
            char field[32];
            (void)snprintf(field, sizeof(field), "joints[%d].name", i);
            prefix_robot_source(robot, robot->joint_name_line ? robot->joint_name_line[i] : 0,
                                field, err, err_len);
            return rc;
        }
    }
    return 0;
}

/* The robot's floating base is the free joint of body PS_PLANT_ROOT_BODY_NAME,
 * wherever it sits in the model: other free bodies (crowd, props) may come
 * before it. */
static int find_root(ps_plant_t *p, char *err, size_t err_len)
{
    const mjModel *m = p->m;
    const int b = mj_name2id(m, mjOBJ_BODY, PS_PLANT_ROOT_BODY_NAME);
    if (b < 0) {
        ps_err_format(err, err_len, "body '%s' (the robot's root) not found in the model",
                      PS_PLANT_ROOT_BODY_NAME);
        return -PS_ERR_CONFIG;
    }
    for (int k = 0; k < m->body_jntnum[b]; k++) {
        const int j = m->body_jntadr[b] + k;
        if (m->jnt_type[j] == mjJNT_FREE) {
            p->root_body = b;
            p->root_qpos_adr = m->jnt_qposadr[j];
            p->root_dof_adr = m->jnt_dofadr[j];
            return 0;
        }
    }
    ps_err_format(err, err_len, "body '%s' has no free joint (floating base)",
                  PS_PLANT_ROOT_BODY_NAME);
    return -PS_ERR_CONFIG;
}

/* Bodies of the robot: the root and its descendants (parents come first in
 * MuJoCo's body order, so one pass marks the whole subtree). */
static void mark_robot_bodies(ps_plant_t *p)
{
    const mjModel *m = p->m;
    for (int b = 0; b < m->nbody; b++)
        p->is_robot[b] =
            (b == p->root_body || (b > 0 && p->is_robot[m->body_parentid[b]])) ? 1u : 0u;
}

static int map_bodies(ps_plant_t *p, char *err, size_t err_len)
{
    const mjModel *m = p->m;
    p->root_body = -1;
    const int rc = find_root(p, err, err_len);
    if (rc < 0)
        return rc;
    mark_robot_bodies(p);
    p->head_body = mj_name2id(m, mjOBJ_BODY, HEAD_BODY_NAME);
    if (p->head_body < 0) {
        ps_err_format(err, err_len, "body '%s' not found in the model", HEAD_BODY_NAME);
        return -PS_ERR_CONFIG;
    }
    int n_feet = 0;
    for (int b = 0; b < m->nbody; b++) {
        const char *name = mj_id2name(m, mjOBJ_BODY, b);
        p->is_foot[b] =
            (p->is_robot[b] && name != NULL && ends_with(name, FOOT_NAME_SUFFIX)) ? 1u : 0u;
        n_feet += p->is_foot[b];
    }
    if (n_feet == 0) {
        ps_err_format(err, err_len, "no body named '*%s' in the model", FOOT_NAME_SUFFIX);
        return -PS_ERR_CONFIG;
    }
    const int gyro = mj_name2id(m, mjOBJ_SENSOR, IMU_GYRO_NAME);
    const int accel = mj_name2id(m, mjOBJ_SENSOR, IMU_ACCEL_NAME);
    if (gyro < 0 || m->sensor_type[gyro] != mjSENS_GYRO || accel < 0 ||
        m->sensor_type[accel] != mjSENS_ACCELEROMETER ||
        mj_name2id(m, mjOBJ_SITE, IMU_SITE_NAME) < 0) {
        ps_err_format(err, err_len, "model needs site '%s' with gyro '%s' and accelerometer '%s'",
                      IMU_SITE_NAME, IMU_GYRO_NAME, IMU_ACCEL_NAME);
        return -PS_ERR_CONFIG;
    }
    p->gyro_adr = m->sensor_adr[gyro];
    p->accel_adr = m->sensor_adr[accel];
    return 0;
}

/* Joints to the stance, root upright at the origin, soles on the floor. */
static void place_in_stance(ps_plant_t *p, const ps_plant_cfg_t *robot)
{
    mjModel *m = p->m;
    mjData *d = p->d;
    mj_resetData(m, d);
    for (int i = 0; i < p->n_joints; i++)
        d->qpos[p->qpos_adr[i]] = robot->stance_rad[i];
    mjtNum *root = d->qpos + p->root_qpos_adr;
    root[0] = robot->spawn_xy_m[0];
    root[1] = robot->spawn_xy_m[1];
    root[3] = cos(robot->spawn_yaw_rad / 2.0);
    root[4] = root[5] = 0.0;
    root[6] = sin(robot->spawn_yaw_rad / 2.0);
    mj_kinematics(m, d);
    root[2] -= foot_min_z(p);
    mj_forward(m, d); /* consistent positions, contacts and sensors at t = 0 */
    for (int k = 0; k < 3; k++)
        p->anchor_pos_m[k] = root[k];
    for (int k = 0; k < 4; k++)
        p->anchor_quat[k] = root[3 + k];
}

/* The first tag id free for the crowd: past every "tag36h11_<id>" texture
 * the robot model has itself (a test scene's tagged people), even. */
static uint32_t first_free_tag_id(const mjModel *m)
{
    uint32_t first = 0;
    for (int t = 0; t < m->ntex; t++) {
        unsigned id = 0;
        char rest = 0;
        if (sscanf(m->names + m->name_texadr[t], "tag36h11_%u%c", &id, &rest) == 1 &&
            id + 1u > first)
            first = id + 1u;
    }
    return (first + 1u) & ~1u;
}

/* The robot model (p->m, loaded) plus the crowd: place the agents, write the
 * scene that includes the model file, load it from memory in place of the
 * robot model. */
static int load_scene(ps_plant_t *p, const ps_plant_cfg_t *robot, ps_crowd_agent_spec_t *agents,
                      uint32_t *out_n, char *err, size_t err_len)
{
    int rc = ps_scene_place(robot->crowd, robot->seed, robot->spawn_xy_m, agents,
                            PS_CROWD_MAX_AGENTS, out_n, err, err_len);
    if (rc < 0)
        return rc;
    char abs_path[PATH_MAX];
    if (realpath(robot->model_path, abs_path) == NULL) {
        ps_err_format(err, err_len, "%s: %s", robot->model_path, strerror(errno));
        return -PS_ERR_PLANT;
    }
    /* The scene lives (in the VFS) beside the robot's model file and includes
     * it by its own name: MuJoCo resolves every include, the model's own
     * nested ones too, from the main file's directory, as when the model is
     * loaded alone. */
    char scene_name[PATH_MAX + sizeof(SCENE_VFS_NAME)];
    char *slash = strrchr(abs_path, '/');
    *slash = '\0';
    (void)snprintf(scene_name, sizeof(scene_name), "%s/%s", abs_path, SCENE_VFS_NAME);
    const char *model_file = slash + 1;
    /* Tags (crowd.tags on): on the people nearest the robot, as many as the
     * renderer's texture slots leave room for (ps_scene.h). */
    int32_t *tag_id = NULL;
    if (robot->crowd->tags == PS_CROWD_TAGS_ON && *out_n > 0) {
        tag_id = calloc(*out_n, sizeof(*tag_id));
        if (tag_id == NULL)
            return -ENOMEM;
        const uint32_t n_tex = (uint32_t)p->m->ntex;
        const uint32_t max_people =
            n_tex < PS_SCENE_MAX_TEXTURES ? (PS_SCENE_MAX_TEXTURES - n_tex) / 2u : 0u;
        (void)ps_scene_choose_tagged(agents, *out_n, robot->spawn_xy_m, first_free_tag_id(p->m),
                                     max_people, tag_id); /* how many: the scene says */
    }
    char *xml = NULL;
    rc = ps_scene_write_mjcf(robot->crowd, agents, *out_n, model_file, p->m->nconmax, p->m->njmax,
                             tag_id, &xml, err, err_len);
    free(tag_id);
    if (rc < 0)
        return rc;
    mjVFS *vfs = calloc(1, sizeof(*vfs));
    if (vfs == NULL) {
        free(xml);
        return -ENOMEM;
    }
    mj_defaultVFS(vfs);
    const int len = (int)strlen(xml);
    if (mj_makeEmptyFileVFS(vfs, scene_name, len) != 0) {
        free(xml);
        free(vfs);
        return -ENOMEM;
    }
    memcpy(vfs->filedata[mj_findFileVFS(vfs, scene_name)], xml, (size_t)len);
    free(xml);
    char mj_err[512] = "";
    mjModel *scene = mj_loadXML(scene_name, vfs, mj_err, (int)sizeof(mj_err));
    mj_deleteVFS(vfs);
    free(vfs);
    if (scene == NULL) {
        one_line(mj_err);
        ps_err_format(err, err_len, "crowd scene around %s (%u agents): %s", robot->model_path,
                      *out_n, mj_err[0] ? mj_err : "load failed");
        return -PS_ERR_PLANT;
    }
    mj_deleteModel(p->m);
    p->m = scene;
    return 0;
}

int ps_plant_create(const ps_plant_cfg_t *robot, ps_plant_t **out, char *err, size_t err_len)
{
    const char *model_path = robot != NULL ? robot->model_path : NULL;
    if (model_path == NULL || robot->joint_name == NULL || robot->stance_rad == NULL ||
        out == NULL) {
        ps_err_format(err, err_len, "ps_plant_create: NULL argument");
        return -EINVAL;
    }
    if (mju_user_warning == NULL)
        mju_user_warning = quiet_warning;

    int rc;
    const bool has_crowd = robot->crowd != NULL && robot->crowd->is_enabled;
    ps_crowd_agent_spec_t *agents = NULL;
    uint32_t n_agents = 0;
    ps_plant_t *p = calloc(1, sizeof(*p));
    if (p == NULL)
        return -ENOMEM;

    char mj_err[512] = "";
    p->m = mj_loadXML(model_path, NULL, mj_err, (int)sizeof(mj_err));
    if (p->m == NULL) {
        one_line(mj_err);
        ps_err_format(err, err_len, "%s: %s", model_path, mj_err[0] ? mj_err : "load failed");
        prefix_robot_source(robot, robot->model_line, "model", err, err_len);
        rc = -PS_ERR_PLANT;
        goto fail;
    }
    if (has_crowd) {
        agents = calloc(PS_CROWD_MAX_AGENTS, sizeof(*agents));
        rc = agents != NULL ? load_scene(p, robot, agents, &n_agents, err, err_len) : -ENOMEM;
        if (rc < 0)
            goto fail;
    }
    p->d = mj_makeData(p->m);
    p->ext_force_n = calloc((size_t)p->m->nbody * 3u, sizeof(double));
    p->is_foot = calloc((size_t)p->m->nbody, 1u);
    p->is_robot = calloc((size_t)p->m->nbody, 1u);
    p->mass0 = calloc((size_t)p->m->nbody, sizeof(double));
    p->inertia0 = calloc((size_t)p->m->nbody * 3u, sizeof(double));
    p->ipos0 = calloc((size_t)p->m->nbody * 3u, sizeof(double));
    p->friction0 = calloc((size_t)p->m->ngeom * 3u, sizeof(double));
    if (p->d == NULL || p->ext_force_n == NULL || p->is_foot == NULL || p->is_robot == NULL ||
        p->mass0 == NULL || p->inertia0 == NULL || p->ipos0 == NULL || p->friction0 == NULL) {
        ps_err_format(err, err_len, "%s: out of memory", model_path);
        rc = -ENOMEM;
        goto fail;
    }
    rc = map_joints(p, robot, err, err_len);
    if (rc < 0)
        goto fail;
    rc = map_bodies(p, err, err_len);
    if (rc < 0) {
        prefix_robot_source(robot, robot->model_line, "model", err, err_len);
        goto fail;
    }

    memcpy(p->mass0, p->m->body_mass, (size_t)p->m->nbody * sizeof(double));
    memcpy(p->inertia0, p->m->body_inertia, (size_t)p->m->nbody * 3u * sizeof(double));
    memcpy(p->ipos0, p->m->body_ipos, (size_t)p->m->nbody * 3u * sizeof(double));
    memcpy(p->friction0, p->m->geom_friction, (size_t)p->m->ngeom * 3u * sizeof(double));
    place_in_stance(p, robot);
    if (has_crowd) {
        rc = ps_crowd_create(robot->crowd, agents, n_agents, p->m, p->is_robot, p->root_body,
                             &p->crowd, err, err_len);
        if (rc < 0)
            goto fail;
    }
    if (full_warning_count(p->d) != 0) {
        ps_err_format(err, err_len, "%s: at the stance: %s", model_path,
                      warning_reason(p->d, 0, 0));
        rc = -PS_ERR_PLANT;
        goto fail;
    }
    free(agents);
    agents = NULL;
    p->is_harness_engaged = true;
    p->n_bad_warnings = bad_warning_count(p->d);
    p->n_full_warnings = 0;
    *out = p;
    return 0;

fail:
    free(agents);
    ps_plant_destroy(p);
    return rc;
}

ps_crowd_t *ps_plant_crowd(ps_plant_t *p)
{
    return p->crowd;
}

const mjModel *ps_plant_model(const ps_plant_t *p)
{
    return p->m;
}

const mjData *ps_plant_data(const ps_plant_t *p)
{
    return p->d;
}

void ps_plant_get_timing(const ps_plant_t *p, int64_t *out_crowd_ns, int64_t *out_mujoco_ns)
{
    *out_crowd_ns = p->crowd_ns;
    *out_mujoco_ns = p->mujoco_ns;
}

int ps_plant_root_body(const ps_plant_t *p)
{
    return p->root_body;
}

double ps_plant_timestep_s(const ps_plant_t *p)
{
    return p->m->opt.timestep;
}

void ps_plant_set_torques(ps_plant_t *p, const double *tau_nm)
{
    const mjModel *m = p->m;
    for (int i = 0; i < p->n_joints; i++) {
        const int a = p->act_id[i];
        double tau = tau_nm[i];
        if (!isfinite(tau))
            tau = 0.0; /* a broken command must not poison the physics */
        if (m->actuator_ctrllimited[a]) {
            const double lo = m->actuator_ctrlrange[2 * a];
            const double hi = m->actuator_ctrlrange[2 * a + 1];
            tau = tau < lo ? lo : (tau > hi ? hi : tau);
        }
        p->d->ctrl[a] = tau;
    }
}

void ps_plant_get_joints(const ps_plant_t *p, double *out_q_rad, double *out_qd_rad_s)
{
    for (int i = 0; i < p->n_joints; i++) {
        if (out_q_rad != NULL)
            out_q_rad[i] = p->d->qpos[p->qpos_adr[i]];
        if (out_qd_rad_s != NULL)
            out_qd_rad_s[i] = p->d->qvel[p->dof_adr[i]];
    }
}

void ps_plant_get_imu(const ps_plant_t *p, double out_gyro_rad_s[3], double out_accel_m_s2[3])
{
    for (int k = 0; k < 3; k++) {
        out_gyro_rad_s[k] = p->d->sensordata[p->gyro_adr + k];
        out_accel_m_s2[k] = p->d->sensordata[p->accel_adr + k];
    }
}

int ps_plant_find_body(const ps_plant_t *p, const char *name)
{
    const int b = mj_name2id(p->m, mjOBJ_BODY, name);
    return b < 0 ? -ENOENT : b;
}

void ps_plant_set_external_force(ps_plant_t *p, int body_idx, const double force_n[3])
{
    if (body_idx < 0 || body_idx >= p->m->nbody)
        return;
    for (int k = 0; k < 3; k++)
        p->ext_force_n[3 * body_idx + k] = force_n[k];
}

void ps_plant_set_harness(ps_plant_t *p, bool is_engaged)
{
    p->is_harness_engaged = is_engaged;
}

/* Spring-damper wrench on the root body toward the anchor pose, world frame,
 * applied at the root's centre of mass (where xfrc_applied acts). */
static void harness_wrench(const ps_plant_t *p, mjtNum out_f[3], mjtNum out_t[3])
{
    const mjData *d = p->d;
    const mjtNum *pos = d->qpos + p->root_qpos_adr;
    const mjtNum *quat = d->qpos + p->root_qpos_adr + 3;
    const mjtNum *vel = d->qvel + p->root_dof_adr;       /* world */
    const mjtNum *omega = d->qvel + p->root_dof_adr + 3; /* body frame */
    mjtNum R[9], err_local[3], err_world[3], omega_world[3];
    mju_quat2Mat(R, quat);
    mju_subQuat(err_local, p->anchor_quat, quat); /* rotation quat -> anchor, body frame */
    mju_rotVecMat(err_world, err_local, R);
    mju_rotVecMat(omega_world, omega, R);
    for (int k = 0; k < 3; k++) {
        out_f[k] = HARNESS_K_N_M * (p->anchor_pos_m[k] - pos[k]) - HARNESS_C_N_S_M * vel[k];
        out_t[k] = HARNESS_K_NM_RAD * err_world[k] - HARNESS_C_NM_S_RAD * omega_world[k];
    }
}

int ps_plant_step(ps_plant_t *p)
{
    mjModel *m = p->m;
    mjData *d = p->d;
    for (int b = 0; b < m->nbody; b++) {
        mjtNum *x = d->xfrc_applied + 6 * b;
        for (int k = 0; k < 3; k++) {
            x[k] = p->ext_force_n[3 * b + k];
            x[3 + k] = 0.0;
        }
    }
    if (p->is_harness_engaged) {
        mjtNum f[3], t[3];
        harness_wrench(p, f, t);
        mjtNum *x = d->xfrc_applied + 6 * p->root_body;
        for (int k = 0; k < 3; k++) {
            x[k] += f[k];
            x[3 + k] += t[k];
        }
    }
    const int64_t t0 = mono_ns();
    if (p->crowd != NULL)
        ps_crowd_before_step(p->crowd, m, d, d->time);
    const int contact_full = d->warning[mjWARN_CONTACTFULL].number;
    const int cnstr_full = d->warning[mjWARN_CNSTRFULL].number;
    const int64_t t1 = mono_ns();
    mj_step(m, d);
    const int64_t t2 = mono_ns();
    if (p->crowd != NULL)
        ps_crowd_after_step(p->crowd, m, d, m->opt.timestep);
    const int64_t t3 = mono_ns();
    p->crowd_ns += (t1 - t0) + (t3 - t2);
    p->mujoco_ns += t2 - t1;

    /* MuJoCo resets the data itself when qpos/qvel/qacc go bad and only
     * warns, so the warning counters catch what a NaN scan would miss; it
     * also only warns when it drops contacts or constraints. */
    const int n_bad = bad_warning_count(d);
    const int n_full = full_warning_count(d);
    const bool is_warned = n_bad != p->n_bad_warnings || n_full != p->n_full_warnings;
    p->n_bad_warnings = n_bad;
    p->n_full_warnings = n_full;
    if (is_warned) {
        p->err_reason = warning_reason(d, contact_full, cnstr_full);
        return -PS_ERR_PLANT;
    }
    for (int i = 0; i < m->nq; i++) {
        if (!isfinite(d->qpos[i])) {
            p->err_reason = "non-finite qpos";
            return -PS_ERR_PLANT;
        }
    }
    for (int i = 0; i < m->nv; i++) {
        if (!isfinite(d->qacc[i])) {
            p->err_reason = "non-finite qacc";
            return -PS_ERR_PLANT;
        }
    }
    return 0;
}

const char *ps_plant_error_reason(const ps_plant_t *p)
{
    return p->err_reason;
}

static bool touches_floor_off_feet(const ps_plant_t *p)
{
    const mjModel *m = p->m;
    const mjData *d = p->d;
    for (int c = 0; c < d->ncon; c++) {
        const int b1 = m->geom_bodyid[d->contact[c].geom1];
        const int b2 = m->geom_bodyid[d->contact[c].geom2];
        if (b1 == 0 && p->is_robot[b2] && !p->is_foot[b2])
            return true;
        if (b2 == 0 && p->is_robot[b1] && !p->is_foot[b1])
            return true;
    }
    return false;
}

void ps_plant_get_truth(const ps_plant_t *p, ps_plant_truth_t *out)
{
    const mjData *d = p->d;
    out->t_s = d->time;
    for (int k = 0; k < 3; k++) {
        out->com_m[k] = d->subtree_com[3 * p->root_body + k];
        out->pelvis_m[k] = d->qpos[p->root_qpos_adr + k];
    }
    out->head_height_m = d->xpos[3 * p->head_body + 2];
    out->is_fallen = touches_floor_off_feet(p);
}

double ps_plant_total_mass_kg(const ps_plant_t *p)
{
    return p->m->body_subtreemass[p->root_body];
}

double ps_plant_foot_min_z_m(const ps_plant_t *p)
{
    return foot_min_z(p);
}

void ps_plant_get_body_pos(const ps_plant_t *p, int body_idx, double out_m[3])
{
    const bool is_valid = body_idx >= 0 && body_idx < p->m->nbody;
    for (int k = 0; k < 3; k++)
        out_m[k] = is_valid ? p->d->xpos[3 * body_idx + k] : NAN;
}

int ps_plant_get_feet_contact(const ps_plant_t *p, double out_force_n[2],
                              double out_cop_m[2][3])
{
    const int feet[2] = {mj_name2id(p->m, mjOBJ_BODY, "l_foot"),
                         mj_name2id(p->m, mjOBJ_BODY, "r_foot")};
    if (feet[0] < 0 || feet[1] < 0)
        return -ENOENT;
    double f[2] = {0, 0}, c[2][3] = {{0, 0, 0}, {0, 0, 0}};
    for (int i = 0; i < p->d->ncon; i++) {
        const mjContact *con = &p->d->contact[i];
        const int b1 = p->m->geom_bodyid[con->geom1], b2 = p->m->geom_bodyid[con->geom2];
        const int other = b1 == 0 ? b2 : (b2 == 0 ? b1 : -1);
        for (int s = 0; s < 2; s++) {
            if (other != feet[s])
                continue;
            mjtNum w[6];
            mj_contactForce(p->m, p->d, i, w);
            const double fn = fabs(w[0]); /* normal, contact frame */
            f[s] += fn;
            for (int k = 0; k < 3; k++)
                c[s][k] += fn * con->pos[k];
        }
    }
    for (int s = 0; s < 2; s++) {
        out_force_n[s] = f[s];
        for (int k = 0; k < 3; k++)
            out_cop_m[s][k] = f[s] > 0.0 ? c[s][k] / f[s] : NAN;
    }
    return 0;
}

void ps_plant_get_root(const ps_plant_t *p, double out_pos_m[3], double out_quat[4],
                       double out_vel_m_s[3])
{
    for (int k = 0; k < 3; k++) {
        out_pos_m[k] = p->d->qpos[p->root_qpos_adr + k];
        out_vel_m_s[k] = p->d->qvel[p->root_dof_adr + k];
    }
    for (int k = 0; k < 4; k++)
        out_quat[k] = p->d->qpos[p->root_qpos_adr + 3 + k];
}

double ps_plant_kinetic_energy_j(ps_plant_t *p)
{
    /* 0.5 qvel' M qvel with the last step's inertia matrix (mj_energyVel
     * leaves 0 unless the model enables energy). */
    mjtNum mv[PS_PLANT_MAX_NV];
    if (p->m->nv > (int)PS_PLANT_MAX_NV)
        return NAN;
    mj_mulM(p->m, p->d, mv, p->d->qvel);
    return 0.5 * mju_dot(p->d->qvel, mv, p->m->nv);
}

void ps_plant_scale_body_mass(ps_plant_t *p, int body_idx, double factor,
                              const double com_offset_m[3])
{
    if (body_idx <= 0 || body_idx >= p->m->nbody || !(factor >= 0.1 && factor <= 10.0))
        return;
    p->m->body_mass[body_idx] = p->mass0[body_idx] * factor;
    for (int k = 0; k < 3; k++) {
        p->m->body_inertia[3 * body_idx + k] = p->inertia0[3 * body_idx + k] * factor;
        p->m->body_ipos[3 * body_idx + k] =
            p->ipos0[3 * body_idx + k] + (com_offset_m != NULL ? com_offset_m[k] : 0.0);
    }
    mj_setConst(p->m, p->d); /* subtree masses and the rest derived from them */
}

void ps_plant_scale_friction(ps_plant_t *p, double factor)
{
    if (!(factor >= 0.1 && factor <= 10.0))
        return;
    for (int g = 0; g < p->m->ngeom; g++) {
        const int b = p->m->geom_bodyid[g];
        if (b == 0 || p->is_foot[b])
            p->m->geom_friction[3 * g] = p->friction0[3 * g] * factor;
    }
}

void ps_plant_reset(ps_plant_t *p, const float *stance_rad, bool is_harness_engaged)
{
    const ps_plant_cfg_t cfg = {.stance_rad = stance_rad};
    memset(p->ext_force_n, 0, (size_t)p->m->nbody * 3u * sizeof(double));
    place_in_stance(p, &cfg);
    p->is_harness_engaged = is_harness_engaged;
    p->n_bad_warnings = bad_warning_count(p->d);
    p->n_full_warnings = full_warning_count(p->d);
    p->err_reason = NULL;
}

void ps_plant_destroy(ps_plant_t *p)
{
    if (p == NULL)
        return;
    ps_crowd_destroy(p->crowd);
    if (p->d != NULL)
        mj_deleteData(p->d);
    if (p->m != NULL)
        mj_deleteModel(p->m);
    free(p->ext_force_n);
    free(p->is_foot);
    free(p->is_robot);
    free(p->mass0);
    free(p->inertia0);
    free(p->ipos0);
    free(p->friction0);
    free(p);
}

void ps_plant_get_qpos(const ps_plant_t *p, double *out_qpos)
{
    memcpy(out_qpos, p->d->qpos, sizeof(mjtNum) * (size_t)p->m->nq);
}
