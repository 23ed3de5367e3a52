/* The lk family's C path: LK's control-loop traffic, byte for byte as the Python model answers it
 * (src/servobus/protocols/lk/sim/: device.py, control.py, replies.py, state.py are the reference).
 *
 * Float operations are written in the order the Python reference evaluates them (-ffp-contract=off):
 * Python's min/max, float % and round() have their exact C twins below. Everything the model does
 * that is not here (parameters, zeroing, brake, calibration, undecodable bytes, latched errors via
 * sb_simmotor.hot) is SB_HOT_COLD, decided before anything changes. The one change a COLD may
 * follow is the plant's advance to the frame's time (only for a 0x92/0x94 reading too large for
 * its field, where the model itself fails): the grid rule makes it invisible (the state at a time
 * does not depend on when it was looked at). */
#include <math.h>
#include <string.h>
#include "sb_internal.h"
#include "sim_pymath.h"

_Static_assert(sizeof(sb_lk_state) <= sizeof(((sb_simmotor *)0)->state), "sb_lk_state must fit sb_simmotor.state");

#define LK_REQUEST_BASE 0x140u
#define LK_REPLY_BASE_V236 0x180u
#define LK_MULTI_ID 0x280u
#define LK_LEN 8
#define LK_POLE_PAIRS 14        /* replies.py _POLE_PAIRS */
#define LK_OPEN_LOOP 0xA0
#define LK_MULTI_REPLY_CODE 0xA1

static const double LK_PI = 3.14159265358979323846;  /* math.pi */
static const double LK_NO_SPEED_DPS = 1e-9;          /* control.py _NO_SPEED_DPS */

/* ---- Python's arithmetic ---- */

static double py_clamp(double x, double lo, double hi) { return py_max(lo, py_min(hi, x)); }

static int64_t py_imod(int64_t a, int64_t b)  /* int % int, b > 0 */
{
    int64_t r = a % b;
    return r < 0 ? r + b : r;
}

static double half_away(double x) { return copysign(floor(fabs(x) + 0.5), x); }  /* _fields.round_half_away */

static double radians(double deg) { return deg * (LK_PI / 180.0); }  /* math.radians */

/* x ** 2 as CPython computes it (libm pow, which the compiler would otherwise fold into x * x). */
static double py_square(double x)
{
    double (*volatile power)(double, double) = pow;
    return power(x, 2.0);
}

/* ---- little-endian fields ---- */

static int32_t get_i16(const uint8_t *d) { return (int16_t)(uint16_t)(d[0] | (d[1] << 8)); }
static uint32_t get_u16(const uint8_t *d) { return (uint32_t)d[0] | ((uint32_t)d[1] << 8); }
static uint32_t get_u32(const uint8_t *d)
{
    return (uint32_t)d[0] | ((uint32_t)d[1] << 8) | ((uint32_t)d[2] << 16) | ((uint32_t)d[3] << 24);
}
static int32_t get_i32(const uint8_t *d) { return (int32_t)get_u32(d); }

static void put_le(uint8_t *d, int64_t v, int size)
{
    uint64_t u = (uint64_t)v;
    for (int i = 0; i < size; i++)
        d[i] = (uint8_t)(u >> (8 * i));
}

/* ---- the motor ---- */

static sb_lk_state *lk(sb_simmotor *m) { return (sb_lk_state *)(void *)m->state; }

static int state_ok(const sb_lk_state *s)
{
    return (s->revision == SB_LK_V2_36 || s->revision == SB_LK_V2_35) && s->motor_type >= SB_LK_MS &&
           s->motor_type <= SB_LK_MG && s->motor_id >= 1 && s->motor_id <= 32 &&
           (s->per_turn == 1 << 14 || s->per_turn == 1 << 15 || s->per_turn == 1 << 16) &&
           s->run_state >= SB_LK_ON && s->run_state <= SB_LK_OFF && s->angle_offset >= 0 &&
           s->angle_offset < s->per_turn && isfinite(s->amps_per_count) && s->amps_per_count > 0 &&
           ((s->motor_type != SB_LK_MF && s->motor_type != SB_LK_MG) || s->iq_counts_per_amp > 0);
}

