/* The myactuator family's C path: the control-loop traffic of one simulated motor, byte for byte and
 * time for time as the Python model (src/servobus/protocols/myactuator/sim/device.py, state.py) does it.
 *
 * Every decision to leave a frame to the model (SB_HOT_COLD) is taken before anything changes. The
 * arithmetic follows the model's expressions operation by operation (-ffp-contract=off), with
 * Python's rules where they differ from C's: `%` on floats (py_mod), round() half to even
 * (nearbyint), round(x, n) on the exact decimal value (round_scaled), and replies' integers clamped
 * to their fields as state.py does. */
#include <math.h>
#include <string.h>

#include "sb_internal.h"
#include "sim_pymath.h"

_Static_assert(sizeof(sb_ma_state) <= sizeof(((sb_simmotor *)0)->state),
               "sb_ma_state must fit sb_simmotor.state");

#define REQUEST_BASE 0x140u
#define REPLY_BASE 0x240u
#define BROADCAST_ID 0x280u
#define ID_SETTING_ID 0x300u
#define MOTION_REQUEST_BASE 0x400u
#define MOTION_REPLY_BASE 0x500u

/* The model's RunMode values (§4.27). */
#define RUN_CURRENT 1
#define RUN_SPEED 2
#define RUN_POSITION 3

/* CPython's math.degrees / math.radians factors (Modules/mathmodule.c) and state.py's _RAD_PER_DEG. */
#define RAD_TO_DEG (180.0 / 3.14159265358979323846)
#define DEG_TO_RAD (3.14159265358979323846 / 180.0)
#define STREAM_STEP_S 0.01   /* 0xB6 interval unit (device.py STREAM_STEP_S) */
#define TWO_POW_52 4503599627370496.0
#define COUNT_LIMIT 4.0e18   /* encoder counts beyond this are no motor's: left to the model */
#define STREAM_COUNT_LIMIT ((int64_t)1 << 52)  /* stream slots: exact as doubles, as in the model */

static sb_ma_state *state_of(sb_simmotor *m)
{
    return (sb_ma_state *)(void *)m->state;
}

static const sb_ma_state *cstate_of(const sb_simmotor *m)
{
    return (const sb_ma_state *)(const void *)m->state;
}

/* ---- Python's number rules ---- */


/* The integer round(x, n) * 10**n stands for, scale = 10**n: the exact product x * scale rounded half
 * to even (round() rounds the exact binary value; the float product may round onto a tie). */
static double round_scaled(double x, double scale)
{
    double p = x * scale;
    double r, d, e;

    if (!(fabs(p) < TWO_POW_52))
        return p; /* already an integer (or not finite: clamped by the caller) */
    r = nearbyint(p);
    d = p - r; /* exact (Sterbenz) */
    if (fabs(d) != 0.5)
        return r; /* not a tie in floats: the exact product rounds the same way */
    e = fma(x, scale, -p); /* the product's rounding error, exactly: which side of the tie it is */
    if (d > 0)
        return e > 0.0 ? r + 1.0 : r;
    return e < 0.0 ? r - 1.0 : r;
}

static int64_t clamp_int(double v, double lo, double hi)
{
    if (!(v >= lo))
        return (int64_t)lo; /* NaN cannot reach here (readings are checked finite); low end if it did */
    if (v > hi)
        return (int64_t)hi;
    return (int64_t)v;
}

/* state.py _clamp: max(lo, min(hi, value)). */
static double clamp_float(double value, double lo, double hi)
{
    double m = hi < value ? hi : value;
    return lo > m ? lo : m;
}

static void put_le16(uint8_t *o, int64_t v)
{
    uint16_t u = (uint16_t)(v & 0xFFFF);
    o[0] = (uint8_t)u;
    o[1] = (uint8_t)(u >> 8);
}

