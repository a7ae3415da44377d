/*
 * End to end in --lockstep: the whole system as `pushstep --lockstep` wires it
 * (ps_app: configs, bus plan, MuJoCo plant, emulated devices, loop, standing
 * controller), driven tick by tick so the test can watch the plant's ground
 * truth and every frame the loop puts on the buses.
 *
 * Built without sanitizers: it counts allocations through the interposer.
 */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <cmocka.h>

#include "../drivers/ps_mit.h"
#include "../rt/ps_app.h"
#include "../rt/ps_err.h"
#include "../rt/ps_guard.h"
#include "../rt/ps_rtsetup.h"

#define START_NS PS_NS_PER_S

/* ---- a port wrapper that checks every command independently ------------ */

typedef struct {
    ps_can_port_t inner;
    const ps_robot_cfg_t *robot;
    uint32_t bus_idx;
    uint64_t n_commands, n_special, n_violations, n_unknown;
    char first_violation[200];
} checking_port_t;

static checking_port_t checkers[PS_MAX_BUSES];

/* One quantisation step of slack: the wire carries the value rounded to the
 * nearest code, which may sit a half step outside a limit that is not on a
 * code. */
static bool is_within(float v, float lo, float hi, float min, float max, unsigned bits)
{
    float step = (max - min) / (float)((1u << bits) - 1u);
    return isfinite(v) && v >= lo - step && v <= hi + step;
}

static void check_command(checking_port_t *c, const ps_can_frame_t *f)
{
    for (uint32_t j = 0; j < c->robot->n_joints; j++) {
        const ps_joint_cfg_t *jc = &c->robot->joints[j];
        if (jc->bus_idx != c->bus_idx || jc->can_id != f->id)
            continue;
        if (ps_mit_classify_special(f->data, f->len) != 0) {
            c->n_special++;
            return;
        }
        ps_mit_cmd_t cmd;
        const ps_mit_range_t *w = &jc->wire;
        bool ok =
            ps_mit_decode_cmd(w, f->data, f->len, &cmd) == 0 &&
            is_within(cmd.p_rad, jc->pos_min_rad, jc->pos_max_rad, w->p_min_rad, w->p_max_rad,
                      PS_MIT_P_BITS) &&
            is_within(cmd.v_rad_s, -jc->vel_max_rad_s, jc->vel_max_rad_s, w->v_min_rad_s,
                      w->v_max_rad_s, PS_MIT_V_BITS) &&
            is_within(cmd.kp_nm_rad, 0, jc->kp_max_nm_rad, 0, w->kp_max_nm_rad, PS_MIT_KP_BITS) &&
            is_within(cmd.kd_nm_s_rad, 0, jc->kd_max_nm_s_rad, 0, w->kd_max_nm_s_rad,
                      PS_MIT_KD_BITS) &&
            is_within(cmd.t_ff_nm, -jc->torque_max_nm, jc->torque_max_nm, w->t_min_nm, w->t_max_nm,
                      PS_MIT_T_BITS);
        c->n_commands++;
        if (!ok && c->n_violations++ == 0)
            snprintf(c->first_violation, sizeof(c->first_violation),
                     "%s: p %.3f v %.3f kp %.2f kd %.3f t %.3f", jc->name, (double)cmd.p_rad,
                     (double)cmd.v_rad_s, (double)cmd.kp_nm_rad, (double)cmd.kd_nm_s_rad,
                     (double)cmd.t_ff_nm);
        return;
    }
    c->n_unknown++;
}

static int checking_send(void *ctx, const ps_can_frame_t *frames, size_t n)
{
    checking_port_t *c = ctx;
    for (size_t i = 0; i < n; i++)
        check_command(c, &frames[i]);
    return ps_can_send_batch(&c->inner, frames, n);
}

static int checking_recv(void *ctx, ps_can_frame_t *out, size_t max)
{
    checking_port_t *c = ctx;
    return ps_can_recv_batch(&c->inner, out, max);
}

static int checking_state(void *ctx, ps_can_state_t *out)
{
    checking_port_t *c = ctx;
    return ps_can_get_state(&c->inner, out);
}

static const ps_can_ops_t CHECKING_OPS = {
    .send_batch = checking_send, .recv_batch = checking_recv, .get_state = checking_state};

static void install_checkers(ps_app_t *app)
{
    for (uint32_t b = 0; b < app->board.n_buses; b++) {
        checkers[b] =
            (checking_port_t){.inner = app->loop.cfg.buses[b], .robot = &app->robot, .bus_idx = b};
        app->loop.cfg.buses[b] =
            (ps_can_port_t){.ops = &CHECKING_OPS, .ctx = &checkers[b], .name = "check"};
    }
}

/* ---- fixture ---------------------------------------------------------- */

static ps_app_t app; /* large: static, like main's */