/* The frames the model ignores (device.py _ignore_reason): a counter index, or -1 for "act on it". */
static int ignore_reason(const sb_lk_state *s, const sb_simframe *in, double now_s)
{
    if (in->flags & (SB_FRAME_EXT | SB_FRAME_FD))
        return SB_LK_N_IGNORED_KIND;
    if (in->id == LK_MULTI_ID) {
        if (s->revision != SB_LK_V2_35)
            return SB_LK_N_OTHER_REVISION;
        if (s->motor_id > 4)
            return SB_LK_N_IGNORED_ID;
    } else if (in->id != LK_REQUEST_BASE + (uint32_t)s->motor_id) {
        return SB_LK_N_IGNORED_ID;
    }
    if (now_s < s->busy_until_s)
        return SB_LK_N_BUSY;
    return -1;
}

/* What a request is, once decoded as the codec would (lk_decode). */
enum { K_STATUS1, K_STATUS2, K_STATUS3, K_ENCODER, K_MULTI_ANGLE, K_SINGLE_ANGLE, K_OFF, K_STOP, K_RUN,
       K_SETPOINT };
enum { S_OPEN_LOOP, S_TORQUE, S_SPEED, S_SPEED_V235, S_MULTI, S_MULTI_SPEED, S_SINGLE, S_SINGLE_SPEED,
       S_INCREMENT, S_INCREMENT_SPEED, S_MULTI_MOTOR };

typedef struct {
    int code;         /* the reply's DATA[0] */
    int kind;         /* K_* */
    int setpoint;     /* S_* */
    double value;     /* the decoded current (A), speed (dps), angle or increment (deg) */
    double limit;     /* 0xA2: the torque limit (A); 0xA4/0xA6/0xA8: maxSpeed (NAN: None) */
    int ccw;          /* 0xA5/0xA6: spinDirection COUNTER_CLOCKWISE */
} lk_request;

/* A request's current given in counts: amperes as the codec decodes them (MF, MG: count / (1 / A per
 * count)), raw counts times the model's A per count otherwise (control.py _amps). */
static double counts_to_amps(const sb_lk_state *s, int32_t counts)
{
    if (s->motor_type == SB_LK_MF || s->motor_type == SB_LK_MG)
        return counts / s->iq_counts_per_amp;
    return counts * s->amps_per_count;
}

static double max_speed_field(const uint8_t *d)  /* MAX_SPEED: uint16, 1 dps/LSB, 0 -> None */
{
    uint32_t code = get_u16(d);
    return code == 0 ? NAN : (double)code;
}

/* Decode the payload as decode_request does for the requests handled here. 0: decoded; 1: COLD
 * (another command, another revision's, or bytes the codec refuses: the model counts those). */