static void put_le32(uint8_t *o, int64_t v)
{
    uint32_t u = (uint32_t)(v & 0xFFFFFFFF);
    o[0] = (uint8_t)u;
    o[1] = (uint8_t)(u >> 8);
    o[2] = (uint8_t)(u >> 16);
    o[3] = (uint8_t)(u >> 24);
}

static int64_t get_le_signed(const uint8_t *p, int n)
{
    uint64_t u = 0;
    uint64_t sign = (uint64_t)1 << (8 * n - 1);
    for (int i = n - 1; i >= 0; i--)
        u = (u << 8) | p[i];
    return (u & sign) ? (int64_t)(u - (sign << 1)) : (int64_t)u;
}

static uint32_t get_le_unsigned(const uint8_t *p, int n)
{
    uint32_t u = 0;
    for (int i = n - 1; i >= 0; i--)
        u = (u << 8) | p[i];
    return u;
}

/* ---- readings (device.py readings(), state.py EncoderFrame) ---- */

typedef struct {
    double temperature_c;
    double current_a;
    double speed_dps;
    double angle_deg;
    double voltage_v;
    double rotor_deg;
    int64_t raw_counts;       /* 0x61 */
    int64_t position_counts;  /* 0x60: raw - offset */
} readings;

/* The measurements at the plant's observed time; 0 when a value is beyond what the model handles
 * (not finite, or encoder counts past COUNT_LIMIT), so the caller leaves the frame to the model. */
static int read_plant(const sb_simmotor *m, const sb_ma_state *s, readings *r)
{
    const sb_plant *pl = &m->plant;
    double cpt = (double)s->counts_per_turn;
    double rotor = pl->now.position_deg * pl->p.gear_ratio;
    double raw = rotor * cpt / 360.0 + (double)s->base_counts;
    double whole = floor(raw);

    if (!(fabs(whole) < COUNT_LIMIT) || !isfinite(pl->now.temperature_c) || !isfinite(pl->now.current_a) ||
        !isfinite(pl->now.speed_dps))
        return 0;
    r->temperature_c = pl->now.temperature_c;
    r->current_a = pl->now.current_a;
    r->speed_dps = pl->now.speed_dps;
    r->angle_deg = (raw - (double)s->offset_counts) * 360.0 / cpt / s->encoder_gear_ratio;
    r->voltage_v = pl->p.supply_v - fabs(pl->now.current_a) * pl->p.supply_resistance_ohm;
    r->rotor_deg = rotor;
    r->raw_counts = (int64_t)whole;
    r->position_counts = r->raw_counts - s->offset_counts;
    return 1;
}

/* ---- replies (state.py) ---- */

static int64_t int8_of(double x) { return clamp_int(nearbyint(x), -128.0, 127.0); }
static int64_t int16_of(double x) { return clamp_int(nearbyint(x), -32768.0, 32767.0); }
static int64_t int32_of(double x) { return clamp_int(nearbyint(x), -2147483648.0, 2147483647.0); }
/* round(x, 2) clamped to ±327.68/327.67, as the int16 0.01 A code it encodes to */
static int64_t centi_amps(double x) { return clamp_int(round_scaled(x, 100.0), -32768.0, 32767.0); }

static int64_t int32_of_int(int64_t v)
{
    return v < INT32_MIN ? INT32_MIN : v > INT32_MAX ? INT32_MAX : v;
}

/* R2 (§3.1): status_reply(). */
static void status_reply(uint8_t code, const readings *r, uint8_t *o)
{
    o[0] = code;
    o[1] = (uint8_t)int8_of(r->temperature_c);
    put_le16(o + 2, centi_amps(r->current_a));
    put_le16(o + 4, int16_of(r->speed_dps));
    put_le16(o + 6, int16_of(r->angle_deg));
}

