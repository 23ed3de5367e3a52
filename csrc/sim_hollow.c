/* The hollow family's hot path: the set-point frames and their replies, byte for byte as the Python
 * model (src/servobus/protocols/hollow/sim/device.py, the reference) handles them.
 *
 * Hot (handled here): on the motor's id, a standard-id classic 8-byte setpoint (absolute in normal
 * CAN mode, an increment in extended mode, hollow.md §4.2, §5.2) when the motor is classic, a 16-byte
 * CAN FD command (§7.2, its zero bit included) when it is FD; frames of the wrong kind or length and
 * undecodable FD bytes are counted and dropped, as the model does. Cold (the Python model): the
 * special commands FF x7 + F9..FE (§4.1), every extended-id frame (mode switch, PI multipliers) and
 * any frame while the model's guards say no (m->hot == 0: unresponsive, reply jitter).
 *
 * The scaling is the codec's own: the frames are unpacked and the replies packed by sb_unpack /
 * sb_pack with the field scales servobus.protocols.hollow.model.packers() builds, computed here in
 * the same order of operations; clamps and roundings are written as the model's (Python's max/min,
 * round() = nearbyint). The reply is packed before anything changes, so a value the codec would
 * refuse (the model raises) leaves the motor as it was and goes cold. */
#include <math.h>
#include <string.h>

#include "sb_internal.h"

_Static_assert(sizeof(sb_hollow_state) <= sizeof(((sb_simmotor *)0)->state),
               "sb_hollow_state must fit sb_simmotor.state");

#define SETPOINT_SIZE 8
#define FD_SIZE 16
#define CAN_MODE_EXTENDED 0
#define MODE_TORQUE 0
#define MODE_VELOCITY 1
#define COUNTS_PER_TURN 1048576.0 /* 2**20, §5.3 / §7.2 */

static const double DPS_PER_RAD_S = 180.0 / 3.141592653589793; /* the model's 180.0 / math.pi */
static const double DPS_PER_RPM = 6.0;

/* ---- the codec's field scales (servobus.core.packing.FieldScale constructors) ---- */

static sb_field offset_binary(double full_scale, int bits)
{
    sb_field f = {-full_scale, full_scale, -full_scale, (double)((int64_t)1 << bits), 2 * full_scale};
    return f;
}

static sb_field integer(double lo, double hi)
{
    sb_field f = {lo, hi, 0.0, 1.0, 1.0};
    return f;
}

static sb_field twos_complement(int bits, double codes, double span)
{
    double top = (double)((int64_t)1 << (bits - 1));
    sb_field f = {-top * span / codes, (top - 1) * span / codes, 0.0, codes, span};
    return f;
}

/* Python's max(lo, min(hi, x)), NaN and all. */
static double clamp(double x, double lo, double hi)
{
    double m = x < hi ? x : hi;
    return m > lo ? m : lo;
}

static int is_special(const uint8_t *d)
{
    for (int i = 0; i < 7; i++)
        if (d[i] != 0xFF)
            return 0;
    return d[7] >= 0xF9 && d[7] <= 0xFE;
}

static void count(sb_simmotor *m, int key) { m->counters[key] += 1; }

/* ---- replies (HollowMotor.status_reply) ---- */

static void reply_header(sb_simframe *o, const sb_hollow_state *s, double ready_s, int flags, int len)
{
    memset(o, 0, sizeof *o);
    o->t = ready_s;
    o->id = s->host_id;
    o->flags = (uint8_t)flags;
    o->len = (uint8_t)len;
}

