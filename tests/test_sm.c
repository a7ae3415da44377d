/*
 * Tests for rt/ps_sm: every edge, every request, the e-stop latch and the
 * priorities, against expectations written here from the spec (ps_sm.h and
 * docs/safety.md), never derived from the implementation's edge table.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <string.h>

#include "../rt/ps_err.h"
#include "../rt/ps_sm.h"

/* Short local names; spelled out bit by bit instead of using the header's
 * fault masks, so a wrong mask in the header shows up here. */
enum {
    START = 1u << 0,
    STOP = 1u << 1,
    RESET = 1u << 2,
    REQ_ESTOP = 1u << 3,
    ESTOP_IN = 1u << 4,
    RAMP_DONE = 1u << 5,
    DAMP_DONE = 1u << 6,
    REPLY_STALE = 1u << 7,
    IMU_STALE = 1u << 8,
    POLICY_LATE = 1u << 9,
    TARGET_INVALID = 1u << 10,
    FALL = 1u << 11,
    DRIVE_FAULT = 1u << 12,
    BUS_OFF = 1u << 13,
    OVERRUN = 1u << 14,
    TX_REFUSED = 1u << 15,
    HOLD_DONE = 1u << 16,
    DRIVE_HOT = 1u << 17,
    N_BITS = 18,
};
#define T_HARD (REQ_ESTOP | ESTOP_IN | DRIVE_FAULT | BUS_OFF)
/* A drive fault does not block a reset: the drive is re-enabled in STANDBY. */
#define T_RESET_BLOCK (REQ_ESTOP | ESTOP_IN | BUS_OFF)
/* Soft faults with the drives still taking commands: ACTIVE holds on these. */
#define T_HOLDF (REPLY_STALE | IMU_STALE | POLICY_LATE | TARGET_INVALID | OVERRUN | TX_REFUSED)
#define T_SOFT  (T_HOLDF | FALL | DRIVE_HOT)

enum {
    SB = PS_SM_STANDBY,
    RA = PS_SM_RAMP,
    AC = PS_SM_ACTIVE,
    DA = PS_SM_DAMPING,
    ES = PS_SM_ESTOP,
    HO = PS_SM_HOLD
};
#define N_STATES 6

/* Expected next state for each state and a single condition bit (column 0:
 * no condition at all). Written by hand from the rules. */
static const int EXPECT_SINGLE[N_STATES][1 + N_BITS] = {
    /*      none START STOP RESET REQ_E E_IN RDONE DDONE REPLY IMU PLATE TINV FALL DRV BUS
     *      OVERRUN TX_REF HDONE HOT */
    [SB] = {SB, RA, SB, SB, ES, ES, SB, SB, SB, SB, SB, SB, SB, ES, ES, SB, SB, SB, SB},
    [RA] = {RA, RA, DA, RA, ES, ES, AC, RA, DA, DA, DA, DA, DA, ES, ES, DA, DA, RA, DA},
    [AC] = {AC, AC, DA, AC, ES, ES, AC, AC, HO, HO, HO, HO, DA, ES, ES, HO, HO, AC, DA},
    [DA] = {DA, DA, DA, DA, ES, ES, DA, SB, DA, DA, DA, DA, DA, ES, ES, DA, DA, DA, DA},
    [ES] = {ES, ES, ES, SB, ES, ES, ES, ES, ES, ES, ES, ES, ES, ES, ES, ES, ES, ES, ES},
    [HO] = {HO, RA, DA, HO, ES, ES, HO, HO, HO, HO, HO, HO, DA, ES, ES, HO, HO, DA, DA},
};

/* Hand-picked combinations: blockers, priorities, latching. */
typedef struct {
    int from;
    uint32_t cond;
    int to;
} combo_t;

