/* libFuzzer target: the e-stop's software debounce and its "pressed since the
 * last read" latch (drivers/ps_gpio_gpiod.h, ps_gpio_debounce_*), fed
 * arbitrary edge sequences as the port feeds it kernel events.
 *
 * Input: debounce time (2 bytes, us), the level and time at init (1 + 8
 * bytes: any int64), then operations of 3 bytes: op (bits 0..1: 0 edge,
 * 1 poll, 2 take, 3 edge stamped back in time; bit 2: the edge's level),
 * and a time step in us (2 bytes). Times saturate at INT64_MAX.
 *
 * The harness keeps the raw level as it told the filter (times clamped as
 * the filter documents: never backwards) and checks the filter's promises:
 *   - no missed press: a press seen held for debounce_ns or longer (by an
 *     edge or poll) is reported by the next take, even if released before;
 *     a press counts again only after a release held that long (a shorter
 *     release is a glitch inside one press, reported once);
 *   - no phantom press: a take says pressed only if some press (or the level
 *     at init) was seen held for at least debounce_ns;
 *   - debounce 0: take says pressed exactly when the input is pressed now or
 *     a press edge came since the previous take (the first take: or the
 *     input was pressed at init). */
#include "../../drivers/ps_gpio_gpiod.h"
#include "fuzz.h"

typedef struct {
    bool is_raw;             /* level told to the filter */
    int64_t since_ns;        /* when it took it */
    int64_t last_ns;         /* latest time told */
    bool is_owed;            /* a new press held >= debounce since the last take: must report */
    bool is_waiting_release; /* a press was counted: the next counts only after a release
                                held >= debounce (a shorter one is a glitch of that press) */
    bool has_stable_press;   /* some press (or the init level) held >= debounce, ever */
    bool has_press_edge;     /* debounce 0: a press edge since the last take */
} model_t;

/* dt >= 0 */
static int64_t add_sat(int64_t t, int64_t dt)
{
    return t > INT64_MAX - dt ? INT64_MAX : t + dt;
}

static int64_t sub_sat(int64_t t, int64_t dt)
{
    return t < INT64_MIN + dt ? INT64_MIN : t - dt;
}

/* The level held from since_ns to t_ns: that long is stable. */
static void observe(model_t *m, int64_t debounce_ns, int64_t t_ns)
{
    if ((uint64_t)t_ns - (uint64_t)m->since_ns < (uint64_t)debounce_ns)
        return;
    if (!m->is_raw) {
        m->is_waiting_release = false;
    } else if (!m->is_waiting_release) {
        m->is_owed = true;
        m->is_waiting_release = true;
        m->has_stable_press = true;
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    fuzz_in_t in = {data, size};
    const int64_t debounce_ns = (int64_t)(fuzz_u8(&in) | (fuzz_u8(&in) << 8)) * 1000;
    const bool is_init_pressed = fuzz_u8(&in) & 1u;
    int64_t t_ns = (int64_t)((uint64_t)fuzz_u32(&in) | ((uint64_t)fuzz_u32(&in) << 32));

    ps_gpio_debounce_t d;
    ps_gpio_debounce_init(&d, debounce_ns, is_init_pressed, t_ns);
    /* a level pressed at init counts as a press for the first take */
    model_t m = {.is_raw = is_init_pressed,
                 .since_ns = t_ns,
                 .last_ns = t_ns,
                 .is_owed = is_init_pressed,
                 .is_waiting_release = is_init_pressed,
                 .has_stable_press = is_init_pressed,
                 .has_press_edge = is_init_pressed};

    while (in.n > 0) {
        const uint8_t op = fuzz_u8(&in);
        const int64_t dt_ns = (int64_t)(fuzz_u8(&in) | (fuzz_u8(&in) << 8)) * 1000;
        const bool level = (op >> 2) & 1u;
        switch (op & 3u) {
        case 0:
        case 3: {
            const int64_t t_edge = (op & 3u) == 0 ? add_sat(t_ns, dt_ns) : sub_sat(t_ns, dt_ns);
            if ((op & 3u) == 0)
                t_ns = t_edge;
            ps_gpio_debounce_edge(&d, level, t_edge);
            const int64_t t = t_edge < m.last_ns ? m.last_ns : t_edge;
            m.last_ns = t;
            observe(&m, debounce_ns, t);
            if (level != m.is_raw) {
                m.is_raw = level;
                m.since_ns = t;
                if (level)
                    m.has_press_edge = true;
                observe(&m, debounce_ns, t);
            }
            break;
        }
        case 1:
            t_ns = add_sat(t_ns, dt_ns);
            ps_gpio_debounce_poll(&d, t_ns);
            m.last_ns = t_ns > m.last_ns ? t_ns : m.last_ns;
            observe(&m, debounce_ns, m.last_ns);
            break;
        default: {
            const bool got = ps_gpio_debounce_take_pressed(&d);
            if (m.is_owed)
                FUZZ_CHECK(got, "a press held for %lld ns or more was not reported",
                           (long long)debounce_ns);
            if (got)
                FUZZ_CHECK(m.has_stable_press,
                           "pressed reported but no press was ever held for %lld ns",
                           (long long)debounce_ns);
            if (debounce_ns == 0)
                FUZZ_CHECK(got == (m.is_raw || m.has_press_edge),
                           "debounce 0: took %d, pressed %d, press edge %d", got, m.is_raw,
                           m.has_press_edge);
            m.is_owed = false;
            m.has_press_edge = false;
            break;
        }
        }
    }
    return 0;
}