/* R2-A6 (§3.2): single_turn_status_reply(). */
static void single_turn_status_reply(const sb_ma_state *s, const readings *r, uint8_t *o)
{
    int64_t cpt = s->counts_per_turn;
    int64_t counts = r->position_counts % cpt;
    if (counts < 0)
        counts += cpt; /* Python's % takes the divisor's sign */
    o[0] = 0xA6;
    o[1] = (uint8_t)int8_of(r->temperature_c);
    put_le16(o + 2, centi_amps(r->current_a));
    put_le16(o + 4, int16_of(r->speed_dps));
    put_le16(o + 6, counts);
}

/* 0x9A (§4.14): status1(); no error flag is set while the C path runs. */
static void status1_reply(const sb_ma_state *s, const readings *r, uint8_t *o)
{
    o[0] = 0x9A;
    o[1] = (uint8_t)int8_of(r->temperature_c);
    o[2] = (uint8_t)clamp_int(nearbyint(r->temperature_c), 0.0, 255.0);
    o[3] = s->brake_released ? 1 : 0;
    put_le16(o + 4, clamp_int(round_scaled(r->voltage_v, 10.0), 0.0, 65535.0));
    put_le16(o + 6, 0);
}

/* 0x9D (§4.16): status3_reply() over phase_currents(). */
static void status3_reply(const sb_ma_state *s, const readings *r, uint8_t *o)
{
    double theta = r->rotor_deg * DEG_TO_RAD * (double)s->pole_pairs;
    double third = 2.0 * 3.14159265358979323846 / 3.0;
    o[0] = 0x9D;
    o[1] = (uint8_t)int8_of(r->temperature_c);
    put_le16(o + 2, centi_amps(-r->current_a * sin(theta)));
    put_le16(o + 4, centi_amps(-r->current_a * sin(theta - third)));
    put_le16(o + 6, centi_amps(-r->current_a * sin(theta + third)));
}

static void counts_reply(uint8_t code, int64_t counts, uint8_t *o)
{
    o[0] = code;
    put_le32(o + 4, int32_of_int(counts));
}

/* The read commands (the streamable ones): their reply. 0 for any other byte. */
static int read_reply(const sb_ma_state *s, const readings *r, uint8_t code, uint8_t *o)
{
    memset(o, 0, 8);
    switch (code) {
    case 0x9C: status_reply(0x9C, r, o); return 1;
    case 0x9A: status1_reply(s, r, o); return 1;
    case 0x9D: status3_reply(s, r, o); return 1;
    case 0x92:
        /* int32(angle * 100) / 100, encoded as round_half_away(value * 100): the int32 itself */
        o[0] = 0x92;
        put_le32(o + 4, int32_of(r->angle_deg * 100.0));
        return 1;
    case 0x60: counts_reply(0x60, r->position_counts, o); return 1;
    case 0x61: counts_reply(0x61, r->raw_counts, o); return 1;
    case 0x62: counts_reply(0x62, s->offset_counts, o); return 1;
    }
    return 0;
}

static int is_streamable(uint8_t code)
{
    switch (code) {
    case 0x60: case 0x61: case 0x62: case 0x92: case 0x9A: case 0x9C: case 0x9D: return 1;
    }
    return 0;
}

/* ---- decoding: what the codec would decode the request to, or 0 (the model's business) ---- */

enum { K_NONE, K_TORQUE, K_SPEED, K_ABSOLUTE, K_SINGLE_TURN, K_INCREMENTAL, K_FORCE, K_FF_SPEED, K_FF_TORQUE,
       K_READ, K_ACTIVE_REPLY, K_MOTION };

typedef struct {
    int kind;
    uint8_t code;
    double value;          /* current_a, speed_dps, angle_deg */
    double max_speed_dps;  /* NAN: none (maxSpeed 0) */
    int pct;               /* max_torque_pct (-1: none), feed-forward %, direction, stream command */
    int enabled;           /* 0xB6 */
    int interval_code;     /* 0xB6, 10 ms counts */
    double motion[5];      /* p, v, kp, kd, t */
} request;

