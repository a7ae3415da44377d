/*
 * The loop against scripted devices and an injected clock: pacing and
 * overrun accounting, the watchdogs and their state transitions, what goes
 * on the wire in each state, and the bus schedule. Uses the shipped board
 * and robot files, so the loop sees the real joint map.
 */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#include "../drivers/ps_imu_msg.h"
#include "../drivers/ps_mit.h"
#include "../rt/ps_err.h"
#include "../rt/ps_app.h"
#include "../rt/ps_config.h"
#include "../rt/ps_loop.h"
#include "fakes/ps_clock_fake.h"

#define PERIOD_NS PS_NS_PER_MS
#define START_NS  PS_NS_PER_S
#define MAX_SENT  64u

/* ---- scripted devices: answer every command like a healthy drive --------- */

typedef struct {
    uint32_t bus_idx;
    ps_can_frame_t sent[MAX_SENT];
    uint32_t n_sent;
    ps_can_frame_t pending[MAX_SENT]; /* delivered on the next recv */
    uint32_t n_pending;
    ps_can_frame_t late[MAX_SENT]; /* fx->is_reply_late: one tick later still */
    uint32_t n_late;
    bool is_bus_off;
    uint32_t n_refuse_batches; /* the next N send_batch calls queue nothing */
    uint32_t n_exit_total;     /* EXIT frames accepted, never cleared */
    bool is_babbling;          /* a node floods the bus: every recv is full */
} fake_bus_t;

typedef struct {
    ps_clock_fake_t clock;
    ps_board_cfg_t board;
    ps_robot_cfg_t robot;
    ps_canbus_plan_t plan;
    fake_bus_t buses[PS_MAX_BUSES];
    bool is_estop_pressed, has_gpio_error;
    bool has_heartbeat_error;    /* set_heartbeat fails */
    bool is_button_latched;      /* the record button: a press since the last read */
    uint64_t n_taps;             /* tap calls */
    uint64_t tap_tick;           /* n_ticks the tap saw last */
    uint32_t tap_n_cmd_sent;     /* joints with a command that tick */
    bool tap_saw_button;         /* a tap saw last.is_button_pressed */
    bool tap_stages_ok;          /* every tap saw read..tick stage times >= 0 */
    bool heartbeat;              /**< level of the heartbeat output */
    uint64_t n_hb_edges;         /**< its level changes */
    uint64_t n_hb_calls;         /**< set_heartbeat calls */
    bool is_mute[PS_MAX_JOINTS]; /* joint does not answer */
    uint8_t fault[PS_MAX_JOINTS];
    bool is_imu_mute;
    bool is_imu_frozen; /* repeats the same seq */
    bool is_imu_values_frozen; /* the same values with an advancing seq */
    float reply_jump_rad[PS_MAX_JOINTS]; /* added to the reported position */
    uint8_t imu_status;
    uint8_t imu_seq;
    float policy_value;             /* NAN: the policy returns a NaN target */
    ps_neighbours_t policy_neighbours; /* meas.neighbours at the last policy step */
    int64_t policy_extra_ns;        /* time the policy takes */
    ps_clock_fake_t cpu_clock;      /* stands for the thread's CPU time */
    bool is_policy_preempted;       /* policy time passes on the wall clock only */
    bool is_ctrl_c_in_damping;      /* the operator presses Ctrl-C once while braking */
    bool is_fault_cleared_by_enter; /* drives clear a latched fault on ENTER, like real ones */
    bool is_reply_late;             /* replies arrive two ticks after their command */
    float policy_offset_rad;        /* added to the stance in every target */
    bool is_imu_tipped;             /* the IMU reads gravity along x: the trunk lies flat */
    int64_t read_extra_ns;          /* time each read of bus 0 takes (forces overruns) */
    unsigned n_policy_resets;
    unsigned n_steps_after_reset; /* policy steps since the last reset */
    int state_at_first_step;      /* loop state at the first step after a reset */
    ps_loop_rec_t recs[256];      /* TRANSITION and REFUSED records drained from the ring */
    unsigned n_recs;
    ps_ring_t ring;
    ps_loop_rec_t ring_storage[256];
    ps_loop_t loop;
} fixture_t;

static fixture_t *fx;

static int joint_of(const fixture_t *f, uint32_t bus, uint32_t can_id)
{
    for (uint32_t j = 0; j < f->robot.n_joints; j++)
        if (f->robot.act[j].bus_idx == bus && f->robot.act[j].can_id == can_id)
            return (int)j;
    return -1;
}

static void answer(fake_bus_t *b, int j)
{
    const ps_act_cfg_t *jc = &fx->robot.act[j];
    const ps_servo_joint_cfg_t *jc_s = &fx->robot.servo[j];
    if (fx->is_mute[j] || b->n_pending >= MAX_SENT)
        return;
    ps_mit_reply_t rep = {.motor_id = (uint8_t)(jc->can_id & 0xf),
                          .fault = fx->fault[j],
                          .p_rad = jc_s->stance_rad + fx->reply_jump_rad[j],
                          .temp_mos_c = 30,
                          .temp_rotor_c = 30};
    if (fx->is_reply_late && b->n_late >= MAX_SENT)
        return;
    ps_can_frame_t *f = fx->is_reply_late ? &b->late[b->n_late++] : &b->pending[b->n_pending++];
    memset(f, 0, sizeof(*f));
    f->id = jc->reply_id;
    f->len = 8;
    ps_mit_encode_reply(&jc->wire, &rep, f->data);
}

static int fake_send(void *ctx, const ps_can_frame_t *frames, size_t n)
{
    fake_bus_t *b = ctx;
    if (b->n_refuse_batches > 0) {
        b->n_refuse_batches--;
        return 0;
    }
    for (size_t i = 0; i < n; i++) {
        if (b->n_sent < MAX_SENT)
            b->sent[b->n_sent++] = frames[i];
        int special = ps_mit_classify_special(frames[i].data, frames[i].len);
        if (special == PS_MIT_SPECIAL_EXIT)
            b->n_exit_total++;
        int j = joint_of(fx, b->bus_idx, frames[i].id);
        if (j >= 0 && special == PS_MIT_SPECIAL_ENTER && fx->is_fault_cleared_by_enter)
            fx->fault[j] = PS_MIT_FAULT_NONE;
        if (j >= 0)
            answer(b, j);
    }
    return (int)n;
}

static int fake_recv(void *ctx, ps_can_frame_t *out, size_t max)
{
    fake_bus_t *b = ctx;
    size_t n = 0;
    if (b->bus_idx == 0)
        ps_clock_fake_advance(&fx->clock, fx->read_extra_ns);
    if (b->is_babbling) {
        for (; n < max; n++) {
            memset(&out[n], 0, sizeof(out[n]));
            out[n].id = 0x555;
            out[n].len = 8;
        }
        return (int)n;
    }
    if (b->bus_idx == fx->robot.imu.bus_idx && !fx->is_imu_mute && max >= 2) {
        /* A MEMS IMU's readings always carry noise: a dither of one LSB. */
        const float dither = fx->is_imu_values_frozen ? 0.0f : 0.001f * (float)(fx->imu_seq & 1u);
        ps_imu_sample_t s = {.gyro_body_rad_s = {dither, 0, 0},
                             .accel_body_m_s2 = {fx->is_imu_tipped ? -9.81f : 0.0f, 0,
                                                 fx->is_imu_tipped ? 0.0f : 9.81f},
                             .seq = fx->is_imu_frozen ? fx->imu_seq : fx->imu_seq++,
                             .status = fx->imu_status};
        ps_imu_msg_encode(fx->robot.imu.base_id, &s, out);
        n = 2;
    }
    for (uint32_t i = 0; i < b->n_pending && n < max; i++)
        out[n++] = b->pending[i];
    b->n_pending = 0;
    memcpy(b->pending, b->late, b->n_late * sizeof(b->late[0]));
    b->n_pending = b->n_late;
    b->n_late = 0;
    return (int)n;
}

static int fake_state(void *ctx, ps_can_state_t *out)
{
    fake_bus_t *b = ctx;
    memset(out, 0, sizeof(*out));
    out->mode = b->is_bus_off ? PS_CAN_BUS_OFF : PS_CAN_BUS_ERROR_ACTIVE;
    return 0;
}

