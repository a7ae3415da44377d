/*
 * Tests of sim/ps_plant.c and the ps1 model (sim/models/ps1.xml): loading,
 * joint mapping, stance placement, standing under an ideal joint PD, falling
 * when limp, the harness, the IMU, pushes, and the kinematic convention the
 * estimator relies on. Run from the repo root.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <math.h>
#include <stdio.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include <mujoco/mujoco.h>

#include "../rt/ps_config.h"
#include "../rt/ps_err.h"
#include "../policy/ps_balance.h"
#include "../policy/ps_legik.h"
#include "../sim/ps_plant.h"

#define MODEL_PATH "sim/models/ps1.xml"
#define ROBOT_PATH "robots/ps1.yaml"

/* ---- the robot of robots/ps1.yaml, written out (same numbers) ---------- */

typedef struct {
    const char *name;
    uint32_t bus, can_id;
    const ps_act_range_t *wire;
    float pos_min, pos_max, torque_max, kp, kd, kp_max, kd_max, stance, kt;
    uint32_t rate_div;
} joint_row_t;

static const ps_act_range_t RS04 = {-12.566371f, 12.566371f, -15.0f, 15.0f, 5000.0f,
                                   100.0f,      -120.0f,    120.0f, -90.0f, 90.0f};
static const ps_act_range_t RS03 = {-12.566371f, 12.566371f, -50.0f, 50.0f, 5000.0f,
                                   100.0f,      -60.0f,     60.0f,  -45.0f, 45.0f};
static const ps_act_range_t RS02 = {-12.566371f, 12.566371f, -44.0f, 44.0f, 500.0f,
                                   5.0f,        -17.0f,     17.0f,  -25.0f, 25.0f};

/* name bus id driver  pos_min pos_max tau_max  kp kd kp_max kd_max stance kt div */
static const joint_row_t JOINTS[] = {
    {"l_hip_yaw", 0, 1, &RS03, -0.6f, 0.6f, 60, 100, 3, 1000, 20, 0.0f, 1.4f, 2},
    {"l_hip_roll", 0, 2, &RS03, -0.35f, 0.6f, 60, 150, 4, 1000, 20, 0.0f, 1.4f, 2},
    {"l_hip_pitch", 0, 3, &RS04, -2.0f, 0.8f, 120, 200, 4, 1000, 20, -0.28f, 1.4f, 2},
    {"l_knee", 0, 4, &RS04, -0.05f, 2.4f, 120, 300, 4, 1000, 20, 0.5f, 1.4f, 2},
    {"r_hip_yaw", 1, 1, &RS03, -0.6f, 0.6f, 60, 100, 3, 1000, 20, 0.0f, 1.4f, 2},
    {"r_hip_roll", 1, 2, &RS03, -0.6f, 0.35f, 60, 150, 4, 1000, 20, 0.0f, 1.4f, 2},
    {"r_hip_pitch", 1, 3, &RS04, -2.0f, 0.8f, 120, 200, 4, 1000, 20, -0.28f, 1.4f, 2},
    {"r_knee", 1, 4, &RS04, -0.05f, 2.4f, 120, 300, 4, 1000, 20, 0.5f, 1.4f, 2},
    {"l_ankle_pitch", 2, 1, &RS03, -0.9f, 0.6f, 60, 300, 4, 1000, 20, -0.25f, 1.4f, 2},
    {"l_ankle_roll", 2, 2, &RS03, -0.4f, 0.4f, 60, 100, 2, 1000, 20, 0.0f, 1.4f, 2},
    {"r_ankle_pitch", 2, 3, &RS03, -0.9f, 0.6f, 60, 300, 4, 1000, 20, -0.25f, 1.4f, 2},
    {"r_ankle_roll", 2, 4, &RS03, -0.4f, 0.4f, 60, 100, 2, 1000, 20, 0.0f, 1.4f, 2},
    {"waist_yaw", 3, 1, &RS03, -1.0f, 1.0f, 60, 80, 2, 1000, 20, 0.0f, 1.4f, 10},
    {"l_shoulder_pitch", 3, 2, &RS02, -3.0f, 1.0f, 17, 30, 1, 100, 3, 0.0f, 0.75f, 10},
    {"l_shoulder_roll", 3, 3, &RS02, -0.3f, 2.5f, 17, 30, 1, 100, 3, 0.15f, 0.75f, 10},
    {"l_shoulder_yaw", 3, 4, &RS02, -1.5f, 1.5f, 17, 30, 1, 100, 3, 0.0f, 0.75f, 10},
    {"l_elbow", 3, 5, &RS02, -2.5f, 0.05f, 17, 30, 1, 100, 3, -0.3f, 0.75f, 10},
    {"r_shoulder_pitch", 3, 6, &RS02, -3.0f, 1.0f, 17, 30, 1, 100, 3, 0.0f, 0.75f, 10},
    {"r_shoulder_roll", 3, 7, &RS02, -2.5f, 0.3f, 17, 30, 1, 100, 3, -0.15f, 0.75f, 10},
    {"r_shoulder_yaw", 3, 8, &RS02, -1.5f, 1.5f, 17, 30, 1, 100, 3, 0.0f, 0.75f, 10},
    {"r_elbow", 3, 9, &RS02, -2.5f, 0.05f, 17, 30, 1, 100, 3, -0.3f, 0.75f, 10},
};
#define N_JOINTS ((int)(sizeof(JOINTS) / sizeof(JOINTS[0])))

static const ps_kinematics_cfg_t KIN = {
    .mass_kg = 37.7f,
    .hip_offset_y_m = 0.08f,
    .hip_offset_z_m = 0.06f,
    .thigh_m = 0.28f,
    .shank_m = 0.28f,
    .ankle_height_m = 0.05f,
    .foot_length_m = 0.20f,
    .foot_width_m = 0.09f,
    .foot_offset_x_m = 0.03f,
    .com_offset_z_m = 0.003f,
    .fall_tilt_rad = 0.8f,
    .fall_com_height_m = 0.39f,
};

static int joint_idx(const char *name)
{
    for (int i = 0; i < N_JOINTS; i++)
        if (strcmp(JOINTS[i].name, name) == 0)
            return i;
    fail_msg("no joint %s", name);
    return -1;
}

