/* ---- simulator: the lk family's C path (sim_lk.c) ----
 * LK's control-loop traffic handled in C exactly as the Python model (servobus/protocols/lk/sim/,
 * the reference) handles it: status reads 0x9A/0x9B/0x9C/0x9D/0x90/0x92/0x94, motor off/stop/run
 * 0x80/0x81/0x88, set-points 0xA0..0xA8 and (V2.35) the 0x280 multi-motor frame, for V2.36 and V2.35.
 * Everything else (parameters, zeroing, brake, calibration, bytes that do not decode) is COLD.
 * Its state struct lives in sb_simmotor.state (sim_lk.c checks that it fits); the Python glue
 * (servobus/protocols/lk/sim/core.py) pushes the fields marked "pushed" and pulls the others. */
#define SB_LK_V2_36 0
#define SB_LK_V2_35 1
#define SB_LK_MS 0
#define SB_LK_MF 1
#define SB_LK_MH 2
#define SB_LK_MG 3
#define SB_LK_ON 0          /* RunState.ON */
#define SB_LK_STOPPED 1     /* RunState.STOPPED */
#define SB_LK_OFF 2         /* RunState.OFF */
/* Indexes into sb_simmotor.counters: the model's Counter keys (core.py maps the names). */
#define SB_LK_N_RECEIVED 0
#define SB_LK_N_ACCEPTED 1
#define SB_LK_N_REPLIED 2
#define SB_LK_N_UNANSWERED 3
#define SB_LK_N_IGNORED_ID 4
#define SB_LK_N_IGNORED_KIND 5
#define SB_LK_N_OTHER_REVISION 6
#define SB_LK_N_BUSY 7
#define SB_LK_N_NOT_EXECUTED_OFF 8
#define SB_LK_N_NOT_IMPLEMENTED 9
#define SB_LK_N_COUNT 10

typedef struct {
    /* pushed: the model, the limits in effect (motor shaft), the knobs */
    int revision;              /* SB_LK_V2_* */
    int motor_type;            /* SB_LK_MS.. */
    int motor_id;              /* 1..32: requests on 0x140+ID */
    int per_turn;              /* encoder counts per motor turn (2^min(bits, 16)) */
    double amps_per_count;     /* plant A per iq (MS: power) count */
    double iq_counts_per_amp;  /* MF/MG: 1 / (A per count), what the codec divides a count by; else 0 */
    int torque_counts;         /* Max Torque Current (MS: Max Power), counts */
    double speed_limit_dps;    /* Max Speed */
    double angle_lo_deg;       /* multi-turn target bounds */
    double angle_hi_deg;
    int brake_engaged;
    int unresponsive;          /* acts on requests, never replies */
    double busy_until_s;       /* calibrating until then: frames are "busy" */
    /* pushed and changed by C (pulled when `pending`) */
    int run_state;             /* SB_LK_ON / STOPPED / OFF */
    int has_held;              /* the held control command (0: None) */
    sb_control held;
    int64_t angle_offset;      /* encoderOffset (RAM) */
    int64_t angle_origin;      /* the total count where the multi-turn angle is 0 */
    int pending;               /* C changed the counters or the fields above since the last pull */
} sb_lk_state;
