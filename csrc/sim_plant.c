/* The plant of one simulated actuator, on its grid (sim_plant.h): the same equations as
 * src/servobus/sim/plant.py, in the same order, so that with -ffp-contract=off every result is the
 * Python reference's bit for bit. Where Python's builtins differ from the obvious C, the C follows
 * Python: min(a, b) keeps a unless b < a, max(a, b) keeps a unless b > a (NaN and signed zeros
 * included), a limit of "None" is NAN here, and x*x is written out (never pow).
 *
 * A plant is caller memory: every entry point checks it (plant_ok) and leaves a bad one untouched. */
#include <math.h>

#include "sb_internal.h"
#include "sim_pymath.h"

#define SB_PI 3.141592653589793 /* math.pi: the double nearest pi */

static const double RAD_PER_DEG = SB_PI / 180.0;

/* plant.py _clamp: max(-limit, min(limit, value)) */
static inline double clamp(double value, double limit) { return py_max(-limit, py_min(limit, value)); }

static int mode_ok(int mode)
{
    switch (mode) {
    case SB_CONTROL_OFF:
    case SB_CONTROL_BRAKE:
    case SB_CONTROL_CURRENT:
    case SB_CONTROL_SPEED:
    case SB_CONTROL_POSITION:
    case SB_CONTROL_IMPEDANCE:
        return 1;
    }
    return 0;
}

/* A step that is not > 0 would never move the grid (and NaN would loop forever); past 2^53 steps
 * the grid's times are not exact (and steps + 1 must not overflow); the committed time is never
 * after now_s (nor are the times infinite or NaN). */
static int plant_ok(const sb_plant *pl)
{
    return pl != NULL && pl->max_step_s > 0 && mode_ok(pl->control.mode) && pl->steps >= 0
           && pl->steps < ((int64_t)1 << 53) && isfinite(pl->anchor_s) && isfinite(pl->now_s)
           && pl->anchor_s + (double)pl->steps * pl->max_step_s <= pl->now_s;
}

int sb_plant_check(const sb_plant *pl) { return plant_ok(pl) ? SB_OK : SB_E_ARG; }

static int unpowered_mode(int mode) { return mode == SB_CONTROL_OFF || mode == SB_CONTROL_BRAKE; }

/* plant.py Plant._at_rest */
static int at_rest(const sb_plant *pl, const sb_plant_state *s)
{
    int mode = pl->control.mode;
    int unpowered = unpowered_mode(mode) && s->current_a == 0.0;
    return unpowered && (s->speed_dps == 0.0 || mode == SB_CONTROL_BRAKE);
}

/* plant.py Plant._cool */
static void cool(const sb_plant *pl, sb_plant_state *s, double dt)
{
    const sb_plant_params *p = &pl->p;
    double tau = p->thermal_resistance_c_per_w * p->thermal_capacity_j_per_c;
    s->temperature_c = p->ambient_c + (s->temperature_c - p->ambient_c) * exp(-dt / tau);
    if (pl->control.mode == SB_CONTROL_BRAKE)
        s->speed_dps = 0.0;
}

/* plant.py Plant._speed_loop; max_current_a NAN: none */
static double speed_loop(const sb_plant *pl, sb_plant_state *s, double target_dps, double max_current_a,
                         double dt)
{
    const sb_plant_params *p = &pl->p;
    double limit = isnan(max_current_a) ? p->max_current_a : py_min(max_current_a, p->max_current_a);
    double step = clamp(target_dps - s->speed_ref, pl->acceleration_dps2 * dt);
    double feed_forward, omega, gain, error, command;

    s->speed_ref += step;
    feed_forward = p->inertia_kgm2 * step / dt * RAD_PER_DEG / p->torque_constant_nm_per_a;
    omega = 2 * SB_PI * p->speed_bandwidth_hz;
    gain = p->inertia_kgm2 * omega / p->torque_constant_nm_per_a;
    error = (s->speed_ref - s->speed_dps) * RAD_PER_DEG;
    command = gain * error + s->speed_integral + feed_forward;
    if (fabs(command) < limit)
        s->speed_integral += gain * (omega / 4) * error * dt;
    return clamp(command, limit);
}

/* plant.py Plant._current_command (the mode is checked on entry, so the last return is unreached) */
static double current_command(const sb_plant *pl, sb_plant_state *s, double dt)
{
    const sb_plant_params *p = &pl->p;
    const sb_control *c = &pl->control;
    double error, speed_error, torque, limit, wanted;

    switch (c->mode) {
    case SB_CONTROL_OFF:
    case SB_CONTROL_BRAKE:
        return 0.0;
    case SB_CONTROL_CURRENT:
        return clamp(c->a, p->max_current_a);
    case SB_CONTROL_IMPEDANCE:
        error = c->a - s->position_deg * RAD_PER_DEG;
        speed_error = c->b - s->speed_dps * RAD_PER_DEG;
        torque = c->c * error + c->d * speed_error + c->e;
        return clamp(torque / p->torque_constant_nm_per_a, p->max_current_a);
    case SB_CONTROL_POSITION:
        limit = isnan(c->b) ? p->max_speed_dps : py_min(c->b, p->max_speed_dps);
        error = c->a - s->position_deg;
        wanted = 2 * SB_PI * p->position_bandwidth_hz * error;
        limit = py_min(limit, sqrt(2 * pl->acceleration_dps2 * fabs(error)));
        return speed_loop(pl, s, clamp(wanted, limit), c->c, dt);
    case SB_CONTROL_SPEED:
        return speed_loop(pl, s, clamp(c->a, p->speed_limit_dps), c->b, dt);
    }
    return 0.0;
}