static const ps_can_ops_t FAKE_BUS_OPS = {
    .send_batch = fake_send, .recv_batch = fake_recv, .get_state = fake_state};

static int gpio_read(void *ctx, bool *out)
{
    (void)ctx;
    if (fx->has_gpio_error)
        return -EIO;
    *out = fx->is_estop_pressed;
    return 0;
}
static int gpio_heartbeat(void *ctx, bool level)
{
    (void)ctx;
    fx->n_hb_calls++;
    if (fx->has_heartbeat_error)
        return -EIO;
    if (level != fx->heartbeat)
        fx->n_hb_edges++;
    fx->heartbeat = level;
    return 0;
}
static int gpio_led(void *ctx, ps_gpio_led_t led)
{
    (void)ctx;
    (void)led;
    return 0;
}
static int gpio_read_button(void *ctx, bool *out)
{
    fixture_t *f = ctx;
    *out = f->is_button_latched;
    f->is_button_latched = false;
    return 0;
}
static const ps_gpio_ops_t FAKE_GPIO_OPS = {.read_estop = gpio_read,
                                            .set_heartbeat = gpio_heartbeat,
                                            .set_led = gpio_led,
                                            .read_button = gpio_read_button};

/* A policy that holds the stance, or returns what the test scripts. */
static int fake_policy_step(void *ctx, const ps_meas_t *m, const ps_estimate_t *e,
                            ps_targets_t *out)
{
    (void)ctx;
    (void)e;
    fx->policy_neighbours = m->neighbours; /* what the policy was shown */
    out->n_joints = fx->robot.n_joints;
    for (uint32_t j = 0; j < fx->robot.n_joints; j++) {
        out->q_rad[j] =
            isnan(fx->policy_value) ? NAN : fx->robot.servo[j].stance_rad + fx->policy_offset_rad;
        out->qd_rad_s[j] = 0;
        out->tau_ff_nm[j] = 0;
    }
    if (fx->is_ctrl_c_in_damping && fx->loop.state == PS_SM_DAMPING) {
        ps_loop_request_stop(&fx->loop);
        fx->is_ctrl_c_in_damping = false;
    }
    if (fx->n_steps_after_reset++ == 0)
        fx->state_at_first_step = (int)fx->loop.state;
    ps_clock_fake_advance(&fx->clock, fx->policy_extra_ns);
    if (!fx->is_policy_preempted)
        ps_clock_fake_advance(&fx->cpu_clock, fx->policy_extra_ns);
    return 0;
}
static void fake_policy_reset(void *ctx)
{
    (void)ctx;
    fx->n_policy_resets++;
    fx->n_steps_after_reset = 0;
}
static const ps_policy_ops_t FAKE_POLICY = {
    .name = "fake", .step = fake_policy_step, .reset = fake_policy_reset};

static int setup(void **state)
{
    char err[PS_ERR_MSG_LEN];
    fx = test_calloc(1, sizeof(*fx));
    assert_non_null(fx);
    if (ps_config_load_board("boards/sim.yaml", &fx->board, err, sizeof(err)) != 0 ||
        ps_config_load_robot("robots/ps1.yaml", &fx->robot, err, sizeof(err)) != 0 ||
        ps_app_plan_buses(&fx->board, &fx->robot, &fx->plan, err, sizeof(err)) != 0)
        fail_msg("config: %s", err);
    ps_clock_fake_init(&fx->clock, START_NS);
    assert_int_equal(ps_ring_init(&fx->ring, fx->ring_storage, 256, sizeof(ps_loop_rec_t)), 0);
    ps_loop_cfg_t lc = {
        .board = &fx->board,
        .robot = &fx->robot,
        .plan = &fx->plan,
        .clock = &fx->clock.clock,
        .gpio = {.ops = &FAKE_GPIO_OPS, .ctx = fx},
        .policy = {.ops = &FAKE_POLICY, .ctx = fx},
        .ring = &fx->ring,
        .status_every = 10,
    };
    for (uint32_t b = 0; b < fx->board.n_buses; b++) {
        fx->buses[b].bus_idx = b;
        lc.buses[b] = (ps_can_port_t){.ops = &FAKE_BUS_OPS, .ctx = &fx->buses[b], .name = "fake"};
    }
    assert_int_equal(ps_loop_init(&fx->loop, &lc), 0);
    assert_int_equal(ps_loop_start(&fx->loop, START_NS), 0);
    *state = fx;
    return 0;
}

static int teardown(void **state)
{
    (void)state;
    ps_loop_deinit(&fx->loop);
    test_free(fx);
    fx = NULL;
    return 0;
}

static void clear_sent(void)
{
    for (uint32_t b = 0; b < fx->board.n_buses; b++)
        fx->buses[b].n_sent = 0;
}

/* Keep the ring's transitions and refusals (status records dropped), so a
 * long run does not lose them to a full ring. */
static void drain_records(void)
{
    ps_loop_rec_t rec;
    while (ps_ring_pop(&fx->ring, &rec) == 0)
        if (rec.kind != PS_REC_STATUS && fx->n_recs < sizeof fx->recs / sizeof fx->recs[0])
            fx->recs[fx->n_recs++] = rec;
}

static void steps(unsigned n)
{
    for (unsigned i = 0; i < n; i++) {
        clear_sent();
        assert_int_equal(ps_loop_step(&fx->loop), 0);
        if (i % 64 == 63)
            drain_records();
    }
    drain_records();
}

/* The last refusal of this request since the last call, if any. */
static bool find_refusal(uint32_t request, const char **out_reason)
{
    drain_records();
    bool is_found = false;
    for (unsigned i = 0; i < fx->n_recs; i++) {
        ps_loop_rec_t *rec = &fx->recs[i];
        if (rec->kind == PS_REC_REFUSED && rec->cond == request) {
            *out_reason = rec->reason;
            is_found = true;
            rec->kind = 0; /* seen */
        }
    }
    return is_found;
}

/* The last from -> to transition so far. */
static const ps_loop_rec_t *find_transition_rec(ps_sm_state_t from, ps_sm_state_t to)
{
    drain_records();
    const ps_loop_rec_t *found = NULL;
    for (unsigned i = 0; i < fx->n_recs; i++)
        if (fx->recs[i].kind == PS_REC_TRANSITION && fx->recs[i].from_state == from &&
            fx->recs[i].state == to)
            found = &fx->recs[i];
    return found;
}

/* Bring the robot to ACTIVE: replies fresh, START, ramp. */
static void go_active(void)
{
    steps(20);
    assert_int_equal(fx->loop.state, PS_SM_STANDBY);
    ps_loop_request(&fx->loop, PS_SM_C_REQ_START);
    steps(1);
    assert_int_equal(fx->loop.state, PS_SM_RAMP);
    steps((unsigned)(fx->robot.control.ramp_s * 1000) + 1);
    assert_int_equal(fx->loop.state, PS_SM_ACTIVE);
}

/* Decode the last command for joint j among this tick's frames. */
static bool last_command(uint32_t j, ps_mit_cmd_t *out)
{
    const ps_act_cfg_t *jc = &fx->robot.act[j];
    const fake_bus_t *b = &fx->buses[jc->bus_idx];
    for (uint32_t i = 0; i < b->n_sent; i++)
        if (b->sent[i].id == jc->can_id &&
            ps_mit_decode_cmd(&jc->wire, b->sent[i].data, b->sent[i].len, out) == 0)
            return true;
    return false;
}

/* ---- pacing ------------------------------------------------------------- */

static void test_loop_step_on_time_sleeps_on_grid(void **state)
{
    (void)state;
    steps(100);
    assert_int_equal(fx->clock.n_sleep_calls, 100);
    for (size_t i = 0; i < 100; i++)
        assert_int_equal(fx->clock.sleep_deadlines_ns[i], START_NS + (int64_t)i * PERIOD_NS);
    assert_int_equal(fx->loop.pacer.n_overruns, 0);
    assert_int_equal(fx->loop.perf[PS_STAGE_WAKE].n, 100);
    assert_int_equal(fx->loop.perf[PS_STAGE_TICK].n, 100);
}