/* The classic reply of the motor's CAN mode: 6 bytes normal, 8 extended. */
static int pack_classic_reply(const sb_hollow_state *s, const sb_plant_state *p, sb_simframe *o, double ready_s)
{
    double pos = p->position_deg - s->zero_offset_deg;
    double v[4];
    sb_field f[4];
    int extended = s->can_mode == CAN_MODE_EXTENDED;
    int layout = extended ? SB_LAYOUT_HOLLOW_EXT_REPLY : SB_LAYOUT_MIT_REPLY;
    int size = extended ? 8 : 6;

    f[0] = integer(0, 255);
    f[2] = offset_binary(s->speed_full_scale_rad_s, 12);
    f[3] = offset_binary(s->current_full_scale_a, 12);
    v[0] = (double)s->motor_id;
    v[2] = clamp(p->speed_dps / DPS_PER_RAD_S, -s->speed_full_scale_rad_s, s->speed_full_scale_rad_s);
    v[3] = clamp(p->current_a, -s->current_full_scale_a, s->current_full_scale_a);
    if (extended) {
        f[1] = twos_complement(32, COUNTS_PER_TURN, 360.0);
        v[1] = clamp(pos, f[1].lo, f[1].hi); /* EXTENDED_POSITION_LIMITS_DEG, computed alike */
    } else {
        double full = s->position_full_scale_deg; /* A34: the code sticks at the ends */
        f[1] = offset_binary(full, 16);
        v[1] = clamp(pos, -full, full);
    }
    reply_header(o, s, ready_s, 0, size);
    return sb_pack(layout, f, v, 1, (size_t)size, 0, o->data, sizeof o->data, NULL);
}

/* The CAN FD reply for a motor in ctrl_mode / enabled with its zero at zero_offset_deg. */
static int pack_fd_reply(const sb_hollow_state *s, const sb_plant_state *p, int ctrl_mode, int enabled,
                         double zero_offset_deg, sb_simframe *o, double ready_s)
{
    double v[8];
    sb_field f[8];

    f[0] = twos_complement(40, COUNTS_PER_TURN, 360.0);
    f[1] = twos_complement(32, s->fd_velocity_counts_per_rpm, 1.0);
    f[2] = twos_complement(16, 1.0, 1.0);
    f[3] = integer(0, 255);
    f[4] = integer(0, 255);
    f[5] = integer(0, 255);
    f[6] = integer(-128, 127);
    f[7] = integer(0, 255);
    v[0] = p->position_deg - zero_offset_deg;
    v[1] = p->speed_dps / DPS_PER_RPM;
    v[2] = nearbyint(clamp(p->current_a / s->fd_current_a_per_count, -32768.0, 32767.0));
    v[3] = (double)ctrl_mode;
    v[4] = enabled ? 1.0 : 0.0;
    v[5] = 0.0;
    v[6] = nearbyint(clamp(p->temperature_c, -125.0, 125.0));
    v[7] = (double)s->motor_id;
    reply_header(o, s, ready_s, SB_FRAME_FD | SB_FRAME_BRS, FD_SIZE);
    return sb_pack(SB_LAYOUT_HOLLOW_FD_REPLY, f, v, 1, FD_SIZE, 0, o->data, sizeof o->data, NULL);
}

/* ---- the model's state changes ---- */

/* HollowMotor._control(): the plant control for the present state. */
static void set_control(sb_simmotor *m, const sb_hollow_state *s)
{
    sb_control c;
    memset(&c, 0, sizeof c);
    if (!s->enabled) {
        c.mode = SB_CONTROL_OFF;
    } else if (!s->has_setpoint) {
        c.mode = SB_CONTROL_CURRENT; /* start without a setpoint: zero current */
        c.a = 0.0;
    } else if (s->ctrl_mode == MODE_TORQUE) {
        c.mode = SB_CONTROL_CURRENT;
        c.a = s->current_a;
    } else if (s->ctrl_mode == MODE_VELOCITY) {
        c.mode = SB_CONTROL_SPEED;
        c.a = s->speed_dps;
        c.b = fabs(s->current_a);
    } else {
        c.mode = SB_CONTROL_POSITION;
        c.a = s->target_deg + s->zero_offset_deg;
        c.b = fabs(s->speed_dps);
        c.c = fabs(s->current_a);
    }
    sb_plant_set_control(&m->plant, &c);
}