static void start_app(const char *scenario)
{
    char err[PS_ERR_MSG_LEN] = "";
    ps_app_opts_t o = {.data_dir = ".", .board = "sim", .scenario = scenario, .is_lockstep = true};
    int rc = ps_app_init(&app, &o, err, sizeof(err));
    if (rc != 0)
        fail_msg("ps_app_init: %s (%s)", err, ps_strerror(rc));
    install_checkers(&app);
    assert_int_equal(ps_sim_start(app.sim, START_NS), 0);
    assert_int_equal(ps_loop_start(&app.loop, START_NS), 0);
}

static int teardown(void **state)
{
    (void)state;
    ps_app_deinit(&app);
    return 0;
}

static double loop_time_s(void)
{
    return ps_ns_to_s(app.loop.t_deadline_ns - START_NS);
}

static void step_until(double t_s)
{
    while (loop_time_s() < t_s)
        assert_int_equal(ps_loop_step(&app.loop), 0);
}

static void drain_ring(void)
{
    ps_loop_rec_t rec;
    while (ps_ring_pop(&app.ring, &rec) == 0) {
    }
}

/* ---- tests -------------------------------------------------------------- */

/* The robot stands 10 simulated seconds after the harness lets go, every
 * command on the wire is inside its joint's limits, and over all of it the
 * loop thread allocates nothing and takes no page fault. */
static void test_lockstep_stand_10s_no_fall_no_alloc_no_fault(void **state)
{
    (void)state;
    start_app("scenarios/stand.yaml");
    if (ps_rtsetup_lock_memory() < 0)
        (void)ps_rtsetup_prefault_maps(); /* without privileges: populate page tables */
    ps_rtsetup_prefault_stack(256 * 1024);

    step_until(1.9); /* start at 0.2 s, ramp 1 s: ACTIVE, still in the harness */
    assert_int_equal(app.loop.state, PS_SM_ACTIVE);
    drain_ring();
    step_until(2.1); /* harness released at 2.0 s */
    ps_sim_truth_t t0;
    ps_sim_get_truth(app.sim, &t0);

    ps_guard_arm();
    uint64_t ticks0 = app.loop.counters.n_ticks;
    double min_com_z = 1e9, max_com_z = 0;
    bool has_fallen = false;
    while (loop_time_s() < 12.2) {
        assert_int_equal(ps_loop_step(&app.loop), 0);
        if (app.loop.counters.n_ticks % 50 == 0) {
            ps_guard_pause(); /* the test's own bookkeeping is not the loop's */
            ps_sim_truth_t t;
            ps_sim_get_truth(app.sim, &t);
            has_fallen |= t.is_fallen;
            min_com_z = fmin(min_com_z, t.com_m[2]);
            max_com_z = fmax(max_com_z, t.com_m[2]);
            drain_ring();
            ps_guard_resume();
        }
    }
    ps_guard_counts_t counts;
    ps_guard_disarm(&counts);
    uint64_t n_ticks = app.loop.counters.n_ticks - ticks0;

    print_message("stood %.1f s: %llu ticks, CoM z %.3f..%.3f m (start %.3f), %llu mallocs, "
                  "%llu frees, %llu page faults\n",
                  (double)n_ticks * 1e-3, (unsigned long long)n_ticks, min_com_z, max_com_z,
                  t0.com_m[2], (unsigned long long)counts.n_allocs,
                  (unsigned long long)counts.n_frees, (unsigned long long)counts.n_faults);
    assert_true(n_ticks >= 10000);
    assert_false(has_fallen);
    assert_false(app.loop.counters.has_fallen);
    assert_int_equal(app.loop.state, PS_SM_ACTIVE);
    assert_int_equal(app.loop.counters.n_transitions, 2); /* STANDBY->RAMP->ACTIVE only */
    assert_true(min_com_z > t0.com_m[2] - 0.05);
    assert_int_equal(counts.n_allocs, 0);
    assert_int_equal(counts.n_frees, 0);
    assert_int_equal(counts.n_faults, 0);

    uint64_t n_commands = 0;
    for (uint32_t b = 0; b < app.board.n_buses; b++) {
        if (checkers[b].n_violations != 0)
            fail_msg("bus %u: %llu commands outside limits, first: %s", b,
                     (unsigned long long)checkers[b].n_violations, checkers[b].first_violation);
        assert_int_equal(checkers[b].n_unknown, 0);
        n_commands += checkers[b].n_commands;
    }
    assert_true(n_commands > 10000 * 4); /* every bus carried commands all along */
    ps_sim_truth_t t;
    ps_sim_get_truth(app.sim, &t);
    assert_int_equal(t.n_cmd_out_of_limits, 0);
    assert_int_equal(t.n_bad_frames, 0);
    assert_int_equal(app.loop.counters.n_cmd_replaced, 0);
    assert_int_equal(app.loop.counters.n_rx_bad, 0);
    assert_int_equal(app.loop.counters.n_rx_unknown, 0);
    assert_int_equal(app.loop.pacer.n_overruns, 0); /* lockstep cannot overrun */

    /* Ctrl-C path: through DAMPING to STANDBY, never straight out. */
    ps_loop_request_stop(&app.loop);
    double t_stop = loop_time_s();
    while (!ps_loop_is_stopped(&app.loop) && loop_time_s() < t_stop + 5.0)
        assert_int_equal(ps_loop_step(&app.loop), 0);
    assert_int_equal(app.loop.state, PS_SM_STANDBY);
    assert_int_equal(app.loop.counters.n_transitions, 4); /* ->DAMPING->STANDBY */
    assert_true(loop_time_s() - t_stop <= app.robot.control.damping_s + 0.01);
}