static void test_loop_step_long_tick_counts_overrun_keeps_grid(void **state)
{
    (void)state;
    steps(10);
    fx->policy_extra_ns = 3 * PERIOD_NS + PERIOD_NS / 2; /* next policy tick takes 3.5 periods */
    steps(fx->loop.policy_div);                          /* reaches a policy tick */
    fx->policy_extra_ns = 0;
    steps(5);
    assert_int_equal(fx->loop.pacer.n_overruns, 1);
    /* the tick began on its deadline D(k) and ended at D(k) + 3.5 P: D(k+1),
     * D(k+2) and D(k+3) are gone */
    assert_int_equal(fx->loop.pacer.n_missed, 3);
    size_t n = fx->clock.n_sleep_calls;
    for (size_t i = 0; i < n; i++)
        assert_int_equal((fx->clock.sleep_deadlines_ns[i] - START_NS) % PERIOD_NS, 0);
}

static void test_loop_policy_runs_at_policy_rate(void **state)
{
    (void)state;
    steps(1000);
    assert_int_equal(fx->loop.counters.n_policy_runs,
                     1000 / (fx->robot.control.servo_hz / fx->robot.control.policy_hz));
}

/* ---- states and watchdogs ----------------------------------------------- */

/* Steps until joint j's next command of this tick is seen (at most its rate_div). */
static bool next_command(uint32_t j, ps_mit_cmd_t *cmd)
{
    for (uint32_t t = 0; t < fx->robot.act[j].rate_div; t++) {
        steps(1);
        if (last_command(j, cmd))
            return true;
    }
    return false;
}

static void test_loop_start_then_ramp_reaches_active_with_gains(void **state)
{
    (void)state;
    go_active();
    steps(20);
    /* Every joint is commanded within its own rate_div ticks; each command
     * must be seen (a joint that got none would pass a check that skips it). */
    unsigned n_checked = 0;
    for (uint32_t j = 0; j < fx->robot.n_joints; j++) {
        ps_mit_cmd_t cmd;
        if (!next_command(j, &cmd))
            fail_msg("joint %s: no command in %u ticks", fx->robot.joint_name[j],
                     fx->robot.act[j].rate_div);
        const ps_act_cfg_t *jc = &fx->robot.act[j];
        const ps_servo_joint_cfg_t *jc_s = &fx->robot.servo[j];
        float kp_step = jc->wire.kp_max_nm_rad / 4095.0f;
        assert_float_equal(cmd.kp_nm_rad, jc_s->kp_nm_rad, kp_step);
        assert_float_equal(cmd.p_rad, jc_s->stance_rad, 0.01);
        n_checked++;
    }
    assert_int_equal(n_checked, fx->robot.n_joints);
    /* the heartbeat beats: a new level every tick */
    const uint64_t e0 = fx->n_hb_edges;
    steps(4);
    assert_int_equal(fx->n_hb_edges - e0, 4);
}

static void test_loop_start_without_replies_refused(void **state)
{
    (void)state;
    for (uint32_t j = 0; j < fx->robot.n_joints; j++)
        fx->is_mute[j] = true;
    steps(20);
    ps_loop_request(&fx->loop, PS_SM_C_REQ_START);
    steps(1);
    assert_int_equal(fx->loop.state, PS_SM_STANDBY);
    const char *reason = NULL;
    assert_true(find_refusal(PS_SM_C_REQ_START, &reason));
    assert_non_null(reason);
    assert_int_equal(fx->loop.counters.n_refused, 1);
}

/* HOLD: stiff at q_rad with the configured gains. */
static void assert_holding(uint32_t j, float q_rad)
{
    ps_mit_cmd_t cmd;
    assert_true(next_command(j, &cmd));
    const ps_servo_joint_cfg_t *sj = &fx->robot.servo[j];
    float lsb[5]; /* one step of each field on the wire: q, qd, kp, kd, tau */
    ps_act_joint_lsb(&fx->robot.act[j], lsb);
    assert_float_equal(cmd.kp_nm_rad, sj->kp_nm_rad, lsb[2]);
    assert_float_equal(cmd.kd_nm_s_rad, sj->kd_nm_s_rad, lsb[3]);
    assert_float_equal(cmd.p_rad, q_rad, 0.001);
    assert_float_equal(cmd.t_ff_nm, 0.0f, lsb[4]);
}

static void assert_damping_limp(uint32_t j)
{
    ps_mit_cmd_t cmd;
    assert_true(next_command(j, &cmd));
    assert_float_equal(cmd.kp_nm_rad, 0.0f, 1e-6);
    assert_float_equal(cmd.kd_nm_s_rad, fx->robot.servo_common.damping_kd_nm_s_rad, 0.01);
}

/* A drive that stops answering while the others still do: HOLD (stiff at the
 * last valid targets), caused by REPLY_STALE; after hold_s, DAMPING. */
static void test_loop_stale_reply_in_active_holds_then_damps(void **state)
{
    (void)state;
    fx->policy_offset_rad = 0.03f; /* targets off the stance and off the replies */
    go_active();
    fx->is_mute[3] = true;
    const ps_act_cfg_t *jc = &fx->robot.act[3];
    unsigned timeout_ticks = (unsigned)(jc->rate_div + fx->robot.control.reply_timeout_s * 1000);
    steps(timeout_ticks - 1);
    assert_int_equal(fx->loop.state, PS_SM_ACTIVE);
    steps(3);
    assert_int_equal(fx->loop.state, PS_SM_HOLD);
    const ps_loop_rec_t *rec = find_transition_rec(PS_SM_ACTIVE, PS_SM_HOLD);
    assert_non_null(rec);
    assert_true((rec->cond & PS_SM_C_REPLY_STALE) != 0u);
    assert_holding(0, fx->robot.servo[0].stance_rad + 0.03f);
    steps((unsigned)(fx->robot.control.hold_s * 1000) - 10);
    assert_int_equal(fx->loop.state, PS_SM_HOLD); /* the mute drive changes nothing here */
    steps(20);
    assert_int_equal(fx->loop.state, PS_SM_DAMPING);
    rec = find_transition_rec(PS_SM_HOLD, PS_SM_DAMPING);
    assert_non_null(rec);
    assert_true((rec->cond & PS_SM_C_HOLD_DONE) != 0u);
    assert_damping_limp(0);
}

static void test_loop_stale_imu_in_active_holds(void **state)
{
    (void)state;
    go_active();
    fx->is_imu_mute = true;
    steps((unsigned)(fx->robot.control.imu_timeout_s * 1000) + fx->robot.imu.rate_div + 2);
    assert_int_equal(fx->loop.state, PS_SM_HOLD);
}

/* A NaN target is never sent; the robot holds the last valid targets. */
static void test_loop_nan_target_holds_last_valid_targets(void **state)
{
    (void)state;
    fx->policy_offset_rad = 0.02f;
    go_active();
    fx->policy_value = NAN;
    steps(fx->loop.policy_div + 2);
    assert_int_equal(fx->loop.state, PS_SM_HOLD);
    assert_true(fx->loop.counters.n_target_invalid > 0);
    assert_int_equal(fx->loop.counters.n_cmd_replaced, 0);
    assert_holding(0, fx->robot.servo[0].stance_rad + 0.02f);
}

/* A late step: HOLD, at the targets of the last step that was on time (the
 * late one's are not trusted as the pose to hold). */
static void test_loop_policy_late_holds_last_timely_targets(void **state)
{
    (void)state;
    fx->policy_offset_rad = 0.02f;
    go_active();
    fx->policy_offset_rad = 0.05f; /* what the late step asks for */
    fx->policy_extra_ns = ps_s_to_ns(fx->robot.control.policy_deadline_s) + 1000;
    steps(fx->loop.policy_div + 1);
    fx->policy_extra_ns = 0;
    assert_int_equal(fx->loop.state, PS_SM_HOLD);
    assert_int_equal(fx->loop.counters.n_policy_late, 1);
    assert_holding(0, fx->robot.servo[0].stance_rad + 0.02f);
}

/* overrun_limit overruns within overrun_window_s: OVERRUN, HOLD. Fewer, or
 * as many spread wider than the window, do not. */