static const combo_t COMBOS[] = {
    /* start blockers */
    {SB, START | REPLY_STALE, SB},
    {SB, START | IMU_STALE, SB},
    {SB, START | DRIVE_HOT, SB}, /* a hot drive: no start */
    {SB, START | ESTOP_IN, ES},
    {SB, START | REQ_ESTOP, ES},
    {SB, START | DRIVE_FAULT, ES},
    {SB, START | BUS_OFF, ES},
    /* soft faults that do not block a start (RAMP damps on its next tick) */
    {SB, START | POLICY_LATE, RA},
    {SB, START | TARGET_INVALID, RA},
    {SB, START | FALL, RA},
    {SB, START | RAMP_DONE, RA},
    /* ramp done blocked by faults and stop */
    {RA, RAMP_DONE | REPLY_STALE, DA},
    {RA, RAMP_DONE | FALL, DA},
    {RA, RAMP_DONE | STOP, DA},
    {RA, RAMP_DONE | BUS_OFF, ES},
    {RA, RAMP_DONE | START, AC},
    /* priority: hard beats soft beats stop */
    {AC, STOP | REPLY_STALE | ESTOP_IN, ES},
    {AC, STOP | FALL, DA},
    {AC, FALL | OVERRUN, DA}, /* a fall damps even with a hold fault present */
    {AC, DRIVE_HOT | POLICY_LATE, DA}, /* so does a drive about to overheat */
    {AC, DRIVE_HOT | STOP, DA},
    {HO, DRIVE_HOT | REPLY_STALE, DA},
    {HO, START | DRIVE_HOT, DA},
    {DA, DAMP_DONE | DRIVE_HOT, SB}, /* limp in STANDBY while it cools */
    {RA, RAMP_DONE | DRIVE_HOT, DA},
    {AC, STOP | POLICY_LATE, HO},
    /* HOLD: the fault that led here changes nothing; a fall, a stop or the
     * end of the hold damps; a start resumes only with every fault gone */
    {HO, REPLY_STALE | IMU_STALE | OVERRUN, HO},
    {HO, START | REPLY_STALE, HO},
    {HO, START | POLICY_LATE, HO},
    {HO, START | FALL, DA},
    {HO, START | HOLD_DONE, DA},
    {HO, START | RAMP_DONE, RA},
    {HO, HOLD_DONE | DRIVE_FAULT, ES},
    {RA, STOP | IMU_STALE | DRIVE_FAULT, ES},
    {DA, DAMP_DONE | BUS_OFF, ES},
    {DA, DAMP_DONE | REPLY_STALE, SB},
    {DA, DAMP_DONE | STOP | START, SB},
    /* e-stop latch and reset blockers */
    {ES, RESET | ESTOP_IN, ES},
    {ES, RESET | REQ_ESTOP, ES},
    {ES, RESET | BUS_OFF, ES},
    {ES, RESET | DRIVE_FAULT, SB},
    {ES, RESET | REPLY_STALE | IMU_STALE | FALL, SB},
    {ES, RESET | START, SB},
    {ES, START | DAMP_DONE | RAMP_DONE | STOP, ES},
};

/* An independent reference model, written as priority logic rather than a
 * table, for the exhaustive sweep over every combination of bits. */
static int ref_next(int s, uint32_t c)
{
    const int hard = (c & T_HARD) != 0u;
    const int soft = (c & T_SOFT) != 0u;
    switch (s) {
    case SB:
        if (hard)
            return ES;
        if ((c & START) && !(c & (REPLY_STALE | IMU_STALE | DRIVE_HOT)))
            return RA;
        return SB;
    case RA:
        if (hard)
            return ES;
        if (soft || (c & STOP))
            return DA;
        return (c & RAMP_DONE) ? AC : RA;
    case AC:
        if (hard)
            return ES;
        if (c & (FALL | DRIVE_HOT))
            return DA;
        if (c & T_HOLDF)
            return HO;
        return (c & STOP) ? DA : AC;
    case HO:
        if (hard)
            return ES;
        if (c & (FALL | HOLD_DONE | STOP | DRIVE_HOT))
            return DA;
        if ((c & START) && !(c & T_SOFT))
            return RA;
        return HO;
    case DA:
        if (hard)
            return ES;
        return (c & DAMP_DONE) ? SB : DA;
    case ES:
        return ((c & RESET) && !(c & T_RESET_BLOCK)) ? SB : ES;
    default:
        return ES;
    }
}

static void test_ps_sm_next_single_bit_matches_expected_table(void **state)
{
    (void)state;
    for (int s = 0; s < N_STATES; s++) {
        assert_int_equal(ps_sm_next((ps_sm_state_t)s, 0u), EXPECT_SINGLE[s][0]);
        for (int b = 0; b < N_BITS; b++) {
            const ps_sm_state_t got = ps_sm_next((ps_sm_state_t)s, 1u << b);
            if ((int)got != EXPECT_SINGLE[s][1 + b])
                fail_msg("%s + %s -> %s, expected %s", ps_sm_state_name((ps_sm_state_t)s),
                         ps_sm_cond_name(1u << b), ps_sm_state_name(got),
                         ps_sm_state_name((ps_sm_state_t)EXPECT_SINGLE[s][1 + b]));
        }
    }
}