static double max_speed_of(const uint8_t *d)
{
    uint32_t code = get_le_unsigned(d + 2, 2);
    return code == 0 ? NAN : (double)code; /* SpecialZero: 0 decodes to None */
}

static int decode_standard(const sb_ma_state *s, const uint8_t *d, request *q)
{
    q->code = d[0];
    q->max_speed_dps = NAN;
    q->pct = -1;
    switch (d[0]) {
    case 0xA1:
        q->kind = K_TORQUE;
        q->value = (double)get_le_signed(d + 4, 2) / 100.0;
        return 1;
    case 0xA2:
        q->kind = K_SPEED;
        q->pct = d[1] == 0 ? -1 : d[1];
        q->value = (double)get_le_signed(d + 4, 4) / 100.0;
        return 1;
    case 0xA4:
    case 0xA8:
        q->kind = d[0] == 0xA4 ? K_ABSOLUTE : K_INCREMENTAL;
        q->max_speed_dps = max_speed_of(d);
        q->value = (double)get_le_signed(d + 4, 4) / 100.0;
        return 1;
    case 0xA6: {
        uint32_t angle = get_le_unsigned(d + 4, 2);
        if (d[1] > 1 || angle > 36000)
            return 0; /* not a SpinDirection, or past the field's 360° */
        q->kind = K_SINGLE_TURN;
        q->pct = d[1];
        q->max_speed_dps = max_speed_of(d);
        q->value = (double)angle / 100.0;
        return 1;
    }
    case 0xA9:
        if (d[1] == 0)
            return 0; /* maxTorque 0 is undefined: it does not decode */
        q->kind = K_FORCE;
        q->pct = d[1];
        q->max_speed_dps = max_speed_of(d);
        q->value = (double)get_le_signed(d + 4, 4) / 100.0;
        return 1;
    case 0x72:
    case 0x73:
        if (s->revision != SB_MA_V4_4)
            return 0; /* V4.4 only: counted as other_revision by the model */
        q->kind = d[0] == 0x72 ? K_FF_SPEED : K_FF_TORQUE;
        q->pct = (int)(int8_t)d[1];
        q->max_speed_dps = max_speed_of(d);
        q->value = (double)get_le_signed(d + 4, 4) / 100.0;
        return 1;
    case 0x9A: case 0x9C: case 0x9D: case 0x92: case 0x60: case 0x61: case 0x62:
        q->kind = K_READ;
        return 1;
    case 0xB6:
        if (!is_streamable(d[1]) || d[2] > 1)
            return 0;
        q->kind = K_ACTIVE_REPLY;
        q->pct = d[1];
        q->enabled = d[2];
        q->interval_code = (int)get_le_unsigned(d + 3, 2);
        return !(q->enabled && q->interval_code == 0); /* an enabled interval 0 does not decode */
    }
    return 0;
}

/* MotionCommand.decode: the MIT_COMMAND codes scaled, then clamped into the fields' ranges. */
static int decode_motion(const sb_ma_state *s, const uint8_t *d, request *q)
{
    if (sb_unpack(SB_LAYOUT_MIT_COMMAND, s->motion_command, d, 1, 8, q->motion, 5) != SB_OK)
        return 0;
    for (int k = 0; k < 5; k++) {
        double x = q->motion[k];
        double lo = s->motion_command[k].lo, hi = s->motion_command[k].hi;
        double v = lo > x ? lo : x;  /* max(x, lo) */
        q->motion[k] = hi < v ? hi : v;  /* min(., hi) */
    }
    q->kind = K_MOTION;
    return 1;
}

/* ---- acting (device.py _control_command, the loops, _set_control, _apply_plant) ---- */