static void test_loop_repeated_overruns_hold(void **state)
{
    (void)state;
    go_active();
    const ps_control_cfg_t *c = &fx->robot.control;
    const unsigned window_ticks = (unsigned)(c->overrun_window_s * 1000);
    /* limit - 1 overruns in a row: nothing */
    fx->read_extra_ns = PERIOD_NS + PERIOD_NS / 2;
    steps(c->overrun_limit - 1);
    fx->read_extra_ns = 0;
    steps(5);
    assert_int_equal(fx->loop.state, PS_SM_ACTIVE);
    /* one more after the window has passed: still limit - 1 within it */
    steps(window_ticks);
    fx->read_extra_ns = PERIOD_NS + PERIOD_NS / 2;
    steps(1);
    fx->read_extra_ns = 0;
    steps(5);
    assert_int_equal(fx->loop.state, PS_SM_ACTIVE);
    /* limit within the window: HOLD, caused by OVERRUN */
    fx->read_extra_ns = PERIOD_NS + PERIOD_NS / 2;
    steps(c->overrun_limit);
    fx->read_extra_ns = 0;
    steps(2);
    assert_int_equal(fx->loop.state, PS_SM_HOLD);
    const ps_loop_rec_t *rec = find_transition_rec(PS_SM_ACTIVE, PS_SM_HOLD);
    assert_non_null(rec);
    assert_true((rec->cond & PS_SM_C_OVERRUN) != 0u);
    assert_int_equal(fx->loop.counters.n_policy_late, 0);
}

/* A fall while holding damps: stiff joints do not help a falling robot. */
static void test_loop_fall_in_hold_damps(void **state)
{
    (void)state;
    go_active();
    fx->is_mute[3] = true;
    steps(20);
    assert_int_equal(fx->loop.state, PS_SM_HOLD);
    fx->is_imu_tipped = true; /* the tilt estimate runs towards 90 degrees */
    unsigned n = 0;
    while (fx->loop.state == PS_SM_HOLD && n < 3000) {
        steps(10);
        n += 10;
    }
    assert_int_equal(fx->loop.state, PS_SM_DAMPING);
    assert_true(n < 3000); /* well before hold_s (10 s) */
    const ps_loop_rec_t *rec = find_transition_rec(PS_SM_HOLD, PS_SM_DAMPING);
    assert_non_null(rec);
    assert_true((rec->cond & PS_SM_C_FALL) != 0u);
    assert_true(fx->loop.counters.has_fallen);
    assert_damping_limp(0);
}

/* Frames a bus would not queue are a condition: HOLD, caused by TX_REFUSED. */
static void test_loop_tx_refused_in_active_holds(void **state)
{
    (void)state;
    go_active();
    fx->buses[1].n_refuse_batches = 1;
    steps(3);
    assert_int_equal(fx->loop.state, PS_SM_HOLD);
    const ps_loop_rec_t *rec = find_transition_rec(PS_SM_ACTIVE, PS_SM_HOLD);
    assert_non_null(rec);
    assert_true((rec->cond & PS_SM_C_TX_REFUSED) != 0u);
    assert_true(fx->loop.counters.n_tx_refused > 0);
}

/* After a transient fault the operator resumes: START from HOLD ramps back
 * to ACTIVE; while the fault is still there it is refused. */
static void test_loop_hold_start_resumes_when_fault_gone(void **state)
{
    (void)state;
    go_active();
    fx->is_imu_mute = true;
    steps((unsigned)(fx->robot.control.imu_timeout_s * 1000) + fx->robot.imu.rate_div + 2);
    assert_int_equal(fx->loop.state, PS_SM_HOLD);
    ps_loop_request(&fx->loop, PS_SM_C_REQ_START);
    steps(1);
    assert_int_equal(fx->loop.state, PS_SM_HOLD);
    const char *reason = NULL;
    assert_true(find_refusal(PS_SM_C_REQ_START, &reason));
    assert_string_equal(reason, "start refused: IMU data stale");
    fx->is_imu_mute = false;
    steps(3);
    ps_loop_request(&fx->loop, PS_SM_C_REQ_START);
    steps(1);
    assert_int_equal(fx->loop.state, PS_SM_RAMP);
    steps((unsigned)(fx->robot.control.ramp_s * 1000) + 1);
    assert_int_equal(fx->loop.state, PS_SM_ACTIVE);
}

/* Entering RAMP resets the policy before that tick's step, and the step runs
 * on that tick even off the policy's decimation grid. */
static void test_loop_ramp_entry_resets_policy_before_step(void **state)
{
    (void)state;
    steps(27); /* replies fresh (go_active waits 20), and off the policy grid (div 20) */
    const uint64_t runs = fx->loop.counters.n_policy_runs;
    ps_loop_request(&fx->loop, PS_SM_C_REQ_START);
    steps(1);
    assert_int_equal(fx->loop.state, PS_SM_RAMP);
    assert_int_equal(fx->n_policy_resets, 1);
    assert_int_equal(fx->loop.counters.n_policy_runs, runs + 1);
    assert_int_equal(fx->n_steps_after_reset, 1);
    assert_int_equal(fx->state_at_first_step, PS_SM_RAMP);
}

/* With a separate deadline clock (CPU time in lockstep): a policy that was
 * preempted is not late, one that computed too long is. */
static void test_loop_policy_deadline_on_deadline_clock(void **state)
{
    (void)state;
    static ps_loop_t loop2;
    ps_clock_fake_init(&fx->cpu_clock, 0);
    ps_loop_cfg_t lc = fx->loop.cfg;
    lc.deadline_clock = &fx->cpu_clock.clock;
    assert_int_equal(ps_loop_init(&loop2, &lc), 0);
    assert_int_equal(ps_loop_start(&loop2, fx->clock.now_ns), 0);
    fx->policy_extra_ns = ps_s_to_ns(fx->robot.control.policy_deadline_s) + 1000;
    fx->is_policy_preempted = true;
    for (unsigned i = 0; i < loop2.policy_div + 1; i++)
        assert_int_equal(ps_loop_step(&loop2), 0);
    assert_int_equal(loop2.counters.n_policy_late, 0);
    fx->is_policy_preempted = false;
    for (unsigned i = 0; i < loop2.policy_div; i++)
        assert_int_equal(ps_loop_step(&loop2), 0);
    assert_int_equal(loop2.counters.n_policy_late, 1);
}

static void test_loop_estop_input_latches_estop_sends_exit(void **state)
{
    (void)state;
    go_active();
    fx->is_estop_pressed = true;
    uint32_t n_exit = 0;
    for (unsigned t = 0; t < 20; t++) {
        steps(1);
        for (uint32_t b = 0; b < fx->board.n_buses; b++)
            for (uint32_t i = 0; i < fx->buses[b].n_sent; i++)
                if (ps_mit_classify_special(fx->buses[b].sent[i].data, 8) == PS_MIT_SPECIAL_EXIT)
                    n_exit++;
    }
    assert_int_equal(fx->loop.state, PS_SM_ESTOP);
    /* the heartbeat holds still in ESTOP, so the relay drops the power */
    const uint64_t e0 = fx->n_hb_edges, c0 = fx->n_hb_calls;
    steps(5);
    assert_int_equal(fx->n_hb_edges, e0);
    assert_int_equal(fx->n_hb_calls, c0);
    assert_int_equal(n_exit, fx->robot.n_joints);
    /* reset refused while pressed, accepted once released */
    ps_loop_request(&fx->loop, PS_SM_C_REQ_RESET);
    steps(1);
    const char *reason = NULL;
    assert_true(find_refusal(PS_SM_C_REQ_RESET, &reason));
    assert_int_equal(fx->loop.state, PS_SM_ESTOP);
    fx->is_estop_pressed = false;
    steps(5);
    assert_int_equal(fx->loop.state, PS_SM_ESTOP); /* latched */
    ps_loop_request(&fx->loop, PS_SM_C_REQ_RESET);
    steps(1);
    assert_int_equal(fx->loop.state, PS_SM_STANDBY);
}

/* The tap (the flight recorder's hook) runs once per tick, after it, and
 * sees what the tick did. */
static void tap(void *ctx, const ps_loop_t *loop)
{
    fixture_t *f = ctx;
    f->n_taps++;
    f->tap_tick = loop->counters.n_ticks;
    f->tap_n_cmd_sent = 0;
    for (uint32_t j = 0; j < loop->meas.n_joints; j++)
        f->tap_n_cmd_sent += loop->last.is_cmd_sent[j];
    f->tap_saw_button |= loop->last.is_button_pressed;
    for (int st = PS_STAGE_READ; st <= PS_STAGE_TICK; st++)
        if (st != PS_STAGE_POLICY && loop->last.stage_ns[st] < 0)
            f->tap_stages_ok = false;
}

