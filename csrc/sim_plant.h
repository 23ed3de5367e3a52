/* ---- simulator: the plant of one actuator (sim_plant.c) ----
 * The same equations and step rules as src/servobus/sim/plant.py (the reference), state at the
 * output shaft. Integration is on a grid: whole steps of max_step_s from the anchor (the time of the
 * last change: control, load, acceleration or a state write), committed; the state at any later time
 * is the committed one plus one partial step, computed and not committed. So the state at a time
 * depends only on the changes and their times, never on when it was looked at: a motor can be
 * integrated lazily, only when it is addressed or observed. */
#define SB_CONTROL_OFF 0
#define SB_CONTROL_BRAKE 1
#define SB_CONTROL_CURRENT 2    /* a = current_a */
#define SB_CONTROL_SPEED 3      /* a = speed_dps, b = max_current_a (NAN: none) */
#define SB_CONTROL_POSITION 4   /* a = position_deg, b = max_speed_dps (NAN: none), c = max_current_a (NAN: none) */
#define SB_CONTROL_IMPEDANCE 5  /* a = position_rad, b = velocity_rad_s, c = kp, d = kd, e = torque_ff_nm */

typedef struct {
    double inertia_kgm2;
    double viscous_friction_nm_s_per_rad;
    double torque_constant_nm_per_a;
    double gear_ratio;
    double max_current_a;
    double max_speed_dps;
    double max_acceleration_dps2;
    double current_time_constant_s;
    double speed_bandwidth_hz;
    double position_bandwidth_hz;
    double winding_resistance_ohm;
    double thermal_resistance_c_per_w;
    double thermal_capacity_j_per_c;
    double ambient_c;
    double supply_v;
    double supply_resistance_ohm;
    double speed_limit_dps;  /* the speed mode's target is clamped to it (INFINITY: none) */
} sb_plant_params;

typedef struct {
    int mode;  /* SB_CONTROL_* */
    double a, b, c, d, e;
} sb_control;

typedef struct {
    double position_deg;
    double speed_dps;
    double current_a;
    double temperature_c;
    double speed_integral;  /* A, the speed loop's integral term */
    double speed_ref;       /* dps, the slew-limited reference */
} sb_plant_state;

typedef struct {
    sb_plant_params p;
    double max_step_s;
    sb_control control;
    double acceleration_dps2;
    double external_torque_nm;
    double anchor_s;            /* the grid's origin: the last change */
    int64_t steps;              /* whole steps committed since anchor_s */
    int resting;                /* the committed state is at rest: no steps, only cooling */
    sb_plant_state committed;   /* at anchor_s + steps * max_step_s */
    double now_s;               /* the time `now` is for */
    sb_plant_state now;         /* the state at now_s (what replies report) */
} sb_plant;

/* A plant at rest at ambient temperature at now_s, control OFF. SB_E_ARG for bad params or step. */
int sb_plant_init(sb_plant *pl, const sb_plant_params *params, double now_s, double max_step_s);
/* Integrate to now_s (nothing if not later than pl->now_s): commits whole steps, fills pl->now. */
void sb_plant_advance(sb_plant *pl, double now_s);
/* Commit the state at pl->now_s as the new anchor (before any change), then apply the change. */
void sb_plant_set_control(sb_plant *pl, const sb_control *control);
void sb_plant_set_acceleration(sb_plant *pl, double acceleration_dps2);
void sb_plant_set_external_torque(sb_plant *pl, double torque_nm);
/* A write of the observed state (tests, a model's reset): committed = *state at pl->now_s. */
void sb_plant_set_state(sb_plant *pl, const sb_plant_state *state);
/* SB_OK if every function above would act on *pl: not NULL, max_step_s > 0, a known control mode,
 * 0 <= steps < 2^53, finite anchor_s and now_s with anchor_s + steps * max_step_s <= now_s (the
 * functions above leave a plant that fails this untouched). */
int sb_plant_check(const sb_plant *pl);
/* Advance n plants to now_s in one call. */
void sb_plants_advance(sb_plant *plants, size_t n, double now_s);