static int lk_decode(const sb_lk_state *s, const sb_simframe *in, lk_request *r)
{
    const uint8_t *d = in->data;
    int v235 = s->revision == SB_LK_V2_35;
    memset(r, 0, sizeof *r);
    r->limit = NAN;
    if (in->len != LK_LEN)
        return 1;
    if (in->id == LK_MULTI_ID) {  /* V2.35 only (ignore_reason): 4 x int16 iqControl, +-2000 each */
        if (s->motor_type == SB_LK_MS)
            return 1;
        for (int i = 0; i < 4; i++)
            if (get_i16(d + 2 * i) < -2000 || get_i16(d + 2 * i) > 2000)
                return 1;
        r->code = LK_MULTI_REPLY_CODE;
        r->kind = K_SETPOINT;
        r->setpoint = S_MULTI_MOTOR;
        r->value = counts_to_amps(s, get_i16(d + 2 * (s->motor_id - 1)));
        return 0;
    }
    r->code = d[0];
    switch (d[0]) {
    case 0x9A:
    case 0x9B: r->kind = K_STATUS1; return 0;
    case 0x9C: r->kind = K_STATUS2; return 0;
    case 0x9D: r->kind = K_STATUS3; return 0;
    case 0x90: r->kind = K_ENCODER; return 0;
    case 0x92: r->kind = K_MULTI_ANGLE; return 0;
    case 0x94: r->kind = K_SINGLE_ANGLE; return 0;
    case 0x80: r->kind = K_OFF; return 0;
    case 0x81: r->kind = K_STOP; return 0;
    case 0x88: r->kind = K_RUN; return 0;
    case 0xA0: {  /* POWER: int16 DATA[4..5], -850..850 */
        int32_t power = get_i16(d + 4);
        if (power < -850 || power > 850)
            return 1;
        r->kind = K_SETPOINT;
        r->setpoint = S_OPEN_LOOP;
        r->value = power * s->amps_per_count;
        return 0;
    }
    case 0xA1: {  /* TORQUE: int16 DATA[4..5], +-2048; MS has no torque loop (the model: not_implemented) */
        int32_t iq = get_i16(d + 4);
        if (s->motor_type == SB_LK_MS || iq < -2048 || iq > 2048)
            return 1;
        r->kind = K_SETPOINT;
        r->setpoint = S_TORQUE;
        r->value = counts_to_amps(s, iq);
        return 0;
    }
    case 0xA2:
        r->kind = K_SETPOINT;
        r->value = get_i32(d + 4) / 100.0;
        if (v235) {
            r->setpoint = S_SPEED_V235;
            return 0;
        } else {  /* TORQUE_LIMIT: int16 DATA[2..3], +-2048, 0 refused */
            int32_t iq = get_i16(d + 2);
            if (iq == 0 || iq < -2048 || iq > 2048)
                return 1;
            r->setpoint = S_SPEED;
            r->limit = fabs(counts_to_amps(s, iq));
            return 0;
        }
    case 0xA3:
    case 0xA4:
        r->kind = K_SETPOINT;
        r->setpoint = d[0] == 0xA3 ? S_MULTI : S_MULTI_SPEED;
        r->value = get_i32(d + 4) / 100.0;
        if (d[0] == 0xA4)
            r->limit = max_speed_field(d + 2);
        return 0;
    case 0xA5:
    case 0xA6:
        if (d[1] > 1)  /* SpinDirection */
            return 1;
        if (v235) {  /* uint16 DATA[4..5], 0..359.99 */
            uint32_t angle = get_u16(d + 4);
            if (angle > 35999)
                return 1;
            r->value = angle / 100.0;
        } else {
            r->value = get_u32(d + 4) / 100.0;
        }
        r->kind = K_SETPOINT;
        r->setpoint = d[0] == 0xA5 ? S_SINGLE : S_SINGLE_SPEED;
        r->ccw = d[1] == 1;
        if (d[0] == 0xA6)
            r->limit = max_speed_field(d + 2);
        return 0;
    case 0xA7:
    case 0xA8:
        r->kind = K_SETPOINT;
        r->setpoint = d[0] == 0xA7 ? S_INCREMENT : S_INCREMENT_SPEED;
        r->value = get_i32(d + 4) / 100.0;
        if (d[0] == 0xA8)
            r->limit = max_speed_field(d + 2);
        return 0;
    }
    return 1;
}

/* ---- readings (replies.py, state.py AngleFrame) ---- */

typedef struct {
    int64_t total;        /* the shaft's cumulative encoder count */
    double multi_turn_deg;
} lk_angles;