static void test_loop_tap_once_per_tick_sees_the_tick(void **state)
{
    (void)state;
    fx->loop.cfg.tap = (ps_loop_tap_t){.on_tick = tap, .ctx = fx};
    fx->tap_stages_ok = true;
    go_active();
    const uint64_t n0 = fx->n_taps;
    steps(50);
    assert_int_equal(fx->n_taps - n0, 50);
    assert_int_equal(fx->tap_tick, fx->loop.counters.n_ticks);
    assert_true(fx->tap_stages_ok);
    assert_true(fx->tap_n_cmd_sent > 0); /* the joints due on the last tick */
    assert_false(fx->tap_saw_button);
    fx->is_button_latched = true;
    steps(1);
    assert_true(fx->tap_saw_button);
    assert_true(fx->loop.perf[PS_STAGE_TAP].n >= 51);
    assert_int_equal(fx->loop.counters.n_gpio_errors, 0);
}

static void test_loop_gpio_error_counts_as_estop(void **state)
{
    (void)state;
    go_active();
    fx->has_gpio_error = true;
    steps(1);
    assert_int_equal(fx->loop.state, PS_SM_ESTOP);
    assert_int_equal(fx->loop.counters.n_gpio_errors, 1);
}

/* A heartbeat that cannot be written lets the relay cut the drives' power:
 * ESTOP the next tick, as an unreadable e-stop input does. In ESTOP the
 * heartbeat is not written; a reset works once it can be written again, and
 * one that cannot goes straight back to ESTOP. */
static void test_loop_heartbeat_write_error_estops_reset_retries(void **state)
{
    (void)state;
    go_active();
    fx->has_heartbeat_error = true;
    steps(1);
    assert_int_equal(fx->loop.state, PS_SM_ACTIVE); /* the failed write is this tick's last act */
    steps(1);
    assert_int_equal(fx->loop.state, PS_SM_ESTOP);
    assert_true((fx->loop.last.cond & PS_SM_C_ESTOP_INPUT) != 0);
    const uint64_t n_calls = fx->n_hb_calls;
    steps(5);
    assert_int_equal(fx->n_hb_calls, n_calls); /* not written in ESTOP */
    ps_loop_request(&fx->loop, PS_SM_C_REQ_RESET);
    steps(1);
    assert_int_equal(fx->loop.state, PS_SM_STANDBY);
    steps(1);
    assert_int_equal(fx->loop.state, PS_SM_ESTOP); /* still failing: back */
    fx->has_heartbeat_error = false;
    ps_loop_request(&fx->loop, PS_SM_C_REQ_RESET);
    steps(3);
    assert_int_equal(fx->loop.state, PS_SM_STANDBY);
}

/* The torque budget of a warm drive: whole up to 15 degC under its
 * temp_max_c, then linearly down to half at 5 degC under it, half beyond;
 * a temperature never reported (NaN) derates nothing. */
static void test_loop_torque_scale_derates_in_band(void **state)
{
    (void)state;
    const float tmax = 90.0f;
    /* The defaults (the robot file's when it names none: tests/test_config.c) */
    const ps_control_cfg_t d = {.derate_band_c = PS_LOOP_DEFAULT_DERATE_BAND_C,
                                .hot_margin_c = PS_LOOP_DEFAULT_HOT_MARGIN_C,
                                .derate_min = PS_LOOP_DEFAULT_DERATE_MIN};
    const ps_control_cfg_t *c = &d;
    assert_float_equal(c->derate_band_c, 15.0f, 0.0f);
    assert_float_equal(c->hot_margin_c, 5.0f, 0.0f);
    assert_float_equal(c->derate_min, 0.5f, 0.0f);
    assert_float_equal(ps_loop_torque_scale(c, 25.0f, tmax), 1.0f, 0.0f);
    assert_float_equal(ps_loop_torque_scale(c, 75.0f, tmax), 1.0f, 1e-6f);
    assert_float_equal(ps_loop_torque_scale(c, 80.0f, tmax), 0.75f, 1e-6f);
    assert_float_equal(ps_loop_torque_scale(c, 84.0f, tmax), 0.55f, 1e-6f);
    assert_float_equal(ps_loop_torque_scale(c, 85.0f, tmax), 0.5f, 0.0f);
    assert_float_equal(ps_loop_torque_scale(c, 120.0f, tmax), 0.5f, 0.0f);
    assert_float_equal(ps_loop_torque_scale(c, NAN, tmax), 1.0f, 0.0f);
    for (float t = 70.0f; t < 90.0f; t += 0.25f) /* never rises with temperature */
        assert_true(ps_loop_torque_scale(c, t + 0.25f, tmax) <= ps_loop_torque_scale(c, t, tmax));
    /* Other settings: from 30 degC under down to 0.3 at 10 degC under. */
    ps_control_cfg_t o = *c;
    o.derate_band_c = 30.0f;
    o.hot_margin_c = 10.0f;
    o.derate_min = 0.3f;
    assert_float_equal(ps_loop_torque_scale(&o, 60.0f, tmax), 1.0f, 0.0f);
    assert_float_equal(ps_loop_torque_scale(&o, 70.0f, tmax), 0.65f, 1e-6f);
    assert_float_equal(ps_loop_torque_scale(&o, 80.0f, tmax), 0.3f, 0.0f);
    o.hot_margin_c = 0.0f; /* damping only at temp_max_c itself */
    assert_float_equal(ps_loop_torque_scale(&o, 90.0f, tmax), 0.3f, 0.0f);
    assert_float_equal(ps_loop_torque_scale(&o, 75.0f, tmax), 0.65f, 1e-6f);
}

static void test_loop_drive_fault_estops(void **state)
{
    (void)state;
    go_active();
    fx->fault[5] = PS_MIT_FAULT_OVERCURRENT;
    steps(fx->robot.act[5].rate_div + 2);
    assert_int_equal(fx->loop.state, PS_SM_ESTOP);
}

static void test_loop_bus_off_estops(void **state)
{
    (void)state;
    go_active();
    fx->buses[1].is_bus_off = true;
    steps(1);
    assert_int_equal(fx->loop.state, PS_SM_ESTOP);
}

static void test_loop_run_until_end_goes_through_damping_to_standby(void **state)
{
    (void)state;
    go_active();
    int64_t end = fx->loop.pacer.next_ns + 100 * PERIOD_NS;
    assert_int_equal(ps_loop_run(&fx->loop, fx->loop.pacer.next_ns, end), 0);
    assert_int_equal(fx->loop.state, PS_SM_STANDBY);
    ps_loop_rec_t rec;
    ps_sm_state_t seen[8];
    unsigned n = 0;
    while (ps_ring_pop(&fx->ring, &rec) == 0)
        if (rec.kind == PS_REC_TRANSITION && n < 8)
            seen[n++] = (ps_sm_state_t)rec.state;
    assert_true(n >= 2);
    assert_int_equal(seen[n - 2], PS_SM_DAMPING);
    assert_int_equal(seen[n - 1], PS_SM_STANDBY);
}

/* The end of the run is not an operator's stop: one Ctrl-C while it brakes
 * does not turn the braking into an e-stop. */
static void test_loop_run_end_then_one_ctrl_c_still_damps(void **state)
{
    (void)state;
    go_active();
    fx->is_ctrl_c_in_damping = true;
    int64_t end = fx->loop.pacer.next_ns + 50 * PERIOD_NS;
    assert_int_equal(ps_loop_run(&fx->loop, fx->loop.pacer.next_ns, end), 0);
    assert_false(fx->is_ctrl_c_in_damping); /* it was pressed */
    assert_int_equal(fx->loop.state, PS_SM_STANDBY);
}

static void test_loop_second_stop_request_estops(void **state)
{
    (void)state;
    go_active();
    ps_loop_request_stop(&fx->loop);
    steps(1);
    assert_int_equal(fx->loop.state, PS_SM_DAMPING);
    ps_loop_request_stop(&fx->loop);
    steps(1);
    assert_int_equal(fx->loop.state, PS_SM_ESTOP);
    assert_true(ps_loop_is_stopped(&fx->loop));
}

/* ---- the bus schedule --------------------------------------------------- */