static void build_robot(ps_robot_cfg_t *r)
{
    memset(r, 0, sizeof(*r));
    (void)snprintf(r->name, sizeof(r->name), "ps1");
    (void)snprintf(r->model, sizeof(r->model), "../sim/models/ps1.xml");
    r->control = (ps_control_cfg_t){.servo_hz = 1000,
                                    .policy_hz = 50,
                                    .ramp_s = 1.0f,
                                    .damping_s = 2.0f,
                                    .still_vel_rad_s = 0.05f,
                                    .reply_timeout_s = 0.01f,
                                    .imu_timeout_s = 0.005f,
                                    .policy_deadline_s = 0.0005f,
                                    .overrun_limit = 5,
                                    .overrun_window_s = 1.0f,
                                    .hold_s = 10.0f,
                                    .derate_band_c = PS_LOOP_DEFAULT_DERATE_BAND_C,
                                    .hot_margin_c = PS_LOOP_DEFAULT_HOT_MARGIN_C,
                                    .derate_min = PS_LOOP_DEFAULT_DERATE_MIN};
    r->servo_common.damping_kd_nm_s_rad = 2.0f;
    r->imu = (ps_imu_cfg_t){.bus_idx = 3, .base_id = 0x080, .rate_div = 1};
    r->kin = KIN;
    r->n_joints = (uint32_t)N_JOINTS;
    for (int i = 0; i < N_JOINTS; i++) {
        const joint_row_t *row = &JOINTS[i];
        ps_act_cfg_t *j = &r->act[i];
        ps_servo_joint_cfg_t *j_s = &r->servo[i];
        (void)snprintf(r->joint_name[i], sizeof(r->joint_name[i]), "%s", row->name);
        j->bus_idx = row->bus;
        j->can_id = row->can_id;
        j->reply_id = 0x100u + row->can_id;
        j->protocol = PS_ACT_PROTO_MIT;
        j->wire = *row->wire;
        j->gear_ratio = 1.0f;
        j->direction = 1.0f;
        j_s->lim.pos_min_rad = row->pos_min;
        j_s->lim.pos_max_rad = row->pos_max;
        j_s->lim.vel_max_rad_s = row->wire == &RS04 ? 15.0f : (row->wire == &RS03 ? 20.0f : 25.0f);
        j_s->lim.torque_max_nm = row->torque_max;
        j_s->kp_nm_rad = row->kp;
        j_s->kd_nm_s_rad = row->kd;
        j_s->lim.kp_max_nm_rad = row->kp_max;
        j_s->lim.kd_max_nm_s_rad = row->kd_max;
        j_s->stance_rad = row->stance;
        j_s->wire = *row->wire;
        j->kt_nm_a = row->kt;
        j->temp_max_c = 90.0f;
        j->rate_div = row->rate_div;
    }
}

/* The plant's view of a robot config; the stance array lives in *buf. */
static int plant_create(const char *model, const ps_robot_cfg_t *r, ps_plant_t **out, char *err,
                        size_t err_len)
{
    static float stance[PS_MAX_JOINTS];
    if (r == NULL)
        return ps_plant_create(NULL, out, err, err_len);
    for (uint32_t i = 0; i < r->n_joints && i < PS_MAX_JOINTS; i++)
        stance[i] = r->servo[i].stance_rad;
    const ps_plant_cfg_t cfg = {
        .model_path = model,
        .n_joints = r->n_joints,
        .joint_name = r->joint_name,
        .stance_rad = stance,
    };
    return ps_plant_create(&cfg, out, err, err_len);
}

/* ---- fixture ----------------------------------------------------------- */

typedef struct {
    ps_robot_cfg_t robot;
    ps_plant_t *plant;
    char err[PS_ERR_MSG_LEN];
} state_t;

static int setup(void **st)
{
    static state_t s;
    memset(&s, 0, sizeof(s));
    build_robot(&s.robot);
    const int rc = plant_create(MODEL_PATH, &s.robot, &s.plant, s.err, sizeof(s.err));
    if (rc != 0) {
        fprintf(stderr, "create: %d %s\n", rc, s.err);
        return -1;
    }
    *st = &s;
    return 0;
}

static int teardown(void **st)
{
    state_t *s = *st;
    ps_plant_destroy(s->plant);
    s->plant = NULL;
    return 0;
}

/* Ideal joint-space PD to the stance, as the servo layer would do it. */
static void pd_stance(const state_t *s, double *tau)
{
    double q[PS_MAX_JOINTS], qd[PS_MAX_JOINTS];
    ps_plant_get_joints(s->plant, q, qd);
    for (int i = 0; i < N_JOINTS; i++) {
        const ps_servo_joint_cfg_t *j_s = &s->robot.servo[i];
        double t = j_s->kp_nm_rad * (j_s->stance_rad - q[i]) - j_s->kd_nm_s_rad * qd[i];
        const double lim = j_s->lim.torque_max_nm;
        tau[i] = t > lim ? lim : (t < -lim ? -lim : t);
    }
}

static int steps_for(const state_t *s, double t_s)
{
    return (int)lround(t_s / ps_plant_timestep_s(s->plant));
}

/** Run for t_s with the PD (or limp), return the time of the first fall or -1. */
static double run(state_t *s, double t_s, bool is_pd)
{
    double tau[PS_MAX_JOINTS] = {0};
    ps_plant_truth_t tr;
    const int n = steps_for(s, t_s);
    for (int k = 0; k < n; k++) {
        if (is_pd)
            pd_stance(s, tau);
        ps_plant_set_torques(s->plant, tau);
        assert_int_equal(ps_plant_step(s->plant), 0);
        ps_plant_get_truth(s->plant, &tr);
        if (tr.is_fallen)
            return tr.t_s;
    }
    return -1.0;
}

