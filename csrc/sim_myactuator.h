/* ---- simulator: the myactuator family's C path (sim_myactuator.c) ----
 * Its state struct lives in sb_simmotor.state; its Python glue is servobus/protocols/myactuator/sim/
 * (core.py). The reference is the Python model (sim/device.py, sim/state.py): the C path answers the
 * control-loop traffic of a motor in the state the model's guards allow (motor.hot: no error flag,
 * not unresponsive, not comm-tripped, ...), byte for byte and time for time as the model would, and
 * returns SB_HOT_COLD, changing nothing, for everything else.
 *
 * Hot frames (0x140+ID and, with the CAN-ID filter off, 0x280; 8 bytes):
 *   0xA1 0xA2 0xA4 0xA6 0xA8 0xA9 (0x72 0x73 on V4.4) set-points, answered with R2 / R2-A6
 *   0x9A 0x9C 0x9D 0x92 0x60 0x61 0x62 reads
 *   0xB6 active reply on/off (no reply; the streams' frames are sb_ma_poll's deadlines)
 * and motion mode on 0x400+ID (reply on 0x500+ID). Extended/FD frames, filtered broadcasts and
 * other identifiers are counted as the model counts them. */
#define SB_MA_V4_3 0
#define SB_MA_V4_4 1
#define SB_MA_MAX_STREAMS 7     /* the streamable commands: 0x60 0x61 0x62 0x92 0x9A 0x9C 0x9D */

/* motor.counters[i]: the model's Counter keys C counts (core.py: COUNTER_NAMES, in this order). */
#define SB_MA_CTR_RECEIVED 0
#define SB_MA_CTR_IGNORED_KIND 1
#define SB_MA_CTR_IGNORED_ID 2
#define SB_MA_CTR_FILTERED 3
#define SB_MA_CTR_ACCEPTED 4
#define SB_MA_CTR_REPLIED 5
#define SB_MA_CTR_SILENCED 6       /* silenced_by_active_reply */
#define SB_MA_CTR_BRAKE_LOCKED 7
#define SB_MA_CTR_STREAM_FRAMES 8
#define SB_MA_CTR_STREAM_SKIPPED 9
#define SB_MA_N_COUNTERS 10

/* sb_ma_state.dirty: what C changed since the model's last pull. */
#define SB_MA_DIRTY_COUNTERS 1
#define SB_MA_DIRTY_CONTROL 2      /* control, run_mode, brake_released, feed-forward */
#define SB_MA_DIRTY_HEARD 4        /* last_heard_s */
#define SB_MA_DIRTY_STREAMS 8      /* the stream list or a stream's count */

typedef struct {
    int command;        /* the streamed command byte */
    int64_t count;      /* the next frame is due at origin_s + count * interval_s */
    double interval_s;
    double origin_s;
} sb_ma_stream;

typedef struct {
    /* ---- pushed by the model (core_push); C only reads them ---- */
    int motor_id;                   /* the RAM id, 1..32 */
    int revision;                   /* SB_MA_V4_3 / SB_MA_V4_4 */
    int can_id_filter;              /* RAM 0x20 index 2: 0x280 and 0x300 are not received */
    int has_brake;
    int pole_pairs;
    int counts_per_turn;            /* 1..65536 (0xA6 carries the single-turn count in a uint16) */
    int64_t base_counts;            /* the encoder frame (state.py EncoderFrame) */
    int64_t offset_counts;
    int64_t comm_timeout_ms;        /* RAM 0xB3, 0: protection off */
    double encoder_gear_ratio;
    double rated_current_a;
    double position_acceleration_dps_s;  /* RAM 0x43 index 0 (0: limited by the current only) */
    double speed_acceleration_dps_s;     /* RAM 0x43 index 2 */
    sb_field motion_command[5];     /* MIT_COMMAND scales: p, v, kp, kd, t */
    sb_field motion_reply[4];       /* MIT_REPLY scales: motor id, p, v, t */
    /* ---- written by both: C sets `dirty`, the model pulls and clears it ---- */
    int dirty;                      /* SB_MA_DIRTY_* */
    int brake_released;
    int run_mode;                   /* the 0x70 value */
    int has_feedforward;            /* feedforward_pct is not None */
    int feedforward_pct;
    sb_control control;             /* the commanded control (the plant gets BRAKE while the brake is locked) */
    double last_heard_s;            /* the 0xB3 protection trips at last_heard_s + comm_timeout_ms / 1000 */
    int n_streams;                  /* 0xB6 streams, in the model's dict order */
    sb_ma_stream streams[7];
} sb_ma_state;