static void test_loop_commands_each_joint_at_its_rate(void **state)
{
    (void)state;
    steps(64); /* ENTER frames go out first, on each joint's first due tick */
    uint32_t n_cmd[PS_MAX_JOINTS] = {0};
    for (unsigned t = 0; t < 200; t++) {
        steps(1);
        for (uint32_t j = 0; j < fx->robot.n_joints; j++) {
            ps_mit_cmd_t cmd;
            n_cmd[j] += last_command(j, &cmd) ? 1u : 0u;
        }
    }
    for (uint32_t j = 0; j < fx->robot.n_joints; j++)
        assert_int_equal(n_cmd[j], 200 / fx->robot.act[j].rate_div);
}

/* ---- findings of the review: each a regression test ------------------------ */

static uint32_t count_special(int which)
{
    uint32_t n = 0;
    for (uint32_t b = 0; b < fx->board.n_buses; b++)
        for (uint32_t i = 0; i < fx->buses[b].n_sent; i++)
            if (ps_mit_classify_special(fx->buses[b].sent[i].data, 8) == which)
                n++;
    return n;
}

/* A bus that refuses the batch carrying ENTER must not leave the loop
 * believing the drive is enabled: ENTER goes out again. */
static void test_loop_refused_enter_is_sent_again(void **state)
{
    (void)state;
    fx->buses[0].n_refuse_batches = 1; /* the first batch on bus 0 carries ENTERs */
    uint32_t n_enter = 0;
    for (unsigned t = 0; t < 64; t++) {
        steps(1);
        n_enter += count_special(PS_MIT_SPECIAL_ENTER);
    }
    uint32_t n_on_bus0 = 0;
    for (uint32_t j = 0; j < fx->robot.n_joints; j++)
        n_on_bus0 += fx->robot.act[j].bus_idx == 0;
    /* every joint's ENTER got through once, those of the refused batch included */
    assert_int_equal(n_enter, fx->robot.n_joints);
    assert_true(n_on_bus0 > 0);
    assert_true(fx->loop.counters.n_tx_refused >= 1);
    for (uint32_t j = 0; j < fx->robot.n_joints; j++)
        assert_true(fx->loop.is_entered[j]);
}

/* A stop that lands in the tick where START is accepted still stops, through
 * DAMPING, and two stop signals before one tick are one stop, not e-stop. */
static void test_loop_stop_with_start_in_same_tick_still_stops(void **state)
{
    (void)state;
    steps(20);
    ps_loop_request(&fx->loop, PS_SM_C_REQ_START);
    ps_loop_request_stop(&fx->loop);
    ps_loop_request_stop(&fx->loop);
    for (unsigned t = 0; t < 3000 && !ps_loop_is_stopped(&fx->loop); t++)
        steps(1);
    assert_true(ps_loop_is_stopped(&fx->loop));
    assert_int_equal(fx->loop.state, PS_SM_STANDBY);
    ps_loop_request(&fx->loop, PS_SM_C_REQ_START); /* stopping: no new start */
    steps(2);
    assert_int_equal(fx->loop.state, PS_SM_STANDBY);
}

static void test_loop_saturated_imu_sample_rejected(void **state)
{
    (void)state;
    go_active();
    unsigned timeout_ticks =
        (unsigned)(fx->robot.control.imu_timeout_s * 1000) + fx->robot.imu.rate_div + 2;
    fx->imu_status = PS_IMU_STATUS_ACCEL_SAT; /* an impact: the gyro still counts */
    steps(timeout_ticks);
    assert_int_equal(fx->loop.state, PS_SM_ACTIVE);
    assert_int_equal(fx->loop.counters.n_imu_rejected, 0);
    fx->imu_status = PS_IMU_STATUS_GYRO_SAT;
    steps(timeout_ticks);
    assert_true(fx->loop.counters.n_imu_rejected > 0);
    assert_int_equal(fx->loop.state, PS_SM_HOLD); /* no valid IMU: stale */
}

static void test_loop_frozen_imu_seq_goes_stale(void **state)
{
    (void)state;
    go_active();
    fx->is_imu_frozen = true;
    steps((unsigned)(fx->robot.control.imu_timeout_s * 1000) + fx->robot.imu.rate_div + 2);
    assert_true(fx->loop.counters.n_imu_repeated > 0);
    assert_int_equal(fx->loop.state, PS_SM_HOLD);
}

/* The same six values with an advancing seq: from the imu.frozen_samples-th
 * such sample on each is refused, so the IMU goes stale and ACTIVE holds;
 * the samples before it still count (ps1's default: 50 at 1 kHz). */
static void test_loop_frozen_imu_values_go_stale(void **state)
{
    (void)state;
    go_active();
    const uint32_t n = fx->robot.imu.frozen_samples;
    assert_int_equal(n, 50);
    fx->is_imu_values_frozen = true;
    steps(n - 1u);
    assert_int_equal(fx->loop.counters.n_imu_frozen, 0);
    assert_int_equal(fx->loop.state, PS_SM_ACTIVE);
    steps(1);
    assert_int_equal(fx->loop.counters.n_imu_frozen, 1);
    steps((unsigned)(fx->robot.control.imu_timeout_s * 1000) + fx->robot.imu.rate_div + 2);
    assert_int_equal(fx->loop.state, PS_SM_HOLD);
    assert_int_equal(fx->loop.counters.n_imu_repeated, 0);
    assert_int_equal(fx->loop.counters.n_imu_rejected, 0);
}

/* A reply whose position jumped farther than its joint can move since the
 * last one is refused and counted; one such reply changes nothing, a run of
 * them leaves the joint stale (HOLD, as a silent drive); once its bound has
 * grown past the jump, the position counts again. */
static void test_loop_implausible_reply_refused_run_goes_stale(void **state)
{
    (void)state;
    go_active();
    const uint32_t j = 3; /* l_knee, every 2 ticks */
    assert_int_equal(fx->loop.counters.n_reply_implausible, 0);
    fx->reply_jump_rad[j] = 1.0f; /* 1 rad in 2 ms: 500 rad/s */
    for (unsigned i = 0; i < 4 && fx->loop.counters.n_reply_implausible == 0; i++)
        steps(1); /* the reply to the next command carries it */
    fx->reply_jump_rad[j] = 0.0f;
    assert_int_equal(fx->loop.counters.n_reply_implausible, 1);
    assert_true(fx->loop.meas.joints[j].q_rad < fx->robot.servo[j].stance_rad + 0.01f);
    steps(20);
    assert_int_equal(fx->loop.state, PS_SM_ACTIVE);
    assert_int_equal(fx->loop.counters.n_reply_implausible, 1);
    const uint64_t n_bad = fx->loop.counters.n_rx_bad;
    fx->reply_jump_rad[j] = 1.0f; /* from now on */
    const unsigned stale_ticks =
        (unsigned)(fx->robot.control.reply_timeout_s * 1000) + fx->robot.act[j].rate_div + 2;
    steps(stale_ticks);
    assert_int_equal(fx->loop.state, PS_SM_HOLD);
    assert_true(fx->loop.counters.n_reply_implausible >= 5);
    assert_true(fx->loop.counters.n_rx_bad >= n_bad + 5);
    /* The bound, 2 x 20.9 rad/s (rs04's no-load speed) over the time since the
     * last reply taken, passes 1 rad after about 24 ms: taken again. */
    steps(30);
    assert_float_equal(fx->loop.meas.joints[j].q_rad, fx->robot.servo[j].stance_rad + 1.0f, 0.01f);
}

static void test_loop_init_rejects_unsafe_tables(void **state)
{
    (void)state;
    static ps_loop_t other;
    ps_loop_cfg_t lc = fx->loop.cfg;
    ps_robot_cfg_t robot = fx->robot;
    ps_board_cfg_t board = fx->board;
    lc.robot = &robot;
    lc.board = &board;
    board.n_buses = 3; /* joints on bus 3 now name a bus the board lacks */
    assert_int_equal(ps_loop_init(&other, &lc), -EINVAL);
    board = fx->board;
    robot.act[2].rate_div = 0;
    assert_int_equal(ps_loop_init(&other, &lc), -EINVAL);
    robot = fx->robot;
    robot.control.ramp_s = 0.0f;
    assert_int_equal(ps_loop_init(&other, &lc), -EINVAL);
    robot = fx->robot;
    robot.control.derate_band_c = robot.control.hot_margin_c; /* a band of no width */
    assert_int_equal(ps_loop_init(&other, &lc), -EINVAL);
    robot = fx->robot;
    robot.control.hot_margin_c = -1.0f;
    assert_int_equal(ps_loop_init(&other, &lc), -EINVAL);
    robot = fx->robot;
    robot.control.derate_min = 0.0f;
    assert_int_equal(ps_loop_init(&other, &lc), -EINVAL);
    robot.control.derate_min = 1.5f;
    assert_int_equal(ps_loop_init(&other, &lc), -EINVAL);
    robot.control.derate_min = NAN;
    assert_int_equal(ps_loop_init(&other, &lc), -EINVAL);
    robot = fx->robot;
    lc.gpio.ops = NULL;
    assert_int_equal(ps_loop_init(&other, &lc), -EINVAL);
    lc.gpio = fx->loop.cfg.gpio;
    assert_int_equal(ps_loop_init(&other, &lc), 0);
}