static void run_for(double t_s, ps_sim_truth_t *out)
{
    start_app("scenarios/push.yaml");
    step_until(t_s);
    ps_sim_get_truth(app.sim, out);
    ps_app_deinit(&app);
}

/* Same seed, same run: lockstep is deterministic through the whole system. */
static void test_lockstep_same_seed_identical_truth(void **state)
{
    (void)state;
    ps_sim_truth_t a, b;
    run_for(6.0, &a);
    run_for(6.0, &b);
    assert_memory_equal(a.com_m, b.com_m, sizeof(a.com_m));
    assert_true(a.head_height_m == b.head_height_m);
    assert_int_equal(a.n_cmd_frames, b.n_cmd_frames);
}

/* E-stop: pressing latches ESTOP (drives told EXIT, enable off), releasing
 * does not leave it, the operator's reset does, and start works again. */
static void test_lockstep_estop_latches_until_reset(void **state)
{
    (void)state;
    start_app("scenarios/estop.yaml");
    step_until(3.9);
    assert_int_equal(app.loop.state, PS_SM_ACTIVE);
    uint64_t special_before = 0;
    for (uint32_t b = 0; b < app.board.n_buses; b++)
        special_before += checkers[b].n_special;
    step_until(4.05);
    assert_int_equal(app.loop.state, PS_SM_ESTOP);
    uint64_t special_after = 0;
    for (uint32_t b = 0; b < app.board.n_buses; b++)
        special_after += checkers[b].n_special;
    assert_int_equal(special_after - special_before, app.robot.n_joints); /* one EXIT each */
    step_until(5.9); /* released at 5.0: still latched */
    assert_int_equal(app.loop.state, PS_SM_ESTOP);
    step_until(6.2); /* reset at 6.0 */
    assert_int_equal(app.loop.state, PS_SM_STANDBY);
    drain_ring();
    step_until(6.7); /* start at 6.5: accepted. The limp robot fell when the
                        e-stop cut it, so the ramp may end in DAMPING (FALL). */
    ps_loop_rec_t rec;
    bool has_ramp = false;
    while (ps_ring_pop(&app.ring, &rec) == 0)
        has_ramp |= rec.kind == PS_REC_TRANSITION && rec.from_state == PS_SM_STANDBY &&
                    rec.state == PS_SM_RAMP;
    assert_true(has_ramp);
    assert_int_equal(app.loop.counters.n_refused, 0);
}

/* An e-stop press shorter than a tick (pressed and released 0.2 ms apart,
 * inside one physics step) is latched by the GPIO port and reaches the state
 * machine at the next tick. */
static void test_lockstep_subtick_estop_press_reaches_estop(void **state)
{
    (void)state;
    char path[] = "/tmp/ps_e2e_subtick_XXXXXX.yaml";
    const int fd = mkstemps(path, 5);
    assert_true(fd >= 0);
    const char *yaml = "name: subtick\nduration_s: 5\nseed: 3\nevents:\n"
                       "  - {t_s: 0.2, kind: start}\n"
                       "  - {t_s: 2.0, kind: harness_release}\n"
                       "  - {t_s: 3.0001, kind: estop_press}\n"
                       "  - {t_s: 3.0003, kind: estop_release}\n";
    assert_int_equal(write(fd, yaml, strlen(yaml)), (ssize_t)strlen(yaml));
    assert_int_equal(close(fd), 0);
    start_app(path);
    (void)unlink(path);
    step_until(2.99);
    assert_int_equal(app.loop.state, PS_SM_ACTIVE);
    step_until(3.003);
    assert_int_equal(app.loop.state, PS_SM_ESTOP);
}

/* A joint that stops answering is a stale reply: DAMPING, then STANDBY. */
static void test_lockstep_dropped_replies_lead_to_damping(void **state)
{
    (void)state;
    start_app("scenarios/fault-drop.yaml");
    step_until(3.95);
    assert_int_equal(app.loop.state, PS_SM_ACTIVE);
    step_until(4.1);
    assert_int_equal(app.loop.state, PS_SM_DAMPING);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_teardown(test_lockstep_stand_10s_no_fall_no_alloc_no_fault, teardown),
        cmocka_unit_test_teardown(test_lockstep_same_seed_identical_truth, teardown),
        cmocka_unit_test_teardown(test_lockstep_estop_latches_until_reset, teardown),
        cmocka_unit_test_teardown(test_lockstep_subtick_estop_press_reaches_estop, teardown),
        cmocka_unit_test_teardown(test_lockstep_dropped_replies_lead_to_damping, teardown),
    };
    return cmocka_run_group_tests_name("e2e_lockstep", tests, NULL, NULL);
}