/* 1: the count does not fit (a position the model could not read either). */
static int read_angles(const sb_simmotor *m, const sb_lk_state *s, lk_angles *a)
{
    double motor_deg = m->plant.now.position_deg * m->plant.p.gear_ratio;  /* Plant.motor_position_deg */
    double counts = floor(motor_deg / 360.0 * s->per_turn);                /* AngleFrame.total */
    if (!(fabs(counts) < 4.0e18))
        return 1;
    a->total = (int64_t)counts;
    a->multi_turn_deg = (double)(a->total - s->angle_origin) * 360.0 / s->per_turn;
    return 0;
}

static int64_t encoder_counts(const sb_lk_state *s, int64_t total)
{
    return py_imod(py_imod(total, s->per_turn) - s->angle_offset, s->per_turn);
}

static int temperature(const sb_plant *pl)
{
    return (int)py_clamp(nearbyint(pl->now.temperature_c), -128, 127);
}

/* Status-2 DATA[2..3]: the plant's current in counts, within the range the reply states. */
static int status2_counts(const sb_simmotor *m, const sb_lk_state *s, int code)
{
    double lo = -32768, hi = 32767;
    if (code != LK_OPEN_LOOP && s->motor_type != SB_LK_MS && s->revision == SB_LK_V2_35)
        lo = -2048, hi = 2048;  /* replies.torque_range */
    return (int)py_clamp(nearbyint(m->plant.now.current_a / s->amps_per_count), lo, hi);
}

static void status2(const sb_simmotor *m, const sb_lk_state *s, int code, int64_t total, uint8_t *d)
{
    const sb_plant *pl = &m->plant;
    d[0] = (uint8_t)code;
    d[1] = (uint8_t)(int8_t)temperature(pl);
    put_le(d + 2, status2_counts(m, s, code), 2);
    put_le(d + 4, (int64_t)py_clamp(nearbyint(pl->now.speed_dps * pl->p.gear_ratio), -32768, 32767), 2);
    put_le(d + 6, encoder_counts(s, total), 2);
}

static void status1(const sb_simmotor *m, const sb_lk_state *s, int code, uint8_t *d)
{
    const sb_plant *pl = &m->plant;
    const sb_plant_params *p = &pl->p;
    double current = pl->now.current_a;
    double voltage = p->supply_v - fabs(current) * p->supply_resistance_ohm;  /* Plant.voltage_v */
    memset(d, 0, LK_LEN);
    d[0] = (uint8_t)code;
    d[1] = (uint8_t)(int8_t)temperature(pl);
    if (s->revision == SB_LK_V2_35) {
        put_le(d + 3, (int64_t)half_away(py_clamp(voltage, 0.0, 6553.5) * 10), 2);
    } else {
        double power_w = py_square(current) * p->winding_resistance_ohm +
                         current * p->torque_constant_nm_per_a * radians(pl->now.speed_dps);
        double bus_a = py_clamp(voltage > 0 ? power_w / voltage : 0.0, -327.68, 327.67);
        put_le(d + 2, (int64_t)half_away(py_clamp(voltage, -327.68, 327.67) * 100), 2);
        put_le(d + 4, (int64_t)half_away(bus_a * 100), 2);
        d[6] = s->run_state == SB_LK_OFF ? 0x10 : 0x00;  /* MotorState */
    }
    d[7] = 0;  /* the latched errors: none while hot */
}

static void status3(const sb_simmotor *m, const sb_lk_state *s, uint8_t *d)
{
    const sb_plant *pl = &m->plant;
    double theta = radians(pl->now.position_deg * pl->p.gear_ratio * LK_POLE_PAIRS);
    double iq = pl->now.current_a;
    static const int ks[3] = {0, 1, -1};
    memset(d, 0, LK_LEN);
    d[0] = 0x9D;
    if (s->revision == SB_LK_V2_35) {
        for (int i = 0; i < 3; i++) {
            double x = -iq * sin(theta - (double)(ks[i] * 2) * LK_PI / 3);
            put_le(d + 2 + 2 * i, (int64_t)half_away(py_clamp(x, -512.0, 511.98) * 64), 2);
        }
        return;
    }
    d[1] = (uint8_t)(int8_t)temperature(pl);
    if (s->motor_type == SB_LK_MS)
        return;  /* no phase-current sampling: zeros */
    for (int i = 0; i < 3; i++) {
        double x = -iq * sin(theta - (double)(ks[i] * 2) * LK_PI / 3);
        /* MF/MG send ia * A/count in A, which encodes back to ia (checked for every int16) */
        put_le(d + 2 + 2 * i, (int64_t)py_clamp(nearbyint(x / s->amps_per_count), -32768, 32767), 2);
    }
}

