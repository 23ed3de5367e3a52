/* ---- simulator: what the engine (sim_net.c) and the families' C paths share ----
 * A simulated CAN network runs in C: the bus model, the routing, the plants and each family's
 * control-loop traffic (its "hot" commands). Everything else is the Python device models': the
 * engine hands those frames and deadlines to Python as events, and the models keep their C twins
 * (sb_simmotor) up to date by pushing what C needs and pulling what C changed. */
#define SB_FAMILY_PYTHON 0       /* a device the engine only hands to Python (sniffers, converters, custom) */
#define SB_FAMILY_MYACTUATOR 1
#define SB_FAMILY_LK 2
#define SB_FAMILY_HOLLOW 3

/* What a family's C path did with a frame or a deadline. */
#define SB_HOT_DONE 0   /* handled in C: *n_out frames in out (each with its ready time in .t), maybe 0 */
#define SB_HOT_COLD 1   /* not handled, nothing changed: the engine hands it to the Python model */

#define SB_SIM_MAX_DATA 64
#define SB_SIM_MAX_LISTEN 16
#define SB_SIM_COUNTERS 32
#define SB_SIM_STATE_DOUBLES 160   /* room for a family's own state struct (1280 bytes) */

typedef struct {
    double t;        /* ready time (queued), end time (received) */
    uint32_t id;
    uint8_t flags;   /* SB_FRAME_* */
    uint8_t len;
    int16_t node;    /* the sender's node (0: the host) */
    uint32_t tag;    /* the caller's handle of the Python Frame (0: made in C) */
    uint8_t data[64];
} sb_simframe;

typedef struct {
    int family;              /* SB_FAMILY_* */
    int hot;                 /* nonzero: the family's C path may act (the model's guards hold) */
    double turnaround_s;     /* request heard -> reply ready */
    double py_deadline_s;    /* when the Python model must be polled (INFINITY: never) */
    int listen_all;          /* handed every frame */
    int n_listen;
    uint32_t listen[16];     /* the identifiers it is handed */
    sb_plant plant;
    int64_t counters[32];    /* the family's counters, changes since the model's last pull */
    double state[160];       /* the family's own struct: sb_ma_state, sb_lk_state, sb_hollow_state */
} sb_simmotor;

/* The families' C paths (sim_myactuator.c, sim_lk.c, sim_hollow.c). receive(): a frame on one of
 * the motor's identifiers, ended at now_s; the plant is not yet advanced. poll(): now_s has reached
 * next_deadline() (INFINITY: none; the C path's own deadlines only, streams). Both return SB_HOT_*
 * and write at most cap frames to out; COLD leaves the motor exactly as it was. */
int sb_ma_receive(sb_simmotor *m, const sb_simframe *in, double now_s, sb_simframe *out, int cap, int *n_out);
int sb_ma_poll(sb_simmotor *m, double now_s, sb_simframe *out, int cap, int *n_out);
double sb_ma_next_deadline(const sb_simmotor *m);
int sb_lk_receive(sb_simmotor *m, const sb_simframe *in, double now_s, sb_simframe *out, int cap, int *n_out);
int sb_lk_poll(sb_simmotor *m, double now_s, sb_simframe *out, int cap, int *n_out);
double sb_lk_next_deadline(const sb_simmotor *m);
int sb_hollow_receive(sb_simmotor *m, const sb_simframe *in, double now_s, sb_simframe *out, int cap, int *n_out);
int sb_hollow_poll(sb_simmotor *m, double now_s, sb_simframe *out, int cap, int *n_out);
double sb_hollow_next_deadline(const sb_simmotor *m);