static void hold(sb_hollow_state *s, double target_deg, double speed_dps, double current_a, int kp, int kd)
{
    s->has_setpoint = 1;
    s->target_deg = target_deg;
    s->speed_dps = speed_dps;
    s->current_a = current_a;
    s->kp = kp;
    s->kd = kd;
}

/* A classic 8-byte setpoint, not the special pattern: Setpoint or IncrementalSetpoint (§4.2, §5.2). */
static int classic_setpoint(sb_simmotor *m, sb_hollow_state *s, const uint8_t *data, double now_s,
                            sb_simframe *out)
{
    sb_field f[5];
    double v[5];
    const sb_plant_state *p = &m->plant.now;

    f[0] = offset_binary(s->position_full_scale_deg, 16);
    f[1] = offset_binary(s->speed_full_scale_rad_s, 12);
    f[2] = integer(0, 4095);
    f[3] = integer(0, 4095);
    f[4] = offset_binary(s->current_full_scale_a, 12);
    if (sb_unpack(SB_LAYOUT_HOLLOW_SETPOINT, f, data, 1, SETPOINT_SIZE, v, 5) != SB_OK)
        return SB_HOT_COLD;
    /* The reply reports the plant at now_s, which setting a control does not change. */
    if (pack_classic_reply(s, p, out, now_s + m->turnaround_s) != SB_OK)
        return SB_HOT_COLD;
    count(m, SB_HOLLOW_RECEIVED);
    count(m, SB_HOLLOW_ACCEPTED);
    if (s->can_mode == CAN_MODE_EXTENDED) {
        /* A11: each frame moves the target once; the first one starts from where the motor is. */
        double base = s->has_setpoint ? s->target_deg : p->position_deg - s->zero_offset_deg;
        hold(s, base + v[0], v[1] * DPS_PER_RAD_S, v[4], (int)v[2], (int)v[3]);
    } else {
        hold(s, v[0], v[1] * DPS_PER_RAD_S, v[4], (int)v[2], (int)v[3]);
    }
    set_control(m, s);
    count(m, SB_HOLLOW_REPLIED);
    return SB_HOT_DONE;
}

/* The 16-byte CAN FD command (§7.2, §13): mode, run, setpoint, then zero if not running. Returns
 * -1 for bytes the codec does not decode (undecodable), else SB_HOT_*. */
static int fd_command(sb_simmotor *m, sb_hollow_state *s, const uint8_t *data, double now_s, sb_simframe *out)
{
    sb_field f[8];
    double v[8];
    const sb_plant_state *p = &m->plant.now;
    int mode, run, zero, refused;
    double zero_offset = s->zero_offset_deg;

    if (data[11] > 2 || data[12] > 1 || data[15] > 1) /* Mode Sel, Run Cmd, Zero */
        return -1;
    f[0] = twos_complement(40, COUNTS_PER_TURN, 360.0);
    f[1] = twos_complement(32, s->fd_velocity_counts_per_rpm, 1.0);
    f[2] = twos_complement(16, 1.0, 1.0);
    f[3] = integer(0, 2);
    f[4] = integer(0, 1);
    f[5] = integer(0, 255);
    f[6] = integer(0, 255);
    f[7] = integer(0, 1);
    if (sb_unpack(SB_LAYOUT_HOLLOW_FD_COMMAND, f, data, 1, FD_SIZE, v, 8) != SB_OK)
        return SB_HOT_COLD;
    mode = data[11];
    run = data[12];
    zero = data[15];
    refused = zero && run;
    if (zero && !run)
        zero_offset = p->position_deg;
    if (pack_fd_reply(s, p, mode, run, zero_offset, out, now_s + m->turnaround_s) != SB_OK)
        return SB_HOT_COLD;
    count(m, SB_HOLLOW_RECEIVED);
    count(m, SB_HOLLOW_ACCEPTED);
    s->ctrl_mode = mode;
    s->enabled = run;
    hold(s, v[0], v[1] * DPS_PER_RPM, (double)(int64_t)v[2] * s->fd_current_a_per_count, (int)v[5],
         (int)v[6]);
    if (refused)
        count(m, SB_HOLLOW_ZERO_REFUSED);
    s->zero_offset_deg = zero_offset;
    set_control(m, s);
    count(m, SB_HOLLOW_REPLIED);
    return SB_HOT_DONE;
}