/* 0x92 / 0x94 replies; 1: the value does not fit its field (the model raises: COLD). */
static int multi_angle(const lk_angles *a, uint8_t *d)
{
    double limit = 281474976710656.0 / 100;  /* replies_position.MULTI_TURN: +-2**48 / 100 */
    if (!(a->multi_turn_deg >= -limit && a->multi_turn_deg <= limit))
        return 1;
    memset(d, 0, LK_LEN);
    d[0] = 0x92;
    put_le(d + 1, (int64_t)half_away(a->multi_turn_deg * 100), 7);
    return 0;
}

static int single_angle(const sb_simmotor *m, const sb_lk_state *s, const lk_angles *a, uint8_t *d)
{
    double period = s->revision == SB_LK_V2_36 ? 360.0 * m->plant.p.gear_ratio : 360.0;
    double period_centi = nearbyint(period * 100);
    double centi = floor(a->multi_turn_deg * 100 + 1e-6);
    if (!(period_centi >= 1 && period_centi <= 4294967295.0 && fabs(centi) < 4.0e18))
        return 1;
    double angle = (double)py_imod((int64_t)centi, (int64_t)period_centi) / 100;  /* single_turn_deg */
    memset(d, 0, LK_LEN);
    d[0] = 0x94;
    if (s->revision == SB_LK_V2_36)
        put_le(d + 4, (int64_t)half_away(angle * 100), 4);
    else
        put_le(d + 6, (int64_t)half_away(angle * 100), 2);
    return 0;
}

/* ---- set-points (control.py) ---- */

static double torque_limit_a(const sb_lk_state *s) { return s->torque_counts * s->amps_per_count; }

static sb_control position_control(const sb_simmotor *m, const sb_lk_state *s, double target_deg, double speed_dps)
{
    sb_control c = {SB_CONTROL_POSITION, 0, 0, 0, 0, 0};
    c.a = target_deg;
    c.b = isfinite(speed_dps) ? py_max(speed_dps / m->plant.p.gear_ratio, LK_NO_SPEED_DPS) : NAN;
    c.c = torque_limit_a(s);
    return c;
}

static double single_turn_target(const sb_simmotor *m, const sb_lk_state *s, const lk_request *r,
                                 const lk_angles *a, double origin_deg)
{
    double ratio = m->plant.p.gear_ratio;
    double period = s->revision == SB_LK_V2_36 ? 360.0 * ratio : 360.0;
    double here = a->multi_turn_deg;
    double delta = py_mod(r->value - here, period);
    if (r->ccw && delta != 0.0)
        delta -= period;
    return (here + delta + origin_deg) / ratio;
}