static void test_ps_sm_next_combinations_match_expected(void **state)
{
    (void)state;
    for (size_t i = 0; i < sizeof COMBOS / sizeof COMBOS[0]; i++) {
        const ps_sm_state_t got = ps_sm_next((ps_sm_state_t)COMBOS[i].from, COMBOS[i].cond);
        if ((int)got != COMBOS[i].to)
            fail_msg("combo %zu: %s cond 0x%x -> %s, expected %s", i,
                     ps_sm_state_name((ps_sm_state_t)COMBOS[i].from), COMBOS[i].cond,
                     ps_sm_state_name(got), ps_sm_state_name((ps_sm_state_t)COMBOS[i].to));
    }
}

static void test_ps_sm_next_every_bit_combination_matches_reference_model(void **state)
{
    (void)state;
    unsigned n_checked = 0;
    for (int s = 0; s < N_STATES; s++) {
        for (uint32_t c = 0; c < (1u << N_BITS); c++) {
            const int want = ref_next(s, c);
            const ps_sm_state_t got = ps_sm_next((ps_sm_state_t)s, c);
            if ((int)got != want)
                fail_msg("%s cond 0x%x -> %s, expected %s", ps_sm_state_name((ps_sm_state_t)s), c,
                         ps_sm_state_name(got), ps_sm_state_name((ps_sm_state_t)want));
            n_checked++;
        }
    }
    assert_int_equal(n_checked, N_STATES * (1u << N_BITS));
}

static void test_ps_sm_next_unknown_bits_ignored(void **state)
{
    (void)state;
    for (int s = 0; s < N_STATES; s++)
        assert_int_equal(ps_sm_next((ps_sm_state_t)s, 0xFFFC0000u), s);
}

static void test_ps_sm_next_invalid_state_estop(void **state)
{
    (void)state;
    assert_int_equal(ps_sm_next(PS_SM_STATE_COUNT, 0u), PS_SM_ESTOP);
    assert_int_equal(ps_sm_next((ps_sm_state_t)99, RESET), PS_SM_ESTOP);
    assert_int_equal(ps_sm_find_edge((ps_sm_state_t)99, T_HARD), -1);
}

static void test_ps_sm_next_estop_latched_under_every_condition(void **state)
{
    (void)state;
    /* Every condition set leaves ESTOP alone unless it holds RESET and none
     * of the reset blockers. */
    for (uint32_t c = 0; c < (1u << N_BITS); c++) {
        const int may_leave = (c & RESET) && !(c & T_RESET_BLOCK);
        assert_int_equal(ps_sm_next(PS_SM_ESTOP, c), may_leave ? PS_SM_STANDBY : PS_SM_ESTOP);
    }
    /* A held e-stop input keeps it latched tick after tick, reset or not. */
    ps_sm_state_t s = PS_SM_ESTOP;
    for (int tick = 0; tick < 100; tick++)
        s = ps_sm_next(s, ESTOP_IN | (tick % 2 ? RESET : 0u));
    assert_int_equal(s, PS_SM_ESTOP);
    /* Releasing the input alone does not unlatch; the reset does. */
    s = ps_sm_next(s, 0u);
    assert_int_equal(s, PS_SM_ESTOP);
    s = ps_sm_next(s, RESET);
    assert_int_equal(s, PS_SM_STANDBY);
}

static void test_ps_sm_next_hard_fault_from_every_state_estop(void **state)
{
    (void)state;
    const uint32_t hard_bits[] = {REQ_ESTOP, ESTOP_IN, DRIVE_FAULT, BUS_OFF};
    assert_int_equal(N_STATES, PS_SM_STATE_COUNT);
    for (int s = 0; s < N_STATES; s++)
        for (size_t h = 0; h < 4; h++)
            /* with every other bit set as well: hard always wins */
            assert_int_equal(ps_sm_next((ps_sm_state_t)s, hard_bits[h] | ((1u << N_BITS) - 1u)),
                             PS_SM_ESTOP);
}

