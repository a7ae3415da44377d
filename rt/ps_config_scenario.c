/*
 * ps_config_scenario: the scenario file (scenarios/<name>.yaml, simulation
 * only) and its check against the robot. Shared machinery:
 * ps_config_common.h. Fills sim's ps_scenario_cfg_t: composition root.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "ps_config_common.h"
#include "ps_config_sim.h"
#include "ps_err.h"

typedef struct {
    char name[PS_NAME_LEN];
    float duration_s;
    uint32_t seed;
    ps_event_cfg_t *events;
    uint32_t n_events;
    ps_push_cfg_t *pushes;
    uint32_t n_pushes;
} scenario_raw_t;

static const cyaml_strval_t EVENT_KINDS[] = {
    {"start", PS_EVENT_START},
    {"stop", PS_EVENT_STOP},
    {"estop_press", PS_EVENT_ESTOP_PRESS},
    {"estop_release", PS_EVENT_ESTOP_RELEASE},
    {"reset", PS_EVENT_RESET},
    {"harness_release", PS_EVENT_HARNESS_RELEASE},
    {"drop_replies", PS_EVENT_DROP_REPLIES},
    {"drive_fault", PS_EVENT_DRIVE_FAULT},
    {"record_button", PS_EVENT_RECORD_BUTTON},
};
static_assert(sizeof(EVENT_KINDS) / sizeof(EVENT_KINDS[0]) == PS_EVENT_COUNT,
              "one YAML name per event kind");

static const cyaml_schema_value_t FLOAT_SCHEMA = {
    CYAML_VALUE_FLOAT(CYAML_FLAG_DEFAULT, float),
};
static const cyaml_schema_field_t EVENT_FIELDS[] = {
    CYAML_FIELD_FLOAT("t_s", CYAML_FLAG_DEFAULT, ps_event_cfg_t, t_s),
    CYAML_FIELD_ENUM("kind", CYAML_FLAG_STRICT, ps_event_cfg_t, kind, EVENT_KINDS,
                     CYAML_ARRAY_LEN(EVENT_KINDS)),
    CYAML_FIELD_STRING("joint", CYAML_FLAG_OPTIONAL, ps_event_cfg_t, joint, 1),
    CYAML_FIELD_FLOAT("duration_s", CYAML_FLAG_OPTIONAL, ps_event_cfg_t, duration_s),
    CYAML_FIELD_END,
};
static const cyaml_schema_value_t EVENT_SCHEMA = {
    CYAML_VALUE_MAPPING(CYAML_FLAG_DEFAULT, ps_event_cfg_t, EVENT_FIELDS),
};
static const cyaml_schema_field_t PUSH_FIELDS[] = {
    CYAML_FIELD_FLOAT("t_s", CYAML_FLAG_DEFAULT, ps_push_cfg_t, t_s),
    CYAML_FIELD_FLOAT("duration_s", CYAML_FLAG_DEFAULT, ps_push_cfg_t, duration_s),
    CYAML_FIELD_STRING("body", CYAML_FLAG_DEFAULT, ps_push_cfg_t, body, 1),
    CYAML_FIELD_SEQUENCE_FIXED("force_n", CYAML_FLAG_DEFAULT, ps_push_cfg_t, force_n, &FLOAT_SCHEMA,
                               3),
    CYAML_FIELD_END,
};
static const cyaml_schema_value_t PUSH_SCHEMA = {
    CYAML_VALUE_MAPPING(CYAML_FLAG_DEFAULT, ps_push_cfg_t, PUSH_FIELDS),
};
static const cyaml_schema_field_t SCENARIO_FIELDS[] = {
    CYAML_FIELD_STRING("name", CYAML_FLAG_DEFAULT, scenario_raw_t, name, 1),
    CYAML_FIELD_FLOAT("duration_s", CYAML_FLAG_DEFAULT, scenario_raw_t, duration_s),
    CYAML_FIELD_UINT("seed", CYAML_FLAG_DEFAULT, scenario_raw_t, seed),
    CYAML_FIELD_SEQUENCE_COUNT("events", CYAML_FLAG_POINTER | CYAML_FLAG_OPTIONAL, scenario_raw_t,
                               events, n_events, &EVENT_SCHEMA, 0, PS_MAX_EVENTS),
    CYAML_FIELD_SEQUENCE_COUNT("pushes", CYAML_FLAG_POINTER | CYAML_FLAG_OPTIONAL, scenario_raw_t,
                               pushes, n_pushes, &PUSH_SCHEMA, 0, PS_MAX_PUSHES),
    CYAML_FIELD_END,
};
static const cyaml_schema_value_t SCENARIO_SCHEMA = {
    CYAML_VALUE_MAPPING(CYAML_FLAG_POINTER, scenario_raw_t, SCENARIO_FIELDS),
};

#define MAX_PUSH_FORCE_N 2000.0
#define MAX_RUN_S        86400.0
static const ps_cfg_array_t SCENARIO_ARRAYS[] = {
    PS_CFG_ARRAY("events", ps_scenario_cfg_t, events, ps_event_cfg_t, n_events),
    PS_CFG_ARRAY("pushes", ps_scenario_cfg_t, pushes, ps_push_cfg_t, n_pushes),
};
enum { SA_EVENTS = 1, SA_PUSHES = 2 };
static const ps_cfg_rule_t SCENARIO_RANGES[] = {
    PS_CFG_RULE_F32(0, 0, "duration_s", ps_scenario_cfg_t, duration_s, 0.0, MAX_RUN_S),
    PS_CFG_RULE_U32(0, 0, "seed", ps_scenario_cfg_t, seed, 0.0, 4294967295.0),
    PS_CFG_RULE_F32(SA_EVENTS, 0, "t_s", ps_event_cfg_t, t_s, 0.0, MAX_RUN_S),
    PS_CFG_RULE_F32(SA_EVENTS, 0, "duration_s", ps_event_cfg_t, duration_s, 0.0, 3600.0),
    PS_CFG_RULE_F32(SA_PUSHES, 0, "t_s", ps_push_cfg_t, t_s, 0.0, MAX_RUN_S),
    PS_CFG_RULE_F32(SA_PUSHES, PS_CFG_RANGE_OPEN_MIN, "duration_s", ps_push_cfg_t, duration_s, 0.0,
                    10.0),
    PS_CFG_RULE_F32(SA_PUSHES, 0, "force_n[0]", ps_push_cfg_t, force_n[0], -MAX_PUSH_FORCE_N,
                    MAX_PUSH_FORCE_N),
    PS_CFG_RULE_F32(SA_PUSHES, 0, "force_n[1]", ps_push_cfg_t, force_n[1], -MAX_PUSH_FORCE_N,
                    MAX_PUSH_FORCE_N),
    PS_CFG_RULE_F32(SA_PUSHES, 0, "force_n[2]", ps_push_cfg_t, force_n[2], -MAX_PUSH_FORCE_N,
                    MAX_PUSH_FORCE_N),
};

static int check_scenario(ps_cfg_ctx_t *c, const ps_scenario_cfg_t *s)
{
    int rc = ps_cfg_check_ranges(c, s);
    if (rc != 0)
        return rc;
    char field[PS_CFG_FIELD_PATH_LEN];
    for (uint32_t i = 0; i < s->n_events; i++) {
        const ps_event_cfg_t *e = &s->events[i];
        const bool is_drop = e->kind == PS_EVENT_DROP_REPLIES;
        const bool has_joint = is_drop || e->kind == PS_EVENT_DRIVE_FAULT;
        if (has_joint && e->joint[0] == '\0') {
            (void)snprintf(field, sizeof(field), "events[%u]", i);
            return ps_cfg_fail_field(c, field, "%s needs a \"joint\"",
                                     ps_config_event_name(e->kind));
        }
        if (!has_joint && e->joint[0] != '\0') {
            (void)snprintf(field, sizeof(field), "events[%u].joint", i);
            return ps_cfg_fail_field(c, field,
                                     "only drop_replies and drive_fault take a joint, not %s",
                                     ps_config_event_name(e->kind));
        }
        if (!is_drop && e->duration_s != 0.0f) {
            (void)snprintf(field, sizeof(field), "events[%u].duration_s", i);
            return ps_cfg_fail_field(c, field, "only drop_replies takes a duration, not %s",
                                     ps_config_event_name(e->kind));
        }
        if (s->duration_s > 0.0f && e->t_s > s->duration_s) {
            (void)snprintf(field, sizeof(field), "events[%u].t_s", i);
            return ps_cfg_fail_field(c, field, "value %g after the end of the run (duration_s %g)",
                                     (double)e->t_s, (double)s->duration_s);
        }
    }
    for (uint32_t i = 0; i < s->n_pushes; i++) {
        const ps_push_cfg_t *p = &s->pushes[i];
        const double f =
            sqrt((double)p->force_n[0] * p->force_n[0] + (double)p->force_n[1] * p->force_n[1] +
                 (double)p->force_n[2] * p->force_n[2]);
        if (f > MAX_PUSH_FORCE_N) {
            (void)snprintf(field, sizeof(field), "pushes[%u].force_n", i);
            return ps_cfg_fail_field(c, field, "magnitude %g N outside [0, %g]", f,
                                     MAX_PUSH_FORCE_N);
        }
        if (s->duration_s > 0.0f && p->t_s > s->duration_s) {
            (void)snprintf(field, sizeof(field), "pushes[%u].t_s", i);
            return ps_cfg_fail_field(c, field, "value %g after the end of the run (duration_s %g)",
                                     (double)p->t_s, (double)s->duration_s);
        }
    }
    return 0;
}

/* Where the fields that the robot and the model are checked against are. */
static void record_src(const ps_cfg_ctx_t *c, ps_scenario_cfg_t *s)
{
    (void)snprintf(s->path, sizeof(s->path), "%s", c->path); /* truncation is acceptable */
    char field[PS_CFG_FIELD_PATH_LEN];
    for (uint32_t i = 0; i < s->n_events; i++) {
        (void)snprintf(field, sizeof(field), "events[%u].joint", i);
        s->events[i].joint_line = ps_cfg_line_of(c, field);
    }
    for (uint32_t i = 0; i < s->n_pushes; i++) {
        (void)snprintf(field, sizeof(field), "pushes[%u].body", i);
        s->pushes[i].body_line = ps_cfg_line_of(c, field);
    }
}