static sb_control setpoint_control(const sb_simmotor *m, const sb_lk_state *s, const lk_request *r,
                                   const lk_angles *a)
{
    double ratio = m->plant.p.gear_ratio;
    double origin_deg = (double)s->angle_origin * 360.0 / s->per_turn;
    double speed = s->speed_limit_dps;
    double base;
    sb_control c = {SB_CONTROL_CURRENT, 0, 0, 0, 0, 0};
    switch (r->setpoint) {
    case S_OPEN_LOOP:
    case S_TORQUE:
    case S_MULTI_MOTOR:
        c.a = r->value;
        return c;
    case S_SPEED:
        c.mode = SB_CONTROL_SPEED;
        c.a = py_max(-s->speed_limit_dps, py_min(s->speed_limit_dps, r->value)) / ratio;
        c.b = r->limit;
        return c;
    case S_SPEED_V235:
        c.mode = SB_CONTROL_SPEED;
        c.a = r->value / ratio;
        c.b = torque_limit_a(s);
        return c;
    case S_MULTI:
    case S_MULTI_SPEED:
        if (r->setpoint == S_MULTI_SPEED && !isnan(r->limit))
            speed = r->limit;
        return position_control(
            m, s, (py_min(py_max(r->value, s->angle_lo_deg), s->angle_hi_deg) + origin_deg) / ratio, speed);
    case S_SINGLE:
    case S_SINGLE_SPEED:
        if (r->setpoint == S_SINGLE_SPEED && !isnan(r->limit))
            speed = r->limit;
        return position_control(m, s, single_turn_target(m, s, r, a, origin_deg), speed);
    case S_INCREMENT:
    case S_INCREMENT_SPEED:
        if (r->setpoint == S_INCREMENT)
            speed = s->revision == SB_LK_V2_36 ? s->speed_limit_dps : INFINITY;  /* D17 */
        else if (!isnan(r->limit))
            speed = r->limit;
        base = m->plant.now.position_deg;
        if (s->run_state == SB_LK_ON && s->has_held && s->held.mode == SB_CONTROL_POSITION)
            base = s->held.a;  /* increments add to the running target */
        return position_control(m, s, base + r->value / ratio, speed);
    }
    return c;  /* not reached: lk_decode sets one of the above */
}

/* device.py _control: what the plant is given after every frame the model acts on. */
static sb_control effective_control(const sb_lk_state *s, double now_s)
{
    sb_control c = {SB_CONTROL_OFF, 0, 0, 0, 0, 0};
    if (s->brake_engaged) {
        c.mode = SB_CONTROL_BRAKE;
        return c;
    }
    if (s->run_state == SB_LK_OFF || now_s < s->busy_until_s)
        return c;  /* latched errors: not hot */
    if (s->run_state == SB_LK_STOPPED) {
        c.mode = SB_CONTROL_SPEED;
        c.a = 0.0;
        c.b = torque_limit_a(s);
        return c;
    }
    return s->has_held ? s->held : c;
}

/* ---- the entry points ---- */

static int args_ok(const sb_simmotor *m, double now_s, const sb_simframe *out, int cap, const int *n_out)
{
    return m && n_out && out && cap >= 1 && m->family == SB_FAMILY_LK && !isnan(now_s) &&
           sb_plant_check(&m->plant) == SB_OK;  /* the plant functions would do nothing with it */
}