static void apply_plant(sb_simmotor *m, sb_ma_state *s)
{
    double slew = s->control.mode == SB_CONTROL_SPEED ? s->speed_acceleration_dps_s
                                                      : s->position_acceleration_dps_s;
    sb_plant_set_acceleration(&m->plant, slew > 0 ? slew : INFINITY);
    if (s->has_brake && !s->brake_released) {
        sb_control brake = {SB_CONTROL_BRAKE, 0.0, 0.0, 0.0, 0.0, 0.0};
        sb_plant_set_control(&m->plant, &brake);
    } else {
        sb_plant_set_control(&m->plant, &s->control);
    }
}

/* _current_limit: % of the rated current, None (NAN) unless strictly between 0 and the stall current. */
static double current_limit(const sb_simmotor *m, const sb_ma_state *s, int pct)
{
    double limit;
    if (pct < 0)
        return NAN;
    limit = (double)pct / 100.0 * s->rated_current_a;
    return (0 < limit && limit < m->plant.p.max_current_a) ? limit : NAN;
}

/* EncoderFrame.output_deg_for: the plant angle at which the encoder reads angle_deg. */
static double target_of(const sb_ma_state *s, double angle_deg)
{
    double shift = (double)(s->offset_counts - s->base_counts) * 360.0 / (double)s->counts_per_turn /
                   s->encoder_gear_ratio;
    return angle_deg + shift;
}

static void position_control(sb_ma_state *s, double target_deg, double max_speed_dps, double limit_a)
{
    sb_control c = {SB_CONTROL_POSITION, target_deg, max_speed_dps, limit_a, 0.0, 0.0};
    s->control = c;
    s->run_mode = RUN_POSITION;
}

/* A closed-loop command: the brake rule, then the loop's control and run mode into the plant. */
static void control_command(sb_simmotor *m, sb_ma_state *s, const request *q, const readings *r)
{
    const sb_plant *pl = &m->plant;
    if (q->kind != K_TORQUE)
        s->brake_released = 1; /* every control command but 0xA1 releases the brake [I] */
    switch (q->kind) {
    case K_TORQUE: {
        sb_control c = {SB_CONTROL_CURRENT, q->value, 0.0, 0.0, 0.0, 0.0};
        if (s->has_brake && !s->brake_released)
            m->counters[SB_MA_CTR_BRAKE_LOCKED] += 1;
        s->control = c;
        s->run_mode = RUN_CURRENT;
        break;
    }
    case K_SPEED: {
        sb_control c = {SB_CONTROL_SPEED, q->value, current_limit(m, s, q->pct), 0.0, 0.0, 0.0};
        s->control = c;
        s->run_mode = RUN_SPEED;
        break;
    }
    case K_ABSOLUTE:
        position_control(s, target_of(s, q->value), q->max_speed_dps, NAN);
        break;
    case K_FORCE:
        position_control(s, target_of(s, q->value), q->max_speed_dps, current_limit(m, s, q->pct));
        break;
    case K_FF_SPEED:
    case K_FF_TORQUE:
        s->has_feedforward = 1;
        s->feedforward_pct = q->pct;
        position_control(s, target_of(s, q->value), q->max_speed_dps, NAN);
        break;
    case K_INCREMENTAL:
        position_control(s, pl->now.position_deg + q->value, q->max_speed_dps, NAN);
        break;
    case K_SINGLE_TURN: {
        double here = py_mod(r->angle_deg, 360.0);
        double wanted = py_mod(q->value, 360.0);
        double delta = q->pct == 0 ? py_mod(wanted - here, 360.0) : -py_mod(here - wanted, 360.0);
        position_control(s, pl->now.position_deg + delta, q->max_speed_dps, NAN);
        break;
    }
    case K_MOTION: {
        double p_des_deg = target_of(s, q->motion[0] * RAD_TO_DEG);
        sb_control c = {SB_CONTROL_IMPEDANCE, p_des_deg * DEG_TO_RAD, q->motion[1], q->motion[2], q->motion[3],
                        q->motion[4]};
        s->control = c;
        s->run_mode = RUN_CURRENT; /* the MIT law ends in a current reference */
        break;
    }
    case K_NONE: case K_READ: case K_ACTIVE_REPLY:
        return;
    }
    s->dirty |= SB_MA_DIRTY_CONTROL;
    apply_plant(m, s);
}