/* A babbling node cannot hold the tick in READ: the drain stops after
 * PS_LOOP_MAX_RX_BATCHES batches per bus and says so. */
static void test_loop_babbling_bus_read_capped(void **state)
{
    (void)state;
    fx->buses[2].is_babbling = true;
    steps(3);
    assert_int_equal(fx->loop.counters.n_rx_capped, 3);
    assert_int_equal(fx->loop.counters.n_rx_unknown,
                     3 * PS_LOOP_MAX_RX_BATCHES *
                         (sizeof(fx->loop.rx_buf) / sizeof(fx->loop.rx_buf[0])));
    assert_int_equal(fx->loop.counters.n_ticks, 3);
}

static void test_loop_bad_sff_id_counted_not_indexed(void **state)
{
    (void)state;
    fake_bus_t *b = &fx->buses[0];
    ps_can_frame_t *f = &b->pending[b->n_pending++];
    memset(f, 0, sizeof(*f));
    f->id = 0x800 + 0x101; /* masked to 11 bits it would alias reply 0x101 */
    f->len = 8;
    steps(1);
    assert_int_equal(fx->loop.counters.n_rx_bad, 1);
}

/* 29-bit and FD frames reach the loop; a 29-bit id with a reply's number is
 * not that reply (MIT replies are 11-bit), a length no frame has is bad. */
static void test_loop_ext_and_fd_frames_classified(void **state)
{
    (void)state;
    fake_bus_t *b = &fx->buses[0];
    ps_can_frame_t *f = &b->pending[b->n_pending++];
    memset(f, 0, sizeof(*f));
    f->id = 0x101; /* the number of joint 0's reply id, but 29-bit */
    f->is_ext = 1;
    f->len = 8;
    f = &b->pending[b->n_pending++];
    memset(f, 0, sizeof(*f));
    f->id = 0x101;
    f->is_fd = 1;
    f->len = 64; /* an FD frame on the reply id: no MIT reply either */
    f = &b->pending[b->n_pending++];
    memset(f, 0, sizeof(*f));
    f->id = 0x300;
    f->is_fd = 1;
    f->len = 13; /* no DLC gives 13 bytes */
    steps(1);
    assert_int_equal(fx->loop.counters.n_rx_unknown, 2);
    assert_int_equal(fx->loop.counters.n_rx_bad, 1);
}

/* A latched drive fault e-stops; the reset is accepted (the drive is
 * re-enabled in STANDBY); a drive still faulted e-stops again. */
static void test_loop_drive_fault_reset_then_back_to_estop_if_persists(void **state)
{
    (void)state;
    go_active();
    fx->fault[5] = PS_MIT_FAULT_ROTOR_OVERTEMP;
    steps(fx->robot.act[5].rate_div + 2);
    assert_int_equal(fx->loop.state, PS_SM_ESTOP);
    ps_loop_request(&fx->loop, PS_SM_C_REQ_RESET);
    steps(1);
    assert_int_equal(fx->loop.state, PS_SM_STANDBY);
    steps(30); /* ENTER, then the drive answers with its fault again */
    assert_int_equal(fx->loop.state, PS_SM_ESTOP);
    fx->fault[5] = PS_MIT_FAULT_NONE; /* cooled down */
    ps_loop_request(&fx->loop, PS_SM_C_REQ_RESET);
    steps(30);
    assert_int_equal(fx->loop.state, PS_SM_STANDBY);
    ps_loop_request(&fx->loop, PS_SM_C_REQ_START);
    steps(1);
    assert_int_equal(fx->loop.state, PS_SM_RAMP);
}

/* A drive that comes up with a latched fault (a previous run's comms loss)
 * clears it on ENTER: that must not e-stop the start, and after an e-stop
 * the replies still in flight with the old fault must not defeat the reset. */
static void test_loop_latched_fault_cleared_by_enter_no_estop(void **state)
{
    (void)state;
    fx->is_reply_late = true; /* replies sent before ENTER arrive after it */
    fx->is_fault_cleared_by_enter = true;
    fx->fault[5] = PS_MIT_FAULT_COMMS_LOST;
    steps(40);
    assert_int_equal(fx->loop.state, PS_SM_STANDBY);
    go_active();
    fx->is_fault_cleared_by_enter = false;
    fx->fault[5] = PS_MIT_FAULT_ROTOR_OVERTEMP;
    steps(fx->robot.act[5].rate_div + 2);
    assert_int_equal(fx->loop.state, PS_SM_ESTOP);
    steps(20);                            /* ESTOP keeps polling: replies carry the fault */
    fx->is_fault_cleared_by_enter = true; /* cooled down: ENTER clears it */
    ps_loop_request(&fx->loop, PS_SM_C_REQ_RESET);
    steps(40);
    assert_int_equal(fx->loop.state, PS_SM_STANDBY);
    ps_loop_request(&fx->loop, PS_SM_C_REQ_START);
    steps(1);
    assert_int_equal(fx->loop.state, PS_SM_RAMP);
}

/* The end of a run leaves the drives disabled and the heartbeat still (the
 * relay then drops the power). */
static void test_loop_run_end_releases_drives(void **state)
{
    (void)state;
    go_active();
    int64_t end = fx->loop.pacer.next_ns + 10 * PERIOD_NS;
    assert_int_equal(ps_loop_run(&fx->loop, fx->loop.pacer.next_ns, end), 0);
    uint32_t n_exit = 0;
    for (uint32_t b = 0; b < fx->board.n_buses; b++)
        n_exit += fx->buses[b].n_exit_total;
    assert_int_equal(n_exit, fx->robot.n_joints);
    const uint64_t c0 = fx->n_hb_calls;
    ps_loop_release_drives(&fx->loop);
    assert_int_equal(fx->n_hb_calls, c0);
}

/* The clock fails mid-run: one last tick in ESTOP, then the error. */
static void test_loop_run_clock_failure_estops(void **state)
{
    (void)state;
    go_active();
    static const int RC[] = {0, 0, -EIO};
    fx->clock.rc_script = RC;
    fx->clock.n_rc_script = 3;
    fx->clock.n_sleep_calls = 0;
    const uint64_t c0 = fx->n_hb_calls;
    assert_int_equal(ps_loop_run(&fx->loop, fx->loop.pacer.next_ns, 0), -EIO);
    assert_int_equal(fx->loop.state, PS_SM_ESTOP);
    /* two paced ticks beat; the last one, in ESTOP, and the release do not */
    assert_int_equal(fx->n_hb_calls - c0, 2);
}

/* ---- the candump tap ---------------------------------------------------- */

/* Every frame a bus took and every frame read reach the frame ring with its
 * bus; sent frames carry the tick's deadline, refused ones are not there,
 * and a full ring drops (counted) while the tick goes on. */