/* ---- the family contract (sim_core.h) ---- */

static int check_motor(const sb_simmotor *m)
{
    return m && m->family == SB_FAMILY_HOLLOW;
}

/* A frame the model counts and drops: received + `key`, the plant advanced (HollowMotor.receive). */
static int dropped(sb_simmotor *m, int key, double now_s)
{
    sb_plant_advance(&m->plant, now_s);
    count(m, SB_HOLLOW_RECEIVED);
    count(m, key);
    return SB_HOT_DONE;
}

int sb_hollow_receive(sb_simmotor *m, const sb_simframe *in, double now_s, sb_simframe *out, int cap, int *n_out)
{
    sb_hollow_state *s;
    int fd, status;

    if (!n_out)
        return SB_E_ARG;
    *n_out = 0;
    if (!check_motor(m) || !in || cap < 0 || (cap > 0 && !out) || in->len > SB_SIM_MAX_DATA || isnan(now_s))
        return SB_E_ARG;
    if (!m->hot)
        return SB_HOT_COLD;
    s = (sb_hollow_state *)m->state;
    fd = (in->flags & SB_FRAME_FD) != 0;
    if (in->id != s->motor_id) /* checked before the kind, as the model does */
        return dropped(m, SB_HOLLOW_IGNORED_ID, now_s);
    if (in->flags & SB_FRAME_EXT) {
        /* §6 / A17: PI frames come classic or FD in CAN FD mode; a classic controller cannot
         * receive FD frames. The rest (mode switch, PI multipliers) is the model's. */
        if (fd && !s->fd_enabled)
            return dropped(m, SB_HOLLOW_IGNORED_KIND, now_s);
        return SB_HOT_COLD;
    }
    if (fd != (s->fd_enabled != 0))
        return dropped(m, SB_HOLLOW_IGNORED_KIND, now_s);
    if (fd ? in->len != FD_SIZE : in->len != SETPOINT_SIZE)
        return dropped(m, SB_HOLLOW_UNDECODABLE, now_s);
    if (!fd && is_special(in->data))
        return SB_HOT_COLD; /* start / stop / mode select / zero */
    if (cap < 1)
        return SB_HOT_COLD; /* nowhere to put the reply: the model answers */
    sb_plant_advance(&m->plant, now_s);
    if (fd) {
        status = fd_command(m, s, in->data, now_s, out);
        if (status < 0)
            return dropped(m, SB_HOLLOW_UNDECODABLE, now_s);
    } else {
        status = classic_setpoint(m, s, in->data, now_s, out);
    }
    if (status == SB_HOT_DONE)
        *n_out = 1;
    return status;
}

int sb_hollow_poll(sb_simmotor *m, double now_s, sb_simframe *out, int cap, int *n_out)
{
    if (!n_out)
        return SB_E_ARG;
    *n_out = 0;
    if (!check_motor(m) || cap < 0 || (cap > 0 && !out) || isnan(now_s))
        return SB_E_ARG;
    if (!m->hot)
        return SB_HOT_COLD;
    /* The motor never transmits on its own (§3, "pure slave"): only the plant moves on. */
    sb_plant_advance(&m->plant, now_s);
    return SB_HOT_DONE;
}

double sb_hollow_next_deadline(const sb_simmotor *m)
{
    (void)m; /* no deadlines of its own, whatever the argument */
    return INFINITY;
}