int ps_config_load_scenario(const char *path, ps_scenario_cfg_t *out, char *err, size_t err_len)
{
    if (path == NULL || out == NULL)
        return -EINVAL;
    ps_cfg_ctx_t c;
    int rc = ps_cfg_ctx_open(&c, path, err, err_len, SCENARIO_ARRAYS, SCENARIO_RANGES,
                             PS_CFG_COUNT(SCENARIO_RANGES));
    scenario_raw_t *raw = NULL;
    if (rc == 0)
        rc = ps_cfg_load_file(&c, &SCENARIO_SCHEMA, (void **)&raw);

    ps_scenario_cfg_t *s = rc == 0 ? calloc(1, sizeof(*s)) : NULL;
    if (rc == 0 && s == NULL)
        rc = -ENOMEM;
    if (rc == 0) {
        memcpy(s->name, raw->name, sizeof(s->name));
        s->duration_s = raw->duration_s;
        s->seed = raw->seed;
        s->n_events = raw->n_events; /* libcyaml enforced the maxima */
        if (raw->n_events > 0)
            memcpy(s->events, raw->events, raw->n_events * sizeof(s->events[0]));
        s->n_pushes = raw->n_pushes;
        if (raw->n_pushes > 0)
            memcpy(s->pushes, raw->pushes, raw->n_pushes * sizeof(s->pushes[0]));
    }
    if (raw != NULL)
        (void)cyaml_free(&c.cyaml, &SCENARIO_SCHEMA, raw, 0); /* only fails on a NULL schema */
    if (rc == 0)
        rc = check_scenario(&c, s);
    if (rc == 0) {
        record_src(&c, s);
        *out = *s;
    }
    free(s);
    ps_cfg_ctx_close(&c);
    return rc;
}