static double now_s(void)
{
    struct timespec ts;
    (void)clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* ---- create ------------------------------------------------------------ */

static void test_ps_plant_create_model_maps_all_joints(void **st)
{
    state_t *s = *st;
    double q[PS_MAX_JOINTS], qd[PS_MAX_JOINTS];
    ps_plant_get_joints(s->plant, q, qd);
    /* every joint reads back its own stance angle: the map is by name */
    for (int i = 0; i < N_JOINTS; i++) {
        assert_float_equal(q[i], s->robot.servo[i].stance_rad, 1e-9);
        assert_float_equal(qd[i], 0.0, 1e-12);
    }
    assert_float_equal(ps_plant_timestep_s(s->plant), 0.0005, 1e-12);
    /* robot file's mass_kg is the model's mass */
    assert_float_equal(ps_plant_total_mass_kg(s->plant), s->robot.kin.mass_kg, 0.01);
    assert_true(ps_plant_find_body(s->plant, "torso") > 0);
    assert_true(ps_plant_find_body(s->plant, "head") > 0);
    assert_int_equal(ps_plant_find_body(s->plant, "no_such_body"), -ENOENT);
}

static void test_ps_plant_create_missing_joint_config_error(void **st)
{
    (void)st;
    ps_robot_cfg_t r;
    build_robot(&r);
    (void)snprintf(r.joint_name[5], sizeof(r.joint_name[5]), "l_tail");
    ps_plant_t *p = NULL;
    char err[PS_ERR_MSG_LEN] = "";
    assert_int_equal(plant_create(MODEL_PATH, &r, &p, err, sizeof(err)), -PS_ERR_CONFIG);
    assert_null(p);
    assert_non_null(strstr(err, "l_tail"));
}

/* A one-joint model written to path: the robot's joint "j" on a free body
 * named root_body, with or without the joint's motor. Loading it with the
 * one-joint robot must fail with a config error whose text has want. */
static void expect_tiny_model_config_error(const char *path, const char *root_body, bool has_motor,
                                           const char *want)
{
    FILE *f = fopen(path, "w");
    assert_non_null(f);
    fprintf(f,
            "<mujoco><worldbody><geom type='plane' size='1 1 .1'/>"
            "<body name='%s' pos='0 0 1'><freejoint/><site name='imu'/>"
            "<geom type='sphere' size='.1'/><body name='head'><geom type='sphere' size='.05'/>"
            "</body><body name='foot'><joint name='j' axis='0 1 0'/>"
            "<geom type='box' pos='0 0 -.5' size='.1 .1 .1'/></body></body></worldbody>"
            "%s<sensor><gyro name='imu_gyro' site='imu'/>"
            "<accelerometer name='imu_accel' site='imu'/></sensor></mujoco>",
            root_body, has_motor ? "<actuator><motor name='j' joint='j'/></actuator>" : "");
    assert_int_equal(fclose(f), 0);
    ps_robot_cfg_t r;
    build_robot(&r);
    r.n_joints = 1;
    (void)snprintf(r.joint_name[0], sizeof(r.joint_name[0]), "j");
    ps_plant_t *p = NULL;
    char err[PS_ERR_MSG_LEN] = "";
    assert_int_equal(plant_create(path, &r, &p, err, sizeof(err)), -PS_ERR_CONFIG);
    assert_null(p);
    assert_non_null(strstr(err, want));
    (void)unlink(path);
}

static void test_ps_plant_create_missing_actuator_config_error(void **st)
{
    (void)st;
    /* a joint without a motor of the same name */
    expect_tiny_model_config_error("/tmp/test_plant_noact.xml", PS_PLANT_ROOT_BODY_NAME, false,
                                   "actuator 'j'");
}

static void test_ps_plant_create_bad_path_plant_error(void **st)
{
    (void)st;
    ps_robot_cfg_t r;
    build_robot(&r);
    ps_plant_t *p = NULL;
    char err[PS_ERR_MSG_LEN] = "";
    assert_int_equal(plant_create("sim/models/nope.xml", &r, &p, err, sizeof(err)), -PS_ERR_PLANT);
    assert_null(p);
    assert_non_null(strstr(err, "nope.xml"));
    assert_true(strlen(err) > strlen("sim/models/nope.xml: "));
}

static void test_ps_plant_create_null_argument_einval(void **st)
{
    (void)st;
    ps_robot_cfg_t r;
    build_robot(&r);
    ps_plant_t *p = NULL;
    char err[PS_ERR_MSG_LEN] = "";
    assert_int_equal(plant_create(NULL, &r, &p, err, sizeof(err)), -EINVAL);
    assert_int_equal(plant_create(MODEL_PATH, NULL, &p, err, sizeof(err)), -EINVAL);
    assert_int_equal(plant_create(MODEL_PATH, &r, NULL, err, sizeof(err)), -EINVAL);
    assert_null(p);
    ps_plant_destroy(NULL); /* safe on NULL */
}

static void test_ps_plant_create_stance_soles_on_floor(void **st)
{
    state_t *s = *st;
    const double z = ps_plant_foot_min_z_m(s->plant);
    assert_true(fabs(z) < 0.002);
    ps_plant_truth_t tr;
    ps_plant_get_truth(s->plant, &tr);
    assert_false(tr.is_fallen);
    /* ~1.3 m robot: head centre between 1.1 and 1.3 m */
    assert_true(tr.head_height_m > 1.1 && tr.head_height_m < 1.3);
    /* the robot file's CoM numbers are the model's, measured in stance */
    const ps_kinematics_cfg_t *k = &s->robot.kin;
    printf("  stance: CoM %.4f %.4f %.4f m, pelvis z %.4f m\n", tr.com_m[0], tr.com_m[1],
           tr.com_m[2], tr.pelvis_m[2]);
    assert_float_equal(tr.com_m[2] - tr.pelvis_m[2], k->com_offset_z_m, 0.005);
    assert_float_equal(0.6 * tr.com_m[2], k->fall_com_height_m, 0.02);
    /* CoM over the support polygon: between heels and toes, between the feet */
    assert_true(tr.com_m[0] > k->foot_offset_x_m - 0.5 * k->foot_length_m);
    assert_true(tr.com_m[0] < k->foot_offset_x_m + 0.5 * k->foot_length_m);
    assert_float_equal(tr.com_m[1], 0.0, 0.01);
}

/* ---- standing, falling, harness ----------------------------------------- */

static void test_ps_plant_step_pd_stance_stands_10s(void **st)
{
    state_t *s = *st;
    ps_plant_truth_t tr0, tr;
    ps_plant_get_truth(s->plant, &tr0);
    ps_plant_set_harness(s->plant, false);
    double tau[PS_MAX_JOINTS];
    double max_dev_m = 0.0;
    const int n = steps_for(s, 10.0);
    const double t0 = now_s();
    for (int k = 0; k < n; k++) {
        pd_stance(s, tau);
        ps_plant_set_torques(s->plant, tau);
        assert_int_equal(ps_plant_step(s->plant), 0);
        ps_plant_get_truth(s->plant, &tr);
        assert_false(tr.is_fallen);
        const double dev = fabs(tr.head_height_m - tr0.head_height_m);
        if (dev > max_dev_m)
            max_dev_m = dev;
    }
    const double wall_s = now_s() - t0;
    printf("  stand 10 s: %d steps in %.3f s wall (%.0f steps/s incl. PD), head dev %.4f m\n", n,
           wall_s, n / wall_s, max_dev_m);
    assert_true(max_dev_m < 0.05);
    assert_true(fabs(ps_plant_foot_min_z_m(s->plant)) < 0.005);
}

static void test_ps_plant_step_limp_no_harness_falls(void **st)
{
    state_t *s = *st;
    ps_plant_set_harness(s->plant, false);
    const double t_fall = run(s, 3.0, false);
    printf("  limp, no harness: fallen at t = %.3f s\n", t_fall);
    assert_true(t_fall > 0.0);
}

static void test_ps_plant_step_limp_harness_holds(void **st)
{
    state_t *s = *st;
    ps_plant_truth_t tr0, tr;
    ps_plant_get_truth(s->plant, &tr0);
    assert_true(run(s, 3.0, false) < 0.0);
    ps_plant_get_truth(s->plant, &tr);
    const double dz = tr.pelvis_m[2] - tr0.pelvis_m[2];
    printf("  limp in harness: pelvis moved %.4f m vertically\n", dz);
    assert_true(fabs(dz) < 0.03);
    assert_true(fabs(tr.pelvis_m[0] - tr0.pelvis_m[0]) < 0.03);
}

static void test_ps_plant_step_huge_force_plant_error(void **st)
{
    state_t *s = *st;
    const double f[3] = {1e30, 0.0, 0.0};
    ps_plant_set_external_force(s->plant, ps_plant_find_body(s->plant, "torso"), f);
    assert_int_equal(ps_plant_step(s->plant), -PS_ERR_PLANT);
}

/* ---- torques ----------------------------------------------------------- */

static void test_ps_plant_set_torques_clamps_and_zeroes_nan(void **st)
{
    state_t *s = *st;
    ps_plant_t *ref = NULL;
    assert_int_equal(plant_create(MODEL_PATH, &s->robot, &ref, s->err, sizeof(s->err)), 0);
    const int w = joint_idx("waist_yaw");
    double big[PS_MAX_JOINTS] = {0}, lim[PS_MAX_JOINTS] = {0};
    big[w] = 1e6;                                 /* far beyond ctrlrange */
    lim[w] = s->robot.servo[w].lim.torque_max_nm; /* exactly the ctrlrange */
    big[0] = NAN;                                 /* must act as 0 */
    for (int k = 0; k < 200; k++) {
        ps_plant_set_torques(s->plant, big);
        ps_plant_set_torques(ref, lim);
        assert_int_equal(ps_plant_step(s->plant), 0);
        assert_int_equal(ps_plant_step(ref), 0);
    }
    double q1[PS_MAX_JOINTS], q2[PS_MAX_JOINTS];
    ps_plant_get_joints(s->plant, q1, NULL);
    ps_plant_get_joints(ref, q2, NULL);
    assert_true(fabs(q1[w] - s->robot.servo[w].stance_rad) > 0.01); /* it did turn */
    for (int i = 0; i < N_JOINTS; i++)
        assert_float_equal(q1[i], q2[i], 1e-12);
    ps_plant_destroy(ref);
}

/* ---- IMU ---------------------------------------------------------------- */

static void test_ps_plant_get_imu_standing_reads_gravity(void **st)
{
    state_t *s = *st;
    ps_plant_set_harness(s->plant, false);
    assert_true(run(s, 3.0, true) < 0.0); /* the whole-body sway settles */
    double gyro[3], acc[3];
    ps_plant_get_imu(s->plant, gyro, acc);
    printf("  IMU standing: gyro %.4f %.4f %.4f  accel %.3f %.3f %.3f\n", gyro[0], gyro[1], gyro[2],
           acc[0], acc[1], acc[2]);
    assert_float_equal(acc[0], 0.0, 0.3);
    assert_float_equal(acc[1], 0.0, 0.3);
    assert_float_equal(acc[2], 9.81, 0.3);
    for (int k = 0; k < 3; k++)
        assert_float_equal(gyro[k], 0.0, 0.05);
}

static void test_ps_plant_get_imu_rotating_reads_rate(void **st)
{
    /* a gyro that always reads 0 would pass the test above: spin the waist
     * in the harness and the pelvis gyro must see the reaction yaw rate */
    state_t *s = *st;
    double tau[PS_MAX_JOINTS] = {0};
    tau[joint_idx("waist_yaw")] = 16.0;
    double max_wz = 0.0;
    for (int k = 0; k < 100; k++) {
        ps_plant_set_torques(s->plant, tau);
        assert_int_equal(ps_plant_step(s->plant), 0);
        double gyro[3], acc[3];
        ps_plant_get_imu(s->plant, gyro, acc);
        if (fabs(gyro[2]) > max_wz)
            max_wz = fabs(gyro[2]);
    }
    assert_true(max_wz > 0.01);
}

/* ---- pushes ------------------------------------------------------------- */

static void test_ps_plant_set_external_force_short_push_moves_pelvis(void **st)
{
    state_t *s = *st;
    ps_plant_t *ref = NULL;
    assert_int_equal(plant_create(MODEL_PATH, &s->robot, &ref, s->err, sizeof(s->err)), 0);
    state_t r = *s;
    r.plant = ref;
    ps_plant_set_harness(s->plant, false);
    ps_plant_set_harness(ref, false);
    assert_true(run(s, 0.5, true) < 0.0);
    assert_true(run(&r, 0.5, true) < 0.0);
    const int torso = ps_plant_find_body(s->plant, "torso");
    assert_true(torso > 0);
    const double f[3] = {60.0, 0.0, 0.0}, zero[3] = {0.0, 0.0, 0.0};
    ps_plant_set_external_force(s->plant, torso, f);
    (void)run(s, 0.1, true);
    ps_plant_set_external_force(s->plant, torso, zero);
    (void)run(s, 0.2, true);
    (void)run(&r, 0.3, true);
    ps_plant_truth_t a, b;
    ps_plant_get_truth(s->plant, &a);
    ps_plant_get_truth(ref, &b);
    printf("  60 N x 0.1 s: pelvis dx %.4f m vs unpushed\n", a.pelvis_m[0] - b.pelvis_m[0]);
    assert_true(a.pelvis_m[0] - b.pelvis_m[0] > 0.005);
    ps_plant_destroy(ref);
}

static void test_ps_plant_set_external_force_sustained_push_falls(void **st)
{
    state_t *s = *st;
    ps_plant_set_harness(s->plant, false);
    const double f[3] = {300.0, 0.0, 0.0};
    ps_plant_set_external_force(s->plant, ps_plant_find_body(s->plant, "torso"), f);
    const double t_fall = run(s, 3.0, true);
    printf("  300 N sustained: fallen at t = %.3f s\n", t_fall);
    assert_true(t_fall > 0.0);
}

/* ---- the robot among other free bodies ------------------------------------ */

/* A copy of the ps1 model with `extra` inserted as the first child of
 * worldbody (before the floor and the robot), written to a temp file; when
 * size is not NULL it replaces the model's <size .../> element. */
static void write_model_with(char *path, size_t len, const char *extra, const char *size)
{
    FILE *in = fopen(MODEL_PATH, "r");
    assert_non_null(in);
    static char text[128 * 1024];
    const size_t n = fread(text, 1, sizeof(text) - 1, in);
    text[n] = '\0';
    (void)fclose(in);
    const char *wb = strstr(text, "<worldbody>");
    assert_non_null(wb);
    const size_t head = (size_t)(wb - text) + strlen("<worldbody>");
    (void)snprintf(path, len, "/tmp/test_plant_extra_XXXXXX.xml");
    const int fd = mkstemps(path, 4);
    assert_true(fd >= 0);
    FILE *out = fdopen(fd, "w");
    assert_non_null(out);
    const char *sz = strstr(text, "<size ");
    assert_non_null(sz);
    const char *sz_end = strstr(sz, "/>") + 2;
    assert_true(sz < wb);
    if (size == NULL)
        size = "";
    assert_int_equal(fwrite(text, 1, (size_t)(sz - text), out), (size_t)(sz - text));
    assert_true(fputs(size[0] ? size : "<size njmax=\"600\" nconmax=\"150\"/>", out) >= 0);
    assert_int_equal(fwrite(sz_end, 1, (size_t)(text + head - sz_end), out),
                     (size_t)(text + head - sz_end));
    assert_true(fputs(extra, out) >= 0);
    assert_true(fputs(text + head, out) >= 0);
    assert_int_equal(fclose(out), 0);
}

/* a 5 kg crate resting on the floor 2 m in front of the robot */
#define EXTRA_CRATE                                                                                \
    "<body name='crate' pos='2 0 0.1'><freejoint/>"                                                \
    "<geom type='box' size='0.1 0.1 0.1' mass='5'/></body>"

static int setup_with_crate(void **st)
{
    static state_t s;
    static char path[64];
    memset(&s, 0, sizeof(s));
    build_robot(&s.robot);
    write_model_with(path, sizeof(path), EXTRA_CRATE, NULL);
    const int rc = plant_create(path, &s.robot, &s.plant, s.err, sizeof(s.err));
    (void)unlink(path);
    if (rc != 0) {
        fprintf(stderr, "create: %d %s\n", rc, s.err);
        return -1;
    }
    *st = &s;
    return 0;
}

static void test_ps_plant_create_free_body_before_robot_roots_at_pelvis(void **st)
{
    state_t *s = *st;
    /* the robot's mass and stance, not the crate's */
    assert_float_equal(ps_plant_total_mass_kg(s->plant), s->robot.kin.mass_kg, 0.01);
    ps_plant_truth_t tr;
    ps_plant_get_truth(s->plant, &tr);
    assert_float_equal(tr.pelvis_m[0], 0.0, 1e-9);
    assert_float_equal(tr.pelvis_m[1], 0.0, 1e-9);
    assert_true(tr.pelvis_m[2] > 0.6 && tr.pelvis_m[2] < 0.8);
    assert_true(tr.head_height_m > 1.1 && tr.head_height_m < 1.3);
    assert_true(fabs(ps_plant_foot_min_z_m(s->plant)) < 0.002);
    /* the harness holds the pelvis, not the crate: the limp robot stays up */
    assert_true(run(s, 1.0, false) < 0.0);
    ps_plant_get_truth(s->plant, &tr);
    assert_true(fabs(tr.pelvis_m[0]) < 0.03 && tr.pelvis_m[2] > 0.6);
}

static void test_ps_plant_get_truth_crate_on_floor_not_fallen(void **st)
{
    state_t *s = *st;
    ps_plant_set_harness(s->plant, false);
    /* the crate rests on the floor all along; the robot stands */
    assert_true(run(s, 0.5, true) < 0.0);
    ps_plant_truth_t tr;
    ps_plant_get_truth(s->plant, &tr);
    assert_false(tr.is_fallen);
}

static void test_ps_plant_get_truth_robot_on_floor_among_crates_fallen(void **st)
{
    state_t *s = *st;
    ps_plant_set_harness(s->plant, false);
    const double t_fall = run(s, 3.0, false); /* limp: knees and trunk reach the floor */
    printf("  limp beside a crate: fallen at t = %.3f s\n", t_fall);
    assert_true(t_fall > 0.1);
}

static void test_ps_plant_create_no_root_body_config_error(void **st)
{
    (void)st;
    /* the free body is not called PS_PLANT_ROOT_BODY_NAME: no robot root */
    expect_tiny_model_config_error("/tmp/test_plant_noroot.xml", "base", true,
                                   PS_PLANT_ROOT_BODY_NAME);
}

/* ---- MuJoCo's warnings are plant errors ---------------------------------- */

/* a crate dropped from 0.4 m lands 2 m in front of the robot at ~0.3 s:
 * 4 more contacts and 16 more constraint rows than the stance's 8 and 53 */
#define EXTRA_DROPPED_CRATE                                                                        \
    "<body name='crate' pos='2 0 0.5'><freejoint/>"                                                \
    "<geom type='box' size='0.1 0.1 0.1' mass='5'/></body>"

/* Step the limp robot in its harness until a step fails or t_s passes;
 * return the failing step's code (0: none failed). */
static int step_until_error(ps_plant_t *p, double t_s)
{
    const double zero[PS_MAX_JOINTS] = {0};
    const int n = (int)lround(t_s / ps_plant_timestep_s(p));
    for (int k = 0; k < n; k++) {
        ps_plant_set_torques(p, zero);
        const int rc = ps_plant_step(p);
        if (rc != 0)
            return rc;
    }
    return 0;
}

static ps_plant_t *create_sized(const char *extra, const char *size, int expect_rc, char *err,
                                size_t err_len)
{
    char path[64];
    ps_robot_cfg_t r;
    build_robot(&r);
    write_model_with(path, sizeof(path), extra, size);
    ps_plant_t *p = NULL;
    const int rc = plant_create(path, &r, &p, err, err_len);
    (void)unlink(path);
    if (rc != expect_rc)
        fail_msg("create: %d, expected %d: %s", rc, expect_rc, err);
    return p;
}

static void test_ps_plant_create_stance_beyond_nconmax_plant_error(void **st)
{
    (void)st;
    char err[PS_ERR_MSG_LEN] = "";
    /* a crate sunk 1 cm into the floor: 4 contacts already at create */
    ps_plant_t *p =
        create_sized("<body name='crate' pos='2 0 0.09'><freejoint/>"
                     "<geom type='box' size='0.1 0.1 0.1' mass='5'/></body>",
                     "<size nconmax='1' njmax='600'/>", -PS_ERR_PLANT, err, sizeof(err));
    assert_null(p);
    assert_non_null(strstr(err, "nconmax"));
}

static void test_ps_plant_step_contacts_beyond_nconmax_plant_error(void **st)
{
    (void)st;
    char err[PS_ERR_MSG_LEN] = "";
    /* room for the stance's 8 contacts, not for the crate's 4 more */
    ps_plant_t *p =
        create_sized(EXTRA_DROPPED_CRATE, "<size nconmax='10' njmax='600'/>", 0, err, sizeof(err));
    assert_null(ps_plant_error_reason(p));
    assert_int_equal(step_until_error(p, 1.0), -PS_ERR_PLANT);
    assert_non_null(ps_plant_error_reason(p));
    assert_non_null(strstr(ps_plant_error_reason(p), "nconmax"));
    ps_plant_truth_t tr;
    ps_plant_get_truth(p, &tr);
    printf("  nconmax 10: plant error at t = %.4f s: %s\n", tr.t_s, ps_plant_error_reason(p));
    assert_true(tr.t_s > 0.1); /* the crate's landing, not the stance */
    ps_plant_destroy(p);
}

static void test_ps_plant_step_constraints_beyond_njmax_plant_error(void **st)
{
    (void)st;
    char err[PS_ERR_MSG_LEN] = "";
    ps_plant_t *p =
        create_sized(EXTRA_DROPPED_CRATE, "<size nconmax='150' njmax='60'/>", 0, err, sizeof(err));
    assert_int_equal(step_until_error(p, 1.0), -PS_ERR_PLANT);
    assert_non_null(strstr(ps_plant_error_reason(p), "njmax"));
    ps_plant_destroy(p);
}

static void test_ps_plant_step_model_sizes_enough_no_error(void **st)
{
    (void)st;
    char err[PS_ERR_MSG_LEN] = "";
    ps_plant_t *p = create_sized(EXTRA_DROPPED_CRATE, NULL, 0, err, sizeof(err));
    assert_int_equal(step_until_error(p, 1.0), 0);
    assert_null(ps_plant_error_reason(p));
    ps_plant_destroy(p);
}

/* ---- kinematic convention ------------------------------------------------ */

static void mat_mul(double out[9], const double a[9], const double b[9])
{
    for (int r = 0; r < 3; r++)
        for (int c = 0; c < 3; c++)
            out[3 * r + c] = a[3 * r] * b[c] + a[3 * r + 1] * b[3 + c] + a[3 * r + 2] * b[6 + c];
}

static void rot(double out[9], int axis, double a)
{
    const double c = cos(a), s = sin(a);
    const double rx[9] = {1, 0, 0, 0, c, -s, 0, s, c};
    const double ry[9] = {c, 0, s, 0, 1, 0, -s, 0, c};
    const double rz[9] = {c, -s, 0, s, c, 0, 0, 0, 1};
    memcpy(out, axis == 0 ? rx : (axis == 1 ? ry : rz), sizeof(rx));
}

static void mat_vec_add(double acc[3], const double m[9], const double v[3])
{
    for (int r = 0; r < 3; r++)
        acc[r] += m[3 * r] * v[0] + m[3 * r + 1] * v[1] + m[3 * r + 2] * v[2];
}

/** Hand-written FK of the left sole centre in the pelvis frame, from the
 *  robot file's kinematics: q = hip yaw, roll, pitch, knee, ankle pitch, roll. */
static void sole_fk(const ps_kinematics_cfg_t *k, const double q[6], double out[3])
{
    double R[9], T[9], A[9];
    out[0] = 0.0;
    out[1] = k->hip_offset_y_m;
    out[2] = -k->hip_offset_z_m;
    rot(R, 2, q[0]);
    rot(A, 0, q[1]);
    mat_mul(T, R, A);
    rot(A, 1, q[2]);
    mat_mul(R, T, A);
    const double thigh[3] = {0, 0, -k->thigh_m};
    mat_vec_add(out, R, thigh);
    rot(A, 1, q[3]);
    mat_mul(T, R, A);
    const double shank[3] = {0, 0, -k->shank_m};
    mat_vec_add(out, T, shank);
    rot(A, 1, q[4]);
    mat_mul(R, T, A);
    rot(A, 0, q[5]);
    mat_mul(T, R, A);
    const double foot[3] = {k->foot_offset_x_m, 0, -k->ankle_height_m};
    mat_vec_add(out, T, foot);
}

static void test_model_kinematics_match_convention(void **st)
{
    (void)st;
    char err[512] = "";
    mjModel *m = mj_loadXML(MODEL_PATH, NULL, err, (int)sizeof(err));
    assert_non_null(m);
    mjData *d = mj_makeData(m);
    assert_non_null(d);
    static const char *const NAMES[6] = {"l_hip_yaw", "l_hip_roll",    "l_hip_pitch",
                                         "l_knee",    "l_ankle_pitch", "l_ankle_roll"};
    const double POSES[][6] = {
        {0, 0, 0, 0, 0, 0},
        {0, 0, 0, M_PI / 2, 0, 0},
        {0, 0, -0.25, 0.5, -0.25, 0},
        {0.3, 0.2, -0.7, 1.1, -0.3, 0.15},
        {-0.4, -0.3, 0.5, 0.2, 0.4, -0.35},
    };
    const int g = mj_name2id(m, mjOBJ_GEOM, "l_foot_geom");
    const int pelvis = mj_name2id(m, mjOBJ_BODY, "pelvis");
    assert_true(g >= 0 && pelvis >= 0);
    /* foot box matches the robot file */
    assert_float_equal(2.0 * m->geom_size[3 * g], KIN.foot_length_m, 1e-6);
    assert_float_equal(2.0 * m->geom_size[3 * g + 1], KIN.foot_width_m, 1e-6);
    for (size_t n = 0; n < sizeof(POSES) / sizeof(POSES[0]); n++) {
        mj_resetData(m, d);
        /* tilt and move the pelvis: the result must be in the pelvis frame */
        d->qpos[0] = 0.3;
        d->qpos[2] = 1.2;
        d->qpos[3] = cos(0.2);
        d->qpos[4] = sin(0.2) * 0.6;
        d->qpos[6] = sin(0.2) * 0.8;
        for (int i = 0; i < 6; i++) {
            const int j = mj_name2id(m, mjOBJ_JOINT, NAMES[i]);
            assert_true(j >= 0);
            d->qpos[m->jnt_qposadr[j]] = POSES[n][i];
        }
        mj_kinematics(m, d);
        const double *gp = d->geom_xpos + 3 * g;
        const double *gR = d->geom_xmat + 9 * g;
        const double hz = m->geom_size[3 * g + 2];
        const double sole_w[3] = {gp[0] - gR[2] * hz, gp[1] - gR[5] * hz, gp[2] - gR[8] * hz};
        const double *pp = d->xpos + 3 * pelvis;
        const double *pR = d->xmat + 9 * pelvis;
        double rel[3] = {0};
        for (int r = 0; r < 3; r++)
            for (int c = 0; c < 3; c++)
                rel[r] += pR[3 * c + r] * (sole_w[c] - pp[c]);
        double fk[3];
        sole_fk(&KIN, POSES[n], fk);
        for (int k = 0; k < 3; k++)
            assert_float_equal(rel[k], fk[k], 0.001);
    }
    /* zero pose, spelled out */
    double fk0[3];
    const double zero[6] = {0};
    sole_fk(&KIN, zero, fk0);
    assert_float_equal(fk0[2], -(0.06 + 0.28 + 0.28 + 0.05), 1e-6);
    mj_deleteData(d);
    mj_deleteModel(m);
}


/* The mass model of robots/ps1.yaml (policy/ps_balance) against MuJoCo's
 * whole-body CoM (subtree_com of the pelvis) in the pelvis frame, both legs
 * moved, arms at their stance (the model lumps them into the trunk): within
 * 2 mm in every pose. */
static void test_ps1_mass_model_com_matches_mujoco(void **st)
{
    (void)st;
    ps_robot_cfg_t r;
    char err[PS_ERR_MSG_LEN] = "";
    if (ps_config_load_robot(ROBOT_PATH, &r, err, sizeof(err)) != 0)
        fail_msg("%s", err);
    assert_true(ps_balance_has_mass_model(&r.kin));
    mjModel *m = mj_loadXML(MODEL_PATH, NULL, err, (int)sizeof(err));
    assert_non_null(m);
    mjData *d = mj_makeData(m);
    static const char *const LEG[2][6] = {
        {"l_hip_yaw", "l_hip_roll", "l_hip_pitch", "l_knee", "l_ankle_pitch", "l_ankle_roll"},
        {"r_hip_yaw", "r_hip_roll", "r_hip_pitch", "r_knee", "r_ankle_pitch", "r_ankle_roll"}};
    const float POSES[][2][6] = {
        {{0, 0, -0.28f, 0.5f, -0.25f, 0}, {0, 0, -0.28f, 0.5f, -0.25f, 0}},
        {{0, 0, 0, 0, 0, 0}, {0, 0, 0, 0, 0, 0}},
        {{0.3f, 0.2f, -0.7f, 1.1f, -0.3f, 0.15f}, {-0.2f, -0.3f, 0.4f, 0.2f, 0.3f, -0.2f}},
        {{-0.4f, -0.3f, 0.5f, 0.2f, 0.4f, -0.35f}, {0, 0.3f, -1.5f, 2.0f, -0.5f, 0.1f}},
    };
    const int pelvis = mj_name2id(m, mjOBJ_BODY, "pelvis");
    for (size_t n = 0; n < sizeof(POSES) / sizeof(POSES[0]); n++) {
        mj_resetData(m, d);
        d->qpos[2] = 1.0;
        for (uint32_t i = 0; i < r.n_joints; i++) /* arms and waist at the stance */
            d->qpos[m->jnt_qposadr[mj_name2id(m, mjOBJ_JOINT, r.joint_name[i])]] =
                r.servo[i].stance_rad;
        for (int s = 0; s < 2; s++)
            for (int j = 0; j < 6; j++)
                d->qpos[m->jnt_qposadr[mj_name2id(m, mjOBJ_JOINT, LEG[s][j])]] = POSES[n][s][j];
        mj_forward(m, d);
        ps_balance_point_t pts[PS_BALANCE_N_POINTS];
        float com[3];
        assert_int_equal(ps_balance_points(&r.kin, POSES[n], pts), (int)PS_BALANCE_N_POINTS);
        assert_int_equal(ps_balance_com(pts, PS_BALANCE_N_POINTS, com), 0);
        for (int k = 0; k < 3; k++) {
            const double want = d->subtree_com[3 * pelvis + k] - d->xpos[3 * pelvis + k];
            if (fabs(com[k] - want) > 0.002)
                fail_msg("pose %zu axis %d: mass model %.4f, MuJoCo %.4f", n, k, (double)com[k],
                         want);
        }
    }
    mj_deleteData(d);
    mj_deleteModel(m);
}

/* ---- the robot file -------------------------------------------------------- */

/* The robot file against the MJCF it names, read with MuJoCo itself: every
 * joint is a limited hinge whose range is the file's [pos_min, pos_max], its
 * motor's ctrlrange is +-torque_max (gear 1), the stance lies inside, its
 * armature is its drive's armature_kg_m2 x gear_ratio^2 and torque_max is
 * within the drive's peak torque. */
static void test_ps_config_load_robot_ps1_matches_model(void **st)
{
    (void)st;
    ps_robot_cfg_t loaded;
    char err[PS_ERR_MSG_LEN] = "";
    const int rc = ps_config_load_robot(ROBOT_PATH, &loaded, err, sizeof(err));
    if (rc != 0)
        fprintf(stderr, "load: %s\n", err);
    assert_int_equal(rc, 0);
    char model[2 * PS_PATH_LEN];
    if (loaded.model[0] == '/' || access(loaded.model, R_OK) == 0)
        (void)snprintf(model, sizeof(model), "%s", loaded.model);
    else
        (void)snprintf(model, sizeof(model), "robots/%s", loaded.model);
    char mj_err[1000] = "";
    mjModel *m = mj_loadXML(model, NULL, mj_err, sizeof(mj_err));
    if (m == NULL)
        fail_msg("%s: %s", model, mj_err);
    int n_hinges = 0;
    for (int k = 0; k < m->njnt; k++)
        n_hinges += m->jnt_type[k] == mjJNT_HINGE;
    assert_int_equal((int)loaded.n_joints, n_hinges); /* every hinge is a robot joint */
    for (uint32_t i = 0; i < loaded.n_joints; i++) {
        const char *name = loaded.joint_name[i];
        const ps_servo_joint_cfg_t *sj = &loaded.servo[i];
        const int jid = mj_name2id(m, mjOBJ_JOINT, name);
        const int aid = mj_name2id(m, mjOBJ_ACTUATOR, name);
        if (jid < 0 || aid < 0)
            fail_msg("joint %s: no hinge or motor of that name in %s", name, model);
        assert_int_equal(m->jnt_type[jid], mjJNT_HINGE);
        assert_true(m->jnt_limited[jid]);
        if (fabs(m->jnt_range[2 * jid] - sj->lim.pos_min_rad) > 1e-6 ||
            fabs(m->jnt_range[2 * jid + 1] - sj->lim.pos_max_rad) > 1e-6)
            fail_msg("joint %s: model range [%g, %g], robot file [%g, %g]", name,
                     m->jnt_range[2 * jid], m->jnt_range[2 * jid + 1], (double)sj->lim.pos_min_rad,
                     (double)sj->lim.pos_max_rad);
        assert_int_equal(m->actuator_trnid[2 * aid], jid);
        assert_float_equal(m->actuator_gear[6 * aid], 1.0, 0.0);
        assert_true(m->actuator_ctrllimited[aid]);
        if (fabs(m->actuator_ctrlrange[2 * aid] + sj->lim.torque_max_nm) > 1e-6 ||
            fabs(m->actuator_ctrlrange[2 * aid + 1] - sj->lim.torque_max_nm) > 1e-6)
            fail_msg("joint %s: motor ctrlrange [%g, %g], robot file torque_max %g", name,
                     m->actuator_ctrlrange[2 * aid], m->actuator_ctrlrange[2 * aid + 1],
                     (double)sj->lim.torque_max_nm);
        assert_true(sj->stance_rad >= sj->lim.pos_min_rad && sj->stance_rad <= sj->lim.pos_max_rad);
        /* the drive's rotor, reflected through the gear, is the joint's armature */
        const ps_act_cfg_t *a = &loaded.act[i];
        assert_true(ps_act_motor_is_modelled(&a->motor));
        const double armature = (double)a->motor.armature_kg_m2 * a->gear_ratio * a->gear_ratio;
        if (fabs(m->dof_armature[m->jnt_dofadr[jid]] - armature) > 1e-6)
            fail_msg("joint %s: model armature %g, robot file's drive %g x gear^2 = %g", name,
                     m->dof_armature[m->jnt_dofadr[jid]], (double)a->motor.armature_kg_m2,
                     armature);
        /* torque_max fits the drive's peak at the joint */
        assert_true(sj->lim.torque_max_nm <= a->motor.peak_torque_nm * a->gear_ratio + 1e-4f);
    }
    /* the kinematics block's mass is the model's floating subtree's */
    ps_plant_t *p = NULL;
    assert_int_equal(plant_create(model, &loaded, &p, err, sizeof(err)), 0);
    assert_float_equal(ps_plant_total_mass_kg(p), loaded.kin.mass_kg, 0.05);
    ps_plant_destroy(p);
    mj_deleteModel(m);
}


/* ---- the robot can step: one leg for 2 s -------------------------------- */

static double smooth01(double x)
{
    x = x < 0.0 ? 0.0 : (x > 1.0 ? 1.0 : x);
    return x * x * (3.0 - 2.0 * x);
}

/* robots/ps1.yaml as loaded, on its model, with no harness: shift the pelvis
 * over the left foot, lift the right foot 8 cm, hold it up 2 s. Joint
 * targets come from the analytic leg IK (feet flat, pelvis level); the
 * torques are an ideal joint PD at the joints' configured kp_max / kd_max
 * (the stiffest the robot file allows) plus a CoM-over-foot correction of
 * the pelvis shift from the plant's ground truth. Every torque the PD asks
 * for must lie inside the joint's torque_max and the drive's torque-speed
 * limit at that instant (nothing is clamped). */
#define K_ANKLE   1.5 /* rad of ankle per m of CoM offset from the sole */
#define K_ANKLE_V 0.3 /* rad of ankle per m/s of CoM velocity */

static void test_ps1_stands_on_one_leg_2s_within_torque_limits(void **st)
{
    (void)st;
    ps_robot_cfg_t r;
    char err[PS_ERR_MSG_LEN] = "";
    if (ps_config_load_robot(ROBOT_PATH, &r, err, sizeof(err)) != 0)
        fail_msg("%s", err);
    ps_plant_t *p = NULL;
    if (plant_create(MODEL_PATH, &r, &p, err, sizeof(err)) != 0)
        fail_msg("%s", err);
    ps_plant_set_harness(p, false);
    static const char *const LEG[2][PS_LEG_N_JOINTS] = {
        {"l_hip_yaw", "l_hip_roll", "l_hip_pitch", "l_knee", "l_ankle_pitch", "l_ankle_roll"},
        {"r_hip_yaw", "r_hip_roll", "r_hip_pitch", "r_knee", "r_ankle_pitch", "r_ankle_roll"}};
    int idx[2][PS_LEG_N_JOINTS];
    float sole0[2][3];
    for (int side = 0; side < 2; side++) {
        float q[PS_LEG_N_JOINTS];
        for (int j = 0; j < PS_LEG_N_JOINTS; j++) {
            idx[side][j] = ps_config_find_joint(&r, LEG[side][j]);
            assert_true(idx[side][j] >= 0);
            q[j] = r.servo[idx[side][j]].stance_rad;
        }
        ps_estimate_leg_fk(&r.kin, side, q, sole0[side]);
    }
    const int l_foot = ps_plant_find_body(p, "l_foot"), r_foot = ps_plant_find_body(p, "r_foot");
    float q_tgt[PS_MAX_JOINTS];
    for (uint32_t i = 0; i < r.n_joints; i++)
        q_tgt[i] = r.servo[i].stance_rad;
    const double dt = ps_plant_timestep_s(p);
    const double t_shift = 1.5, t_lift = 0.5, t_hold = 2.0, lift_m = 0.08;
    const int n = (int)lround((t_shift + t_lift + t_hold) / dt);
    double tau[PS_MAX_JOINTS], q[PS_MAX_JOINTS], qd[PS_MAX_JOINTS];
    double shift_fb_m = 0.0, min_lift_m = 1.0, max_ratio = 0.0, com_prev[3] = {0};
    for (int k = 0; k < n; k++) {
        const double t = k * dt;
        ps_plant_truth_t tr;
        ps_plant_get_truth(p, &tr);
        assert_false(tr.is_fallen);
        double lf[3], rf[3];
        ps_plant_get_body_pos(p, l_foot, lf);
        ps_plant_get_body_pos(p, r_foot, rf);
        /* CoM over the left sole centre (its frame origin is the ankle's x
         * and y less the foot's 3 cm offset): integrate the error into the
         * pelvis shift, slowly. */
        double vel[3] = {0};
        for (int a = 0; a < 3 && k > 0; a++)
            vel[a] = (tr.com_m[a] - com_prev[a]) / dt;
        memcpy(com_prev, tr.com_m, sizeof(com_prev));
        if (t > 0.5 * t_shift)
            shift_fb_m += dt * 2.0 * (lf[1] - tr.com_m[1]);
        /* Ankle strategy on the left foot (signs as policy/ps_stand.c):
         * CoM right of the sole or moving right: roll the ankle target up. */
        const double sole_x = lf[0] + r.kin.foot_offset_x_m;
        const double on = smooth01((t - t_shift) / t_lift); /* single support */
        const double d_roll = on * (-K_ANKLE * (tr.com_m[1] - lf[1]) - K_ANKLE_V * vel[1]);
        const double d_pitch = on * (K_ANKLE * (tr.com_m[0] - sole_x) + K_ANKLE_V * vel[0]);
        const double shift = 0.08 * smooth01(t / t_shift) + shift_fb_m;
        const double up = lift_m * smooth01((t - t_shift) / t_lift);
        if (k % 2 == 0) { /* targets at 1 kHz, as the servo layer would */
            for (int side = 0; side < 2; side++) {
                const float eye[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
                float sole[3] = {sole0[side][0], sole0[side][1] - (float)shift, sole0[side][2]};
                if (side == 1)
                    sole[2] += (float)up;
                float ql[PS_LEG_N_JOINTS];
                assert_true(ps_legik_solve(&r.kin, side, sole, eye, ql) >= 0);
                for (int j = 0; j < PS_LEG_N_JOINTS; j++)
                    q_tgt[idx[side][j]] = ql[j];
            }
            q_tgt[idx[0][PS_LEG_ANKLE_ROLL]] += (float)d_roll;
            q_tgt[idx[0][PS_LEG_ANKLE_PITCH]] += (float)d_pitch;
        }
        ps_plant_get_joints(p, q, qd);
        for (uint32_t i = 0; i < r.n_joints; i++) {
            const ps_servo_joint_cfg_t *j = &r.servo[i];
            const float qt = q_tgt[i] < j->lim.pos_min_rad   ? j->lim.pos_min_rad
                             : q_tgt[i] > j->lim.pos_max_rad ? j->lim.pos_max_rad
                                                             : q_tgt[i];
            const bool is_leg = r.act[i].motor.peak_torque_nm > 20.0f;
            const double kp = is_leg ? j->lim.kp_max_nm_rad : j->kp_nm_rad;
            const double kd = is_leg ? j->lim.kd_max_nm_s_rad : j->kd_nm_s_rad;
            tau[i] = kp * (qt - q[i]) - kd * qd[i];
            const float deliverable =
                ps_act_motor_limit_torque(&r.act[i].motor, (float)tau[i], (float)qd[i]);
            if (fabs(tau[i]) > j->lim.torque_max_nm || fabs(deliverable - tau[i]) > 1e-3)
                fail_msg("t=%.3f s %s: PD torque %.1f Nm at %.2f rad/s, limit %.1f / deliverable "
                         "%.1f",
                         t, r.joint_name[i], tau[i], qd[i], (double)j->lim.torque_max_nm,
                         (double)deliverable);
            const double ratio = fabs(tau[i]) / j->lim.torque_max_nm;
            max_ratio = ratio > max_ratio ? ratio : max_ratio;
        }
        ps_plant_set_torques(p, tau);
        assert_int_equal(ps_plant_step(p), 0);
        if (t >= t_shift + t_lift) {
            const double lifted = rf[2] - lf[2];
            min_lift_m = lifted < min_lift_m ? lifted : min_lift_m;
        }
    }
    ps_plant_truth_t tr;
    ps_plant_get_truth(p, &tr);
    printf("  one leg: right foot at least %.3f m above the left over %.1f s, largest torque "
           "%.0f%% of its limit, pelvis height %.3f m\n",
           min_lift_m, t_hold, 100.0 * max_ratio, tr.pelvis_m[2]);
    assert_false(tr.is_fallen);
    assert_true(min_lift_m > 0.5 * lift_m); /* the right foot stayed up, off the floor */
    ps_plant_destroy(p);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup_teardown(test_ps_plant_create_model_maps_all_joints, setup,
                                        teardown),
        cmocka_unit_test(test_ps_plant_create_missing_joint_config_error),
        cmocka_unit_test(test_ps_plant_create_missing_actuator_config_error),
        cmocka_unit_test(test_ps_plant_create_bad_path_plant_error),
        cmocka_unit_test(test_ps_plant_create_null_argument_einval),
        cmocka_unit_test_setup_teardown(test_ps_plant_create_stance_soles_on_floor, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_ps_plant_step_pd_stance_stands_10s, setup, teardown),
        cmocka_unit_test_setup_teardown(test_ps_plant_step_limp_no_harness_falls, setup, teardown),
        cmocka_unit_test_setup_teardown(test_ps_plant_step_limp_harness_holds, setup, teardown),
        cmocka_unit_test_setup_teardown(test_ps_plant_step_huge_force_plant_error, setup, teardown),
        cmocka_unit_test_setup_teardown(test_ps_plant_set_torques_clamps_and_zeroes_nan, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_ps_plant_get_imu_standing_reads_gravity, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_ps_plant_get_imu_rotating_reads_rate, setup, teardown),
        cmocka_unit_test_setup_teardown(test_ps_plant_set_external_force_short_push_moves_pelvis,
                                        setup, teardown),
        cmocka_unit_test_setup_teardown(test_ps_plant_set_external_force_sustained_push_falls,
                                        setup, teardown),
        cmocka_unit_test_setup_teardown(test_ps_plant_create_free_body_before_robot_roots_at_pelvis,
                                        setup_with_crate, teardown),
        cmocka_unit_test_setup_teardown(test_ps_plant_get_truth_crate_on_floor_not_fallen,
                                        setup_with_crate, teardown),
        cmocka_unit_test_setup_teardown(test_ps_plant_get_truth_robot_on_floor_among_crates_fallen,
                                        setup_with_crate, teardown),
        cmocka_unit_test(test_ps_plant_create_no_root_body_config_error),
        cmocka_unit_test(test_ps_plant_create_stance_beyond_nconmax_plant_error),
        cmocka_unit_test(test_ps_plant_step_contacts_beyond_nconmax_plant_error),
        cmocka_unit_test(test_ps_plant_step_constraints_beyond_njmax_plant_error),
        cmocka_unit_test(test_ps_plant_step_model_sizes_enough_no_error),
        cmocka_unit_test(test_model_kinematics_match_convention),
        cmocka_unit_test(test_ps_config_load_robot_ps1_matches_model),
        cmocka_unit_test(test_ps1_stands_on_one_leg_2s_within_torque_limits),
        cmocka_unit_test(test_ps1_mass_model_com_matches_mujoco),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