/* MotionReply (§5.3): position, velocity and torque clamped to the motion ranges, packed. */
static void motion_reply(const sb_simmotor *m, const sb_ma_state *s, const readings *r, uint8_t *o)
{
    const sb_field *f = s->motion_reply;
    double values[4];
    values[0] = (double)s->motor_id;
    values[1] = clamp_float(r->angle_deg * DEG_TO_RAD, f[1].lo, f[1].hi);
    values[2] = clamp_float(r->speed_dps * DEG_TO_RAD, f[2].lo, f[2].hi);
    values[3] = clamp_float(r->current_a * m->plant.p.torque_constant_nm_per_a, f[3].lo, f[3].hi);
    if (sb_pack(SB_LAYOUT_MIT_REPLY, f, values, 1, 8, 0, o, 8, NULL) != SB_OK)
        memset(o, 0, 8); /* unreachable: the values are clamped and the fields checked on entry */
}

/* 0xB6 (_active_reply): off removes the stream; on replaces it in place or appends it (dict order). */
static void active_reply(sb_ma_state *s, const request *q, double now_s)
{
    int at = 0;
    while (at < s->n_streams && s->streams[at].command != q->pct)
        at++;
    if (!q->enabled) {
        if (at < s->n_streams) {
            memmove(&s->streams[at], &s->streams[at + 1], (size_t)(s->n_streams - at - 1) * sizeof(sb_ma_stream));
            s->n_streams--;
        }
    } else {
        if (at == s->n_streams)
            s->n_streams++;
        s->streams[at].command = q->pct;
        s->streams[at].count = 1;
        s->streams[at].interval_s = (double)q->interval_code * STREAM_STEP_S;
        s->streams[at].origin_s = now_s;
    }
    s->dirty |= SB_MA_DIRTY_STREAMS;
}

/* ---- checks ---- */

static int fields_ok(const sb_field *f, int n)
{
    for (int k = 0; k < n; k++)
        if (!(isfinite(f[k].lo) && isfinite(f[k].hi) && isfinite(f[k].origin) && isfinite(f[k].codes) &&
              isfinite(f[k].span) && f[k].lo <= f[k].hi && f[k].codes > 0 && f[k].span > 0))
            return 0;
    return 1;
}

static int streams_ok(const sb_ma_state *s)
{
    for (int i = 0; i < s->n_streams; i++) {
        const sb_ma_stream *st = &s->streams[i];
        if (!is_streamable((uint8_t)st->command) || st->command != (uint8_t)st->command ||
            !(st->interval_s > 0 && st->interval_s < INFINITY) || !isfinite(st->origin_s) || st->count < 0 ||
            st->count > STREAM_COUNT_LIMIT)
            return 0;
    }
    return 1;
}

/* What the arithmetic above relies on, whatever was written into the state. */
static int state_ok(const sb_ma_state *s)
{
    return s->motor_id >= 1 && s->motor_id <= 32 && s->counts_per_turn >= 1 && s->counts_per_turn <= 65536 &&
           s->n_streams >= 0 && s->n_streams <= SB_MA_MAX_STREAMS && s->base_counts > -(int64_t)COUNT_LIMIT &&
           s->base_counts < (int64_t)COUNT_LIMIT && s->offset_counts > -(int64_t)COUNT_LIMIT &&
           s->offset_counts < (int64_t)COUNT_LIMIT && s->comm_timeout_ms >= 0 &&
           isfinite(s->encoder_gear_ratio) && s->encoder_gear_ratio != 0.0 && streams_ok(s);
}

static int stream_due(const sb_ma_stream *st, double now_s)
{
    return st->origin_s + (double)st->count * st->interval_s <= now_s;
}