static void test_ps_sm_find_edge_priority_hard_soft_stop(void **state)
{
    (void)state;
    unsigned n = 0;
    const ps_sm_edge_t *e = ps_sm_edges(&n);

    /* hard + soft + stop in ACTIVE: the hard-fault edge matches */
    int idx = ps_sm_find_edge(PS_SM_ACTIVE, STOP | REPLY_STALE | BUS_OFF);
    assert_true(idx >= 0 && (unsigned)idx < n);
    assert_int_equal(e[idx].to, PS_SM_ESTOP);
    assert_true((e[idx].trigger & BUS_OFF) != 0u);

    /* soft + stop: the soft-fault edge, not the stop edge, is the cause
     * (RAMP damps on it, ACTIVE holds) */
    for (int s = RA; s <= AC; s++) {
        idx = ps_sm_find_edge((ps_sm_state_t)s, STOP | IMU_STALE);
        assert_true(idx >= 0);
        assert_int_equal(e[idx].to, s == RA ? PS_SM_DAMPING : PS_SM_HOLD);
        assert_true((e[idx].trigger & IMU_STALE) != 0u);
        assert_true((e[idx].trigger & STOP) == 0u);
        /* stop alone: the stop edge */
        idx = ps_sm_find_edge((ps_sm_state_t)s, STOP);
        assert_true(idx >= 0);
        assert_int_equal(e[idx].to, PS_SM_DAMPING);
        assert_true((e[idx].trigger & STOP) != 0u);
    }
    /* nothing matches: stay */
    assert_int_equal(ps_sm_find_edge(PS_SM_ACTIVE, RAMP_DONE | START), -1);
    assert_int_equal(ps_sm_find_edge(PS_SM_STANDBY, 0u), -1);
    /* ESTOP's latch is a matched self-edge */
    idx = ps_sm_find_edge(PS_SM_ESTOP, ESTOP_IN);
    assert_true(idx >= 0);
    assert_int_equal(e[idx].from, PS_SM_ESTOP);
    assert_int_equal(e[idx].to, PS_SM_ESTOP);
}

static void test_ps_sm_edges_table_well_formed(void **state)
{
    (void)state;
    unsigned n = 0;
    const ps_sm_edge_t *e = ps_sm_edges(&n);
    assert_non_null(e);
    assert_true(n > 0u);
    assert_ptr_equal(ps_sm_edges(NULL), e);

    int first_seen[N_STATES] = {0};
    for (unsigned i = 0; i < n; i++) {
        assert_true((unsigned)e[i].from < PS_SM_STATE_COUNT);
        assert_true((unsigned)e[i].to < PS_SM_STATE_COUNT);
        assert_true(e[i].trigger != 0u);
        assert_true((e[i].trigger & ~PS_SM_C_ALL) == 0u);
        assert_true((e[i].blocker & ~PS_SM_C_ALL) == 0u);
        /* an edge whose trigger is entirely blocked could never fire */
        assert_true((e[i].trigger & ~e[i].blocker) != 0u);
        if (!first_seen[e[i].from]) {
            /* ESTOP is checked first in every state: the state's first edge
             * goes to ESTOP on exactly the hard faults, unblocked (in ESTOP
             * itself: the latch holds on the reset blockers) */
            first_seen[e[i].from] = 1;
            assert_int_equal(e[i].to, PS_SM_ESTOP);
            assert_int_equal(e[i].trigger, e[i].from == PS_SM_ESTOP ? T_RESET_BLOCK : T_HARD);
            assert_int_equal(e[i].blocker, 0u);
        }
    }
    for (int s = 0; s < N_STATES; s++)
        assert_true(first_seen[s]);
}

static void test_ps_sm_fault_masks_match_spec(void **state)
{
    (void)state;
    assert_int_equal(PS_SM_C_HARD_FAULTS, T_HARD);
    assert_int_equal(PS_SM_C_SOFT_FAULTS, T_SOFT);
    assert_int_equal(PS_SM_C_REQUESTS, START | STOP | RESET | REQ_ESTOP);
    assert_int_equal(PS_SM_C_START_BLOCKERS, T_HARD | REPLY_STALE | IMU_STALE | DRIVE_HOT);
    assert_int_equal(PS_SM_C_HOLD_FAULTS, T_HOLDF);
    assert_int_equal(PS_SM_C_RESUME_BLOCKERS, T_HARD | T_SOFT | HOLD_DONE);
    assert_int_equal(PS_SM_C_RESET_BLOCKERS, T_RESET_BLOCK);
    assert_int_equal(PS_SM_C_ALL, (1u << N_BITS) - 1u);
}