static void test_loop_frame_ring_gets_sent_and_read_frames(void **state)
{
    (void)state;
    static ps_loop_frame_rec_t storage[1024];
    ps_ring_t ring;
    assert_int_equal(ps_ring_init(&ring, storage, 1024, sizeof(storage[0])), 0);
    steps(5);
    fx->loop.cfg.frame_ring = &ring;
    fx->buses[2].n_refuse_batches = 1;
    clear_sent();
    const uint64_t rx_before = fx->loop.counters.n_rx_frames;
    const uint64_t refused_before = fx->loop.counters.n_tx_refused;
    assert_int_equal(ps_loop_step(&fx->loop), 0);
    assert_true(fx->loop.counters.n_tx_refused > refused_before);
    const int64_t deadline_ns = fx->loop.t_deadline_ns;
    size_t n_tx[PS_MAX_BUSES] = {0}, n_rx = 0;
    ps_loop_frame_rec_t rec;
    while (ps_ring_pop(&ring, &rec) == 0) {
        assert_true(rec.bus_idx < fx->board.n_buses);
        if (!rec.is_tx) {
            n_rx++;
            continue;
        }
        const fake_bus_t *b = &fx->buses[rec.bus_idx];
        const size_t i = n_tx[rec.bus_idx]++;
        assert_true(i < b->n_sent);
        assert_int_equal(rec.frame.id, b->sent[i].id);
        assert_int_equal(rec.frame.len, b->sent[i].len);
        assert_memory_equal(rec.frame.data, b->sent[i].data, b->sent[i].len);
        assert_true(rec.frame.t_ns == deadline_ns);
    }
    size_t n_sent_all = 0;
    for (uint32_t b = 0; b < fx->board.n_buses; b++) {
        assert_int_equal(n_tx[b], fx->buses[b].n_sent);
        n_sent_all += fx->buses[b].n_sent;
    }
    assert_int_equal(fx->buses[2].n_sent, 0); /* refused: sent nothing, logged nothing */
    assert_true(n_sent_all > 0);
    assert_int_equal(n_rx, fx->loop.counters.n_rx_frames - rx_before);
    assert_true(n_rx > 0);
    assert_int_equal(ps_ring_dropped(&ring), 0);
    /* nobody drains: the ring fills, the loop keeps its pace */
    for (int i = 0; i < 200; i++)
        assert_int_equal(ps_loop_step(&fx->loop), 0);
    assert_true(ps_ring_dropped(&ring) > 0);
    assert_int_equal(ps_ring_count(&ring), 1024);
    fx->loop.cfg.frame_ring = NULL;
}

/* ---- neighbours from camera perception ----------------------------------- */

static void publish_neighbours(ps_mailbox_t *mb, int64_t t_exposure_ns, uint32_t n)
{
    ps_neighbours_t *nb = ps_mailbox_write_slot(mb);
    memset(nb, 0, sizeof(*nb));
    nb->t_exposure_ns = t_exposure_ns;
    nb->n_shoulders = n;
    for (uint32_t i = 0; i < n; i++)
        nb->shoulders[i] = (ps_shoulder_t){.pos_robot_m = {1.0f, 0.1f * (float)i, 0.3f},
                                           .confidence = 1.0f,
                                           .neighbour_id = (uint16_t)(i / 2),
                                           .side = (uint8_t)(i % 2)};
    ps_mailbox_publish(mb);
}

/* The loop takes each new list, the policy sees it, and a list older than
 * camera.max_age_s becomes "no neighbour information" until a fresh one. */
static void test_loop_neighbours_taken_aged_then_stale(void **state)
{
    (void)state;
    static ps_loop_t loop2;
    static ps_neighbours_t slots[PS_MAILBOX_SLOTS];
    ps_mailbox_t mb;
    assert_int_equal(ps_mailbox_init(&mb, slots, sizeof(slots[0])), 0);
    ps_loop_cfg_t lc = fx->loop.cfg;
    lc.neighbours = &mb;
    assert_int_equal(ps_loop_init(&loop2, &lc), -EINVAL); /* the board has no camera */
    fx->board.has_perception = true;
    fx->board.perception.max_age_s = 0.05f; /* 50 ticks */
    assert_int_equal(ps_loop_init(&loop2, &lc), 0);
    assert_int_equal(ps_loop_start(&loop2, fx->clock.now_ns), 0);
    const unsigned div = loop2.policy_div;
    for (unsigned i = 0; i < div; i++)
        assert_int_equal(ps_loop_step(&loop2), 0);
    assert_false(loop2.meas.neighbours.is_valid); /* nothing yet */
    assert_int_equal(loop2.counters.n_neighbour_stale, div);
    publish_neighbours(&mb, fx->clock.now_ns, 3);
    for (unsigned i = 0; i < div; i++)
        assert_int_equal(ps_loop_step(&loop2), 0);
    assert_int_equal(loop2.counters.n_neighbour_lists, 1);
    assert_true(fx->policy_neighbours.is_valid);
    assert_int_equal(fx->policy_neighbours.n_shoulders, 3);
    assert_float_equal(fx->policy_neighbours.shoulders[2].pos_robot_m[1], 0.2f, 1e-6);
    assert_int_equal(loop2.counters.n_neighbour_stale, div);
    /* 60 ms later with no new list: stale, emptied, and so at the policy */
    for (unsigned i = 0; i < 60; i++)
        assert_int_equal(ps_loop_step(&loop2), 0);
    assert_false(loop2.meas.neighbours.is_valid);
    assert_int_equal(loop2.meas.neighbours.n_shoulders, 0);
    assert_true(loop2.meas.neighbours.age_ns > 50 * PS_NS_PER_MS);
    for (unsigned i = 0; i < div; i++)
        assert_int_equal(ps_loop_step(&loop2), 0);
    assert_false(fx->policy_neighbours.is_valid);
    assert_int_equal(fx->policy_neighbours.n_shoulders, 0);
    const uint64_t n_stale = loop2.counters.n_neighbour_stale;
    assert_true(n_stale > div);
    /* a fresh list: valid again */
    publish_neighbours(&mb, fx->clock.now_ns, 1);
    assert_int_equal(ps_loop_step(&loop2), 0);
    assert_true(loop2.meas.neighbours.is_valid);
    assert_int_equal(loop2.meas.neighbours.n_shoulders, 1);
    assert_int_equal(loop2.counters.n_neighbour_lists, 2);
    assert_int_equal(loop2.counters.n_neighbour_stale, n_stale);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup_teardown(test_loop_frame_ring_gets_sent_and_read_frames, setup,
                                        teardown),
#define T(f) cmocka_unit_test_setup_teardown(f, setup, teardown)
        T(test_loop_step_on_time_sleeps_on_grid),
        T(test_loop_step_long_tick_counts_overrun_keeps_grid),
        T(test_loop_policy_runs_at_policy_rate),
        T(test_loop_start_then_ramp_reaches_active_with_gains),
        T(test_loop_start_without_replies_refused),
        T(test_loop_stale_reply_in_active_holds_then_damps),
        T(test_loop_repeated_overruns_hold),
        T(test_loop_tx_refused_in_active_holds),
        T(test_loop_fall_in_hold_damps),
        T(test_loop_hold_start_resumes_when_fault_gone),
        T(test_loop_ramp_entry_resets_policy_before_step),
        T(test_loop_stale_imu_in_active_holds),
        T(test_loop_nan_target_holds_last_valid_targets),
        T(test_loop_policy_late_holds_last_timely_targets),
        T(test_loop_policy_deadline_on_deadline_clock),
        T(test_loop_estop_input_latches_estop_sends_exit),
        T(test_loop_gpio_error_counts_as_estop),
        T(test_loop_tap_once_per_tick_sees_the_tick),
        T(test_loop_heartbeat_write_error_estops_reset_retries),
        cmocka_unit_test(test_loop_torque_scale_derates_in_band),
        T(test_loop_drive_fault_estops),
        T(test_loop_bus_off_estops),
        T(test_loop_run_until_end_goes_through_damping_to_standby),
        T(test_loop_run_end_then_one_ctrl_c_still_damps),
        T(test_loop_second_stop_request_estops),
        T(test_loop_commands_each_joint_at_its_rate),
        T(test_loop_refused_enter_is_sent_again),
        T(test_loop_stop_with_start_in_same_tick_still_stops),
        T(test_loop_saturated_imu_sample_rejected),
        T(test_loop_frozen_imu_seq_goes_stale),
        T(test_loop_frozen_imu_values_go_stale),
        T(test_loop_implausible_reply_refused_run_goes_stale),
        T(test_loop_init_rejects_unsafe_tables),
        T(test_loop_babbling_bus_read_capped),
        T(test_loop_bad_sff_id_counted_not_indexed),
        T(test_loop_ext_and_fd_frames_classified),
        T(test_loop_drive_fault_reset_then_back_to_estop_if_persists),
        T(test_loop_latched_fault_cleared_by_enter_no_estop),
        T(test_loop_run_end_releases_drives),
        T(test_loop_run_clock_failure_estops),
        T(test_loop_neighbours_taken_aged_then_stale),
#undef T
    };
    return cmocka_run_group_tests_name("loop", tests, NULL, NULL);
}
