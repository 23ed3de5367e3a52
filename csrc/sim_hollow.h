/* ---- simulator: the hollow family's C path (sim_hollow.c) ----
 * Its state struct lives in sb_simmotor.state; its Python glue is servobus/protocols/hollow/sim/
 * (core.py). C handles the set-point frames (hollow.md §4.2, §5.2, §7.2) and their replies; the
 * special commands (FF x7 + F9..FE), the extended-id frames (mode switch, PI multipliers) and
 * everything the model's guards exclude go to the Python model (SB_HOT_COLD).
 * While attached, the RAM state below is the model's only copy: its Python properties read and
 * write it, so neither side ever sees a stale value. */

/* motor.counters[i]: the Python model's Counter keys (core.py COUNTER_KEYS, in this order). */
#define SB_HOLLOW_RECEIVED 0
#define SB_HOLLOW_IGNORED_ID 1
#define SB_HOLLOW_IGNORED_KIND 2
#define SB_HOLLOW_UNDECODABLE 3
#define SB_HOLLOW_ACCEPTED 4
#define SB_HOLLOW_REPLIED 5
#define SB_HOLLOW_ZERO_REFUSED 6
#define SB_HOLLOW_COUNTERS 7

typedef struct {
    /* pushed by the model (core_push): the motor model's scales and the interface */
    double position_full_scale_deg;     /* 360 * Pmax */
    double speed_full_scale_rad_s;
    double current_full_scale_a;
    double fd_velocity_counts_per_rpm;  /* HollowModel.fd_velocity_counts_per_rpm */
    double fd_current_a_per_count;
    /* RAM state (§13), shared: C and the Python model both read and write it */
    double zero_offset_deg;             /* plant angle of the mechanical zero */
    double target_deg;                  /* the held setpoint (when has_setpoint), plant units */
    double speed_dps;
    double current_a;
    uint32_t motor_id;                  /* the id it accepts (0..100) */
    uint32_t host_id;                   /* the id it replies on */
    int fd_enabled;                     /* CAN FD (1) or classic CAN (0) */
    int can_mode;                       /* CanMode: 0 extended, 1 normal */
    int ctrl_mode;                      /* ControlMode: 0 torque, 1 velocity, 2 position */
    int enabled;
    int has_setpoint;
    int kp;
    int kd;
} sb_hollow_state;