/* ---- ps_sm_check_request ------------------------------------------------ */

typedef struct {
    int state;
    uint32_t request;
    uint32_t cond;
    int rc;
    const char *reason; /* NULL: accepted */
} req_case_t;

#define ILL (-PS_ERR_ILLEGAL_STATE)

static const req_case_t REQ_CASES[] = {
    /* START */
    {SB, START, 0u, 0, NULL},
    {SB, START, POLICY_LATE | TARGET_INVALID | FALL | RAMP_DONE, 0, NULL},
    {SB, START, ESTOP_IN, ILL, "start refused: e-stop input pressed"},
    {SB, START, REQ_ESTOP, ILL, "start refused: e-stop requested"},
    {SB, START, BUS_OFF, ILL, "start refused: CAN bus off"},
    {SB, START, DRIVE_FAULT, ILL, "start refused: drive fault"},
    {SB, START, REPLY_STALE, ILL, "start refused: actuator replies stale"},
    {SB, START, IMU_STALE, ILL, "start refused: IMU data stale"},
    {SB, START, IMU_STALE | ESTOP_IN, ILL, "start refused: e-stop input pressed"},
    {SB, START, DRIVE_HOT, ILL, "start refused: drive too hot"},
    {SB, START, DRIVE_HOT | IMU_STALE, ILL, "start refused: IMU data stale"},
    {RA, START, 0u, ILL, "start refused: only allowed from STANDBY or HOLD"},
    {AC, START, 0u, ILL, "start refused: only allowed from STANDBY or HOLD"},
    {DA, START, 0u, ILL, "start refused: only allowed from STANDBY or HOLD"},
    {HO, START, 0u, 0, NULL},
    {HO, START, RAMP_DONE, 0, NULL},
    {HO, START, HOLD_DONE, ILL, "start refused: hold time over, damping"},
    {HO, START, REPLY_STALE, ILL, "start refused: actuator replies stale"},
    {HO, START, POLICY_LATE, ILL, "start refused: policy still late"},
    {HO, START, TARGET_INVALID, ILL, "start refused: targets still invalid"},
    {HO, START, OVERRUN, ILL, "start refused: loop still overrunning"},
    {HO, START, TX_REFUSED, ILL, "start refused: bus still refusing frames"},
    {HO, START, FALL, ILL, "start refused: robot fallen"},
    {HO, START, DRIVE_HOT, ILL, "start refused: drive too hot"},
    {SB, START, OVERRUN | TX_REFUSED, 0, NULL}, /* not start blockers in STANDBY */
    {ES, START, 0u, ILL, "start refused: e-stop latched, reset first"},
    /* STOP */
    {SB, STOP, 0u, ILL, "stop refused: nothing to stop in STANDBY"},
    {RA, STOP, 0u, 0, NULL},
    {AC, STOP, 0u, 0, NULL},
    {AC, STOP, REPLY_STALE | BUS_OFF, 0, NULL},
    {HO, STOP, 0u, 0, NULL},
    {HO, STOP, POLICY_LATE, 0, NULL},
    {DA, STOP, 0u, ILL, "stop refused: already DAMPING"},
    {ES, STOP, 0u, ILL, "stop refused: e-stop latched"},
    /* RESET */
    {SB, RESET, 0u, ILL, "reset refused: not in ESTOP"},
    {RA, RESET, 0u, ILL, "reset refused: not in ESTOP"},
    {AC, RESET, 0u, ILL, "reset refused: not in ESTOP"},
    {DA, RESET, 0u, ILL, "reset refused: not in ESTOP"},
    {HO, RESET, 0u, ILL, "reset refused: not in ESTOP"},
    {ES, RESET, 0u, 0, NULL},
    {ES, RESET, REPLY_STALE | IMU_STALE | FALL | POLICY_LATE | TARGET_INVALID, 0, NULL},
    {ES, RESET, ESTOP_IN, ILL, "reset refused: e-stop input still pressed"},
    {ES, RESET, REQ_ESTOP, ILL, "reset refused: e-stop requested"},
    {ES, RESET, BUS_OFF, ILL, "reset refused: CAN bus still off"},
    {ES, RESET, DRIVE_FAULT, 0, NULL},
    {ES, RESET, DRIVE_FAULT | ESTOP_IN, ILL, "reset refused: e-stop input still pressed"},
    /* ESTOP: from everywhere, whatever else is going on */
    {SB, REQ_ESTOP, 0u, 0, NULL},
    {RA, REQ_ESTOP, 0u, 0, NULL},
    {AC, REQ_ESTOP, T_SOFT, 0, NULL},
    {DA, REQ_ESTOP, 0u, 0, NULL},
    {HO, REQ_ESTOP, T_SOFT, 0, NULL},
    {ES, REQ_ESTOP, ESTOP_IN, 0, NULL},
    {99, REQ_ESTOP, 0u, 0, NULL},
    {99, START, 0u, ILL, "request refused: unknown state"},
    /* not a single request bit */
    {SB, 0u, 0u, -EINVAL, "request refused: not a single request bit"},
    {SB, START | STOP, 0u, -EINVAL, "request refused: not a single request bit"},
    {AC, FALL, 0u, -EINVAL, "request refused: not a single request bit"},
    {ES, ESTOP_IN, 0u, -EINVAL, "request refused: not a single request bit"},
    {ES, 1u << 20, 0u, -EINVAL, "request refused: not a single request bit"},
};