int sb_lk_receive(sb_simmotor *m, const sb_simframe *in, double now_s, sb_simframe *out, int cap, int *n_out)
{
    if (n_out)
        *n_out = 0;
    if (!args_ok(m, now_s, out, cap, n_out) || !in || in->len > SB_SIM_MAX_DATA)
        return SB_E_ARG;
    sb_lk_state *s = lk(m);
    if (!state_ok(s))
        return SB_E_ARG;
    if (!m->hot)
        return SB_HOT_COLD;
    int64_t *counters = m->counters;
    int reason = ignore_reason(s, in, now_s);
    if (reason >= 0) {
        sb_plant_advance(&m->plant, now_s);
        counters[SB_LK_N_RECEIVED]++;
        counters[reason]++;
        s->pending = 1;
        return SB_HOT_DONE;
    }
    lk_request r;
    if (lk_decode(s, in, &r))
        return SB_HOT_COLD;

    sb_plant_advance(&m->plant, now_s);
    lk_angles a;
    uint8_t reply[LK_LEN];
    if (read_angles(m, s, &a))
        return SB_HOT_COLD;
    switch (r.kind) {
    case K_MULTI_ANGLE:
        if (multi_angle(&a, reply))
            return SB_HOT_COLD;
        break;
    case K_SINGLE_ANGLE:
        if (single_angle(m, s, &a, reply))
            return SB_HOT_COLD;
        break;
    case K_STATUS1: status1(m, s, r.code, reply); break;
    case K_STATUS2: status2(m, s, r.code, a.total, reply); break;
    case K_STATUS3: status3(m, s, reply); break;
    case K_ENCODER:
        memset(reply, 0, LK_LEN);
        reply[0] = 0x90;
        put_le(reply + 2, encoder_counts(s, a.total), 2);
        put_le(reply + 4, py_imod(a.total, s->per_turn), 2);
        put_le(reply + 6, s->angle_offset, 2);
        break;
    case K_OFF:
        s->run_state = SB_LK_OFF;
        s->has_held = 0;
        if (s->revision == SB_LK_V2_36)  /* [001] §5: clear the turns (AngleFrame.clear_turns) */
            s->angle_origin = a.total - encoder_counts(s, a.total);
        memset(reply, 0, LK_LEN);
        reply[0] = 0x80;
        break;
    case K_STOP:
        if (s->run_state == SB_LK_ON)
            s->run_state = SB_LK_STOPPED;
        memset(reply, 0, LK_LEN);
        reply[0] = 0x81;
        break;
    case K_RUN:
        if (s->run_state == SB_LK_OFF || s->revision == SB_LK_V2_35)
            s->run_state = SB_LK_ON;
        memset(reply, 0, LK_LEN);
        reply[0] = 0x88;
        break;
    case K_SETPOINT: {
        sb_control c = setpoint_control(m, s, &r, &a);  /* from the context before it runs */
        if (r.setpoint == S_OPEN_LOOP && s->revision == SB_LK_V2_36 && s->motor_type != SB_LK_MS) {
            counters[SB_LK_N_NOT_IMPLEMENTED]++;  /* [001]: 0xA0 is MS only */
        } else if (s->revision == SB_LK_V2_36 && s->run_state == SB_LK_OFF) {
            counters[SB_LK_N_NOT_EXECUTED_OFF]++;  /* answered, not performed */
        } else {
            s->run_state = SB_LK_ON;
            s->has_held = 1;
            s->held = c;
        }
        status2(m, s, r.code, a.total, reply);
        break;
    }
    }
    counters[SB_LK_N_RECEIVED]++;
    counters[SB_LK_N_ACCEPTED]++;
    sb_control effective = effective_control(s, now_s);
    sb_plant_set_control(&m->plant, &effective);
    s->pending = 1;
    if (s->unresponsive) {
        counters[SB_LK_N_UNANSWERED]++;
        return SB_HOT_DONE;
    }
    counters[SB_LK_N_REPLIED]++;
    sb_simframe *f = &out[0];
    memset(f, 0, sizeof *f);
    f->t = now_s + m->turnaround_s;
    f->id = (s->revision == SB_LK_V2_36 ? LK_REPLY_BASE_V236 : LK_REQUEST_BASE) + (uint32_t)s->motor_id;
    f->len = LK_LEN;
    memcpy(f->data, reply, LK_LEN);
    *n_out = 1;
    return SB_HOT_DONE;
}

int sb_lk_poll(sb_simmotor *m, double now_s, sb_simframe *out, int cap, int *n_out)
{
    if (n_out)
        *n_out = 0;
    if (!args_ok(m, now_s, out, cap, n_out) || !state_ok(lk(m)))
        return SB_E_ARG;
    if (!m->hot)
        return SB_HOT_COLD;
    sb_plant_advance(&m->plant, now_s);  /* the model's poll: nothing to send */
    return SB_HOT_DONE;
}

double sb_lk_next_deadline(const sb_simmotor *m)
{
    (void)m;  /* an LK motor only answers: no deadlines of its own */
    return INFINITY;
}