/* ---- entry points ---- */

int sb_ma_receive(sb_simmotor *m, const sb_simframe *in, double now_s, sb_simframe *out, int cap, int *n_out)
{
    sb_ma_state *s;
    readings r;
    request q;
    uint32_t id;
    int motor_id, motion = 0;

    if (!m || !in || !n_out || cap < 0 || (cap > 0 && !out) || m->family != SB_FAMILY_MYACTUATOR ||
        in->len > SB_SIM_MAX_DATA || isnan(now_s))
        return SB_E_ARG;
    *n_out = 0;
    s = state_of(m);
    if (!m->hot || !state_ok(s) || sb_plant_check(&m->plant) != SB_OK)
        return SB_HOT_COLD;
    if (m->py_deadline_s <= now_s)
        return SB_HOT_COLD; /* the 0xB3 trip (or anything else of the model's) comes first */
    motor_id = s->motor_id;
    id = in->id;
    if (!(in->flags & (SB_FRAME_EXT | SB_FRAME_FD))) {
        if (id == REQUEST_BASE + (uint32_t)motor_id || (id == BROADCAST_ID && !s->can_id_filter)) {
            if (in->len != 8 || !decode_standard(s, in->data, &q))
                return SB_HOT_COLD;
        } else if (id == MOTION_REQUEST_BASE + (uint32_t)motor_id) {
            /* (sb_unpack checks the command's scales; the reply's are checked here) */
            if (in->len != 8 || !fields_ok(s->motion_reply, 4) || !decode_motion(s, in->data, &q))
                return SB_HOT_COLD;
            motion = 1;
        } else if (id == ID_SETTING_ID && !s->can_id_filter) {
            return SB_HOT_COLD; /* 0x79 */
        } else {
            q.kind = K_NONE; /* filtered or another identifier: counted below */
        }
    } else {
        q.kind = K_NONE;
    }
    sb_plant_advance(&m->plant, now_s);
    if (q.kind != K_NONE && !read_plant(m, s, &r))
        return SB_HOT_COLD; /* nothing has changed: advancing is an observation */
    if (q.kind != K_NONE && q.kind != K_ACTIVE_REPLY && s->n_streams == 0 && cap < 1)
        return SB_E_ARG;

    /* receive(): counted, routed */
    m->counters[SB_MA_CTR_RECEIVED] += 1;
    s->dirty |= SB_MA_DIRTY_COUNTERS;
    if (q.kind == K_NONE) {
        if (in->flags & (SB_FRAME_EXT | SB_FRAME_FD))
            m->counters[SB_MA_CTR_IGNORED_KIND] += 1;
        else if ((id == BROADCAST_ID || id == ID_SETTING_ID) && s->can_id_filter)
            m->counters[SB_MA_CTR_FILTERED] += 1;
        else
            m->counters[SB_MA_CTR_IGNORED_ID] += 1;
        return SB_HOT_DONE;
    }

    /* handle(): accepted, heard (the 0xB3 deadline moves), executed */
    m->counters[SB_MA_CTR_ACCEPTED] += 1;
    s->last_heard_s = now_s;
    s->dirty |= SB_MA_DIRTY_HEARD;
    if (s->comm_timeout_ms > 0)
        m->py_deadline_s = now_s + (double)s->comm_timeout_ms / 1000.0;
    if (q.kind == K_ACTIVE_REPLY) {
        active_reply(s, &q, now_s);
        return SB_HOT_DONE; /* NO_REPLY */
    }
    if (q.kind != K_READ)
        control_command(m, s, &q, &r); /* the model reads after this: the observed state is the same */
    if (s->n_streams > 0) {
        m->counters[SB_MA_CTR_SILENCED] += 1;
        return SB_HOT_DONE;
    }
    m->counters[SB_MA_CTR_REPLIED] += 1;

    memset(out, 0, sizeof *out);
    out->t = now_s + m->turnaround_s;
    out->len = 8;
    out->id = (motion ? MOTION_REPLY_BASE : REPLY_BASE) + (uint32_t)motor_id;
    switch (q.kind) {
    case K_MOTION: motion_reply(m, s, &r, out->data); break;
    case K_SINGLE_TURN: single_turn_status_reply(s, &r, out->data); break;
    case K_READ: read_reply(s, &r, q.code, out->data); break;
    case K_TORQUE: case K_SPEED: case K_ABSOLUTE: case K_INCREMENTAL: case K_FORCE: case K_FF_SPEED:
    case K_FF_TORQUE:
        status_reply(q.code, &r, out->data);
        break;
    case K_NONE: case K_ACTIVE_REPLY:
        return SB_HOT_DONE;
    }
    *n_out = 1;
    return SB_HOT_DONE;
}