static void test_ps_sm_check_request_cases_exact_reason(void **state)
{
    (void)state;
    for (size_t i = 0; i < sizeof REQ_CASES / sizeof REQ_CASES[0]; i++) {
        const req_case_t *c = &REQ_CASES[i];
        const char *sentinel = "untouched";
        const char *reason = sentinel;
        const int rc = ps_sm_check_request((ps_sm_state_t)c->state, c->request, c->cond, &reason);
        if (rc != c->rc)
            fail_msg("case %zu: rc %d, expected %d (%s)", i, rc, c->rc, reason);
        if (c->reason == NULL)
            assert_ptr_equal(reason, sentinel); /* untouched when accepted */
        else if (strcmp(reason, c->reason) != 0)
            fail_msg("case %zu: reason \"%s\", expected \"%s\"", i, reason, c->reason);
        /* NULL out_reason is allowed and gives the same verdict */
        assert_int_equal(ps_sm_check_request((ps_sm_state_t)c->state, c->request, c->cond, NULL),
                         c->rc);
    }
}

/* Accepted iff the request moves the machine where the request says. */
static void test_ps_sm_check_request_agrees_with_next(void **state)
{
    (void)state;
    const uint32_t reqs[] = {START, STOP, RESET, REQ_ESTOP};
    for (int s = 0; s < N_STATES; s++) {
        for (size_t r = 0; r < 4; r++) {
            for (uint32_t c = 0; c < (1u << N_BITS); c++) {
                if (c & (START | STOP | RESET | REQ_ESTOP))
                    continue; /* other requests in the same tick: not this question */
                const int rc = ps_sm_check_request((ps_sm_state_t)s, reqs[r], c, NULL);
                const ps_sm_state_t nx = ps_sm_next((ps_sm_state_t)s, c | reqs[r]);
                const ps_sm_state_t without = ps_sm_next((ps_sm_state_t)s, c);
                int want_ok;
                if (reqs[r] == START)
                    want_ok = (s == SB || s == HO) && nx == PS_SM_RAMP;
                else if (reqs[r] == RESET)
                    want_ok = s == ES && nx == PS_SM_STANDBY;
                else if (reqs[r] == STOP)
                    /* legal from RAMP/ACTIVE/HOLD; the result is DAMPING or worse, or
                     * HOLD when a hold fault in ACTIVE wins over the stop */
                    want_ok =
                        (s == RA || s == AC || s == HO) &&
                        (nx == PS_SM_DAMPING || nx == PS_SM_ESTOP || (s == AC && nx == PS_SM_HOLD));
                else
                    want_ok = nx == PS_SM_ESTOP;
                if ((rc == 0) != want_ok)
                    fail_msg("%s req %s cond 0x%x: rc %d, next %s (without %s)",
                             ps_sm_state_name((ps_sm_state_t)s), ps_sm_cond_name(reqs[r]), c, rc,
                             ps_sm_state_name(nx), ps_sm_state_name(without));
            }
        }
    }
}