int ps_config_check_scenario(const ps_robot_cfg_t *r, const ps_scenario_cfg_t *s, char *err,
                             size_t err_len)
{
    if (r == NULL || s == NULL)
        return -EINVAL;
    if (err != NULL && err_len > 0)
        err[0] = '\0';
    for (uint32_t i = 0; i < s->n_events && i < PS_MAX_EVENTS; i++) {
        const ps_event_cfg_t *e = &s->events[i];
        if ((e->kind != PS_EVENT_DROP_REPLIES && e->kind != PS_EVENT_DRIVE_FAULT) ||
            ps_config_find_joint(r, e->joint) >= 0)
            continue;
        if (s->path[0] == '\0')
            ps_err_format(err, err_len,
                          "scenario %s: events[%u].joint: no joint \"%s\" in robot %s", s->name, i,
                          e->joint, r->name);
        else if (e->joint_line == 0)
            ps_err_format(err, err_len, "%s: events[%u].joint: no joint \"%s\" in robot %s",
                          s->path, i, e->joint, r->name);
        else
            ps_err_format(err, err_len, "%s:%u: events[%u].joint: no joint \"%s\" in robot %s",
                          s->path, e->joint_line, i, e->joint, r->name);
        return -PS_ERR_CONFIG;
    }
    return 0;
}

const char *ps_config_event_name(ps_event_kind_t k)
{
    if ((unsigned)k >= (unsigned)PS_EVENT_COUNT)
        return "unknown";
    return EVENT_KINDS[k].str; /* static_assert above keeps the table complete */
}