/* plant.py Plant._step */
static void step(const sb_plant *pl, sb_plant_state *s, double dt)
{
    const sb_plant_params *p = &pl->p;
    double command = current_command(pl, s, dt);
    double speed_rad, torque, heat_w, cooling_w;

    s->current_a += (command - s->current_a) * py_min(1.0, dt / p->current_time_constant_s);
    if (command == 0.0 && fabs(s->current_a) < 1e-6)
        s->current_a = 0.0;
    if (pl->control.mode == SB_CONTROL_BRAKE) {
        s->speed_dps = 0.0;
    } else {
        speed_rad = s->speed_dps * RAD_PER_DEG;
        torque = s->current_a * p->torque_constant_nm_per_a + pl->external_torque_nm
                 - p->viscous_friction_nm_s_per_rad * speed_rad;
        speed_rad += torque / p->inertia_kgm2 * dt;
        s->speed_dps = speed_rad / RAD_PER_DEG;
        if (s->current_a == 0.0 && pl->external_torque_nm == 0.0 && fabs(s->speed_dps) < 1e-6)
            s->speed_dps = 0.0;
    }
    s->position_deg += s->speed_dps * dt;
    heat_w = s->current_a * s->current_a * p->winding_resistance_ohm;
    cooling_w = (s->temperature_c - p->ambient_c) / p->thermal_resistance_c_per_w;
    s->temperature_c += (heat_w - cooling_w) / p->thermal_capacity_j_per_c * dt;
}

static int params_ok(const sb_plant_params *p)
{
    /* PlantParams.__post_init__: these must be > 0 (NaN is not) */
    return p->inertia_kgm2 > 0 && p->torque_constant_nm_per_a > 0 && p->gear_ratio > 0
           && p->max_current_a > 0 && p->max_speed_dps > 0 && p->current_time_constant_s > 0
           && p->speed_bandwidth_hz > 0 && p->position_bandwidth_hz > 0 && p->thermal_capacity_j_per_c > 0;
}

int sb_plant_init(sb_plant *pl, const sb_plant_params *params, double now_s, double max_step_s)
{
    sb_plant_state rest = {0};

    if (pl == NULL)
        return SB_E_ARG;
    *pl = (sb_plant){0}; /* max_step_s 0: refused by every other function until a good init */
    if (params == NULL || !params_ok(params) || !(max_step_s > 0) || isnan(now_s) || isinf(now_s))
        return SB_E_ARG;
    pl->p = *params;
    pl->max_step_s = max_step_s;
    pl->control.mode = SB_CONTROL_OFF;
    pl->acceleration_dps2 = params->max_acceleration_dps2;
    pl->external_torque_nm = 0.0;
    pl->anchor_s = now_s;
    pl->steps = 0;
    pl->resting = 1;
    rest.temperature_c = params->ambient_c;
    pl->committed = rest;
    pl->now_s = now_s;
    pl->now = rest;
    return SB_OK;
}

static double committed_s(const sb_plant *pl) { return pl->anchor_s + (double)pl->steps * pl->max_step_s; }

void sb_plant_advance(sb_plant *pl, double now_s)
{
    double dt;

    /* not later (NaN included): nothing; +inf would step forever */
    if (!plant_ok(pl) || !(now_s > pl->now_s) || isinf(now_s))
        return;
    pl->now_s = now_s;
    if (!pl->resting) {
        double anchor = pl->anchor_s, h = pl->max_step_s;
        int64_t steps = pl->steps;
        while (anchor + (double)(steps + 1) * h <= now_s) {
            step(pl, &pl->committed, h);
            steps++;
            if (at_rest(pl, &pl->committed)) {
                pl->resting = 1;
                break;
            }
        }
        pl->steps = steps;
    }
    pl->now = pl->committed;
    dt = now_s - committed_s(pl);
    if (dt > 1e-12) {
        if (pl->resting) {
            if (pl->now.temperature_c != pl->p.ambient_c || pl->now.speed_dps != 0.0)
                cool(pl, &pl->now, dt);
        } else {
            step(pl, &pl->now, dt);
        }
    }
}

/* plant.py Plant._commit: the state at now_s becomes the committed one, a new grid starts there */
static void commit(sb_plant *pl)
{
    pl->committed = pl->now;
    pl->anchor_s = pl->now_s;
    pl->steps = 0;
}

void sb_plant_set_control(sb_plant *pl, const sb_control *control)
{
    if (!plant_ok(pl) || control == NULL || !mode_ok(control->mode))
        return;
    commit(pl);
    if (control->mode != pl->control.mode) {
        /* a new mode starts its loops fresh, from the present speed */
        pl->committed.speed_integral = 0.0;
        pl->committed.speed_ref = pl->committed.speed_dps;
        pl->now = pl->committed;
    }
    pl->control = *control;
    pl->resting = at_rest(pl, &pl->committed);
}

void sb_plant_set_acceleration(sb_plant *pl, double acceleration_dps2)
{
    if (!plant_ok(pl))
        return;
    commit(pl);
    pl->acceleration_dps2 = acceleration_dps2;
}

void sb_plant_set_external_torque(sb_plant *pl, double torque_nm)
{
    if (!plant_ok(pl))
        return;
    commit(pl);
    pl->external_torque_nm = torque_nm;
}

void sb_plant_set_state(sb_plant *pl, const sb_plant_state *state)
{
    if (!plant_ok(pl) || state == NULL)
        return;
    commit(pl);
    pl->committed = *state;
    pl->now = pl->committed;
    pl->resting = at_rest(pl, &pl->committed);
}

void sb_plants_advance(sb_plant *plants, size_t n, double now_s)
{
    if (plants == NULL)
        return;
    for (size_t i = 0; i < n; i++)
        sb_plant_advance(&plants[i], now_s);
}