static void test_ps_sm_check_request_every_blocker_bit_has_reason(void **state)
{
    (void)state;
    for (unsigned b = 0; b < N_BITS; b++) {
        const uint32_t bit = 1u << b;
        const char *reason = NULL;
        int rc = ps_sm_check_request(PS_SM_STANDBY, START, bit, &reason);
        if (bit & PS_SM_C_START_BLOCKERS) {
            assert_int_equal(rc, ILL);
            assert_non_null(reason);
            assert_non_null(strstr(reason, "start refused: "));
            assert_null(strstr(reason, "only allowed"));
        } else {
            assert_int_equal(rc, 0);
        }
        reason = NULL;
        rc = ps_sm_check_request(PS_SM_ESTOP, RESET, bit, &reason);
        if (bit & PS_SM_C_RESET_BLOCKERS) {
            assert_int_equal(rc, ILL);
            assert_non_null(strstr(reason, "reset refused: "));
            assert_null(strstr(reason, "not in ESTOP"));
        } else {
            assert_int_equal(rc, 0);
        }
    }
}

/* ---- names ----------------------------------------------------------------- */

static void test_ps_sm_state_name_each_state_named(void **state)
{
    (void)state;
    assert_string_equal(ps_sm_state_name(PS_SM_STANDBY), "STANDBY");
    assert_string_equal(ps_sm_state_name(PS_SM_RAMP), "RAMP");
    assert_string_equal(ps_sm_state_name(PS_SM_ACTIVE), "ACTIVE");
    assert_string_equal(ps_sm_state_name(PS_SM_DAMPING), "DAMPING");
    assert_string_equal(ps_sm_state_name(PS_SM_ESTOP), "ESTOP");
    assert_string_equal(ps_sm_state_name(PS_SM_HOLD), "HOLD");
    assert_string_equal(ps_sm_state_name(PS_SM_STATE_COUNT), "?");
    assert_string_equal(ps_sm_state_name((ps_sm_state_t)-1), "?");
}

static void test_ps_sm_cond_name_each_bit_named(void **state)
{
    (void)state;
    static const char *const want[N_BITS] = {
        "REQ_START",   "REQ_STOP",    "REQ_RESET", "REQ_ESTOP",   "ESTOP_INPUT",    "RAMP_DONE",
        "DAMP_DONE",   "REPLY_STALE", "IMU_STALE", "POLICY_LATE", "TARGET_INVALID", "FALL",
        "DRIVE_FAULT", "BUS_OFF",     "OVERRUN",   "TX_REFUSED",  "HOLD_DONE",      "DRIVE_HOT",
    };
    for (unsigned b = 0; b < N_BITS; b++)
        assert_string_equal(ps_sm_cond_name(1u << b), want[b]);
    /* lowest set bit wins */
    assert_string_equal(ps_sm_cond_name(BUS_OFF | REPLY_STALE), "REPLY_STALE");
    assert_string_equal(ps_sm_cond_name(0u), "?");
    assert_string_equal(ps_sm_cond_name(1u << 18), "?");
    assert_string_equal(ps_sm_cond_name(1u << 31), "?");
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_ps_sm_next_single_bit_matches_expected_table),
        cmocka_unit_test(test_ps_sm_next_combinations_match_expected),
        cmocka_unit_test(test_ps_sm_next_every_bit_combination_matches_reference_model),
        cmocka_unit_test(test_ps_sm_next_unknown_bits_ignored),
        cmocka_unit_test(test_ps_sm_next_invalid_state_estop),
        cmocka_unit_test(test_ps_sm_next_estop_latched_under_every_condition),
        cmocka_unit_test(test_ps_sm_next_hard_fault_from_every_state_estop),
        cmocka_unit_test(test_ps_sm_find_edge_priority_hard_soft_stop),
        cmocka_unit_test(test_ps_sm_edges_table_well_formed),
        cmocka_unit_test(test_ps_sm_fault_masks_match_spec),
        cmocka_unit_test(test_ps_sm_check_request_cases_exact_reason),
        cmocka_unit_test(test_ps_sm_check_request_agrees_with_next),
        cmocka_unit_test(test_ps_sm_check_request_every_blocker_bit_has_reason),
        cmocka_unit_test(test_ps_sm_state_name_each_state_named),
        cmocka_unit_test(test_ps_sm_cond_name_each_bit_named),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