int sb_ma_poll(sb_simmotor *m, double now_s, sb_simframe *out, int cap, int *n_out)
{
    sb_ma_state *s;
    readings r;
    int due = 0;

    if (!m || !n_out || cap < 0 || (cap > 0 && !out) || m->family != SB_FAMILY_MYACTUATOR || isnan(now_s))
        return SB_E_ARG;
    *n_out = 0;
    s = state_of(m);
    if (!m->hot || !state_ok(s) || sb_plant_check(&m->plant) != SB_OK || m->py_deadline_s <= now_s)
        return SB_HOT_COLD;
    for (int i = 0; i < s->n_streams; i++) {
        const sb_ma_stream *st = &s->streams[i];
        if (!stream_due(st, now_s))
            continue;
        if (!((now_s - st->origin_s) / st->interval_s < (double)STREAM_COUNT_LIMIT))
            return SB_HOT_COLD; /* a schedule this far behind is left to the model's exact integers */
        due++;
    }
    if (due == 0)
        return SB_HOT_DONE;
    if (cap < due)
        return SB_E_ARG;
    sb_plant_advance(&m->plant, now_s);
    if (!read_plant(m, s, &r))
        return SB_HOT_COLD;
    /* spontaneous(): each due stream in order, its schedule moved past now_s, its read's reply sent now */
    for (int i = 0; i < s->n_streams; i++) {
        sb_ma_stream *st = &s->streams[i];
        sb_simframe *o;
        double due_slots;
        int64_t slots, skipped;
        if (!stream_due(st, now_s))
            continue;
        due_slots = floor((now_s - st->origin_s) / st->interval_s + 1e-9);
        slots = (int64_t)due_slots + 1;
        skipped = slots - st->count - 1;
        m->counters[SB_MA_CTR_STREAM_SKIPPED] += skipped > 0 ? skipped : 0;
        m->counters[SB_MA_CTR_STREAM_FRAMES] += 1;
        st->count = st->count + 1 > slots ? st->count + 1 : slots;
        o = &out[(*n_out)++];
        memset(o, 0, sizeof *o);
        o->t = now_s;
        o->id = REPLY_BASE + (uint32_t)s->motor_id;
        o->len = 8;
        read_reply(s, &r, (uint8_t)st->command, o->data);
    }
    s->dirty |= SB_MA_DIRTY_COUNTERS | SB_MA_DIRTY_STREAMS;
    return SB_HOT_DONE;
}

double sb_ma_next_deadline(const sb_simmotor *m)
{
    const sb_ma_state *s;
    double next = INFINITY;

    if (!m || m->family != SB_FAMILY_MYACTUATOR || !m->hot)
        return INFINITY;
    s = cstate_of(m);
    if (!state_ok(s))
        return INFINITY;
    for (int i = 0; i < s->n_streams; i++) {
        const sb_ma_stream *st = &s->streams[i];
        double t = st->origin_s + (double)st->count * st->interval_s;
        if (t < next)
            next = t;
    }
    return next;
}
