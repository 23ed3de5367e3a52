/* ---- simulator: the engine, one simulated CAN network (sim_net.c) ----
 * The C twin of src/servobus/sim/network.py (SimCanNetwork) and sim/canbus.py (CanBusModel), which
 * stay the reference: the same arbitration, wire time, queues, event order, routing and link counts.
 * Node 0 is the host; a device is a node whose C twin is motors[node]. One sb_simnet_run() call runs
 * the network until until_s, or until something needs Python (a frame or a deadline of a Python model,
 * or of a C family that answered SB_HOT_COLD): it then stops with that event last, and the next call
 * goes on from where it stopped (after Python has queued the model's frames and touched the node).
 * Caller-allocated, fixed capacities; no malloc, no globals. */
#define SB_NET_NODES 64      /* node 0: the host */
#define SB_NET_FRAMES 4096   /* frames queued, in flight or being delivered, all nodes together */
#define SB_NET_LOG 16384     /* frame ends kept for the links (dropped once every link settled up) */
#define SB_NET_ROUTES 512    /* identifiers whose recipients are remembered */
#define SB_NET_OUT 16        /* frames a family's C path may answer with at once */
#define SB_NET_TIMES 256     /* wire times kept by frame content */

#define SB_E_FULL -5         /* a fixed capacity is exhausted (frames queued, nodes) */

/* Node kinds. */
#define SB_NODE_FREE 0
#define SB_NODE_HOST 1
#define SB_NODE_CORE 2       /* a device with a C family path: used while motors[node].hot */
#define SB_NODE_PYTHON 3     /* a device only Python models: its frames and deadlines are events */
#define SB_NODE_GONE 4       /* removed; frames it queued before still go out */

/* Events (sb_netevent.kind). */
#define SB_EV_RX 1           /* the host received frame (from frame.node) at t */
#define SB_EV_DELIVER 2      /* hand frame to node's Python model at t (the run stopped) */
#define SB_EV_POLL 3         /* poll node's Python model at t (the run stopped) */

/* sb_simnet_run() modes and flags. */
#define SB_RUN_ADVANCE 0     /* SimCanNetwork.advance: every event at t <= until_s and t < before_s */
#define SB_RUN_AHEAD 1       /* SimCanNetwork.run_ahead(host_time_s): stops before what the host sees */
#define SB_RUN_STOP_RX 2     /* flag: stop after every SB_EV_RX (faults towards the host act on it) */

/* sb_simnet_run() results (negative: an error, nothing was done). */
#define SB_RUN_IDLE 0        /* nothing more to do within the limits */
#define SB_RUN_STOPPED 1     /* the last event needs Python before the network goes on */
#define SB_RUN_EVENTS_FULL 2 /* the event buffer is full: take the events and call again */
#define SB_RUN_LOG_FULL 3    /* the frame log is full: settle every link up, sb_simnet_drop_log, call again */

typedef struct {
    int32_t kind;            /* SB_EV_* */
    int32_t node;            /* the node the event is for (SB_EV_RX: 0) */
    double t;                /* frame end, or the deadline's time */
    sb_simframe frame;       /* SB_EV_RX, SB_EV_DELIVER: the frame (frame.tag: the caller's, 0: made in C) */
} sb_netevent;

typedef struct {
    sb_simframe f;           /* f.t: ready time; f.node: sender */
    double joined_s;         /* when it joined its node's queue (schedule: its ready time) */
    int64_t seq;
    double dur_s;            /* wire time, valid while dur_epoch == the net's rate_epoch */
    int32_t dur_epoch;
    int32_t next;            /* next in its node's queue, the done list or the free list; -1: none */
} sb_netslot;

typedef struct {
    int32_t kind;            /* SB_NODE_* */
    int32_t linked;          /* keeps a link (counts below) */
    int32_t head;            /* its queue, ordered by (joined_s, seq): first and last slot, -1: empty */
    int32_t tail;
    int32_t queued;
    uint32_t head_key;       /* the head frame's arbitration priority as one number */
    double head_t;           /* the head frame's ready time (arbitration reads it for every node) */
    int32_t has_first;
    double first_joined_s;   /* the node's first (joined_s, seq) ever: ties between nodes' equal ids */
    int64_t first_seq;
    double deadline_s;       /* min(py_deadline_s, the family's next deadline while hot); INFINITY: none */
    int32_t listen_all;      /* the listen list routes were built from */
    int32_t n_listen;
    uint32_t listen[16];
    /* The link (sim/device.py BusLink): frames it sent and was handed, and where it settled up. */
    int64_t own, own_odd, taken, taken_odd;
    int64_t cursor;
    int64_t mark_odd, mark_own, mark_own_odd, mark_taken, mark_taken_odd;
} sb_netnode;

typedef struct {
    uint32_t id;
    int32_t used;
    uint64_t mask;           /* recipients by node */
} sb_netroute;

typedef struct {
    int32_t epoch;           /* the rate epoch + 1 it was computed at (0: empty) */
    uint32_t id;
    uint8_t flags;
    uint8_t len;
    uint8_t data[64];
    double dur_s;
} sb_nettime;

typedef struct {
    double now_s;            /* the network's time (SimCanNetwork.now_s) */
    double bus_now_s;        /* the time the bus has run to: nothing may be queued before it */
    double free_at_s;
    double bitrate;          /* bit/s; INFINITY: a zero-latency bus */
    double data_bitrate;     /* CAN FD data phase; 0: the nominal rate */
    int32_t rate_epoch;
    int32_t in_flight;       /* the slot on the wire, -1: none */
    double in_start_s, in_end_s;
    double busy_s;
    int64_t frames;
    int64_t seq;
    int32_t chosen;          /* the tentative next transmission is known: */
    int32_t choice_node;     /*   -1: the bus is idle */
    double choice_start_s, choice_dur_s;
    /* The step in progress (a run may stop inside one and go on with the next call). */
    int32_t phase;           /* 0: none, 1: polling due nodes, 2: delivering frames */
    int32_t phase_pos;       /* polling: position in order[]; delivering: recipient position, n_order: host */
    double phase_t;
    uint64_t phase_due;
    int32_t done_head, done_tail;   /* completed transmissions still to deliver */
    int32_t free_slot;
    int32_t used_slots;
    uint64_t active;         /* nodes with frames queued */
    int32_t n_order;
    int16_t order[64];       /* live device nodes, in the order they were added */
    int32_t deadline_known;  /* deadline_min holds: the earliest deadline_s of the nodes in order */
    double deadline_min;
    int32_t n_routes;
    int64_t log_base, log_count, log_odd;
    double log_end[16384];
    int16_t log_src[16384];
    sb_netnode nodes[64];
    sb_netroute routes[512];
    sb_nettime times[256];
    sb_netslot slots[4096];
    sb_simframe out[16];
    sb_simmotor motors[64];
} sb_simnet;

/* An empty network at time 0: the host is node 0. SB_E_ARG: net NULL, bitrate not > 0, data_bitrate < 0. */
int sb_simnet_init(sb_simnet *net, double bitrate, double data_bitrate);
/* Change the bit rates (later arbitrations use them). SB_E_ARG as for init. */
int sb_simnet_set_rates(sb_simnet *net, double bitrate, double data_bitrate);
/* Add a device node (SB_NODE_CORE or SB_NODE_PYTHON), last in the order; its motor is zeroed with
 * py_deadline_s INFINITY. has_first: the node's first (joined_s, seq), kept from an earlier node of the
 * same name. Returns the node (>= 1), SB_E_FULL, or SB_E_ARG. */
int sb_simnet_add(sb_simnet *net, int kind, int linked, int has_first, double first_joined_s, int64_t first_seq);
/* Take a device node off: no more frames or deadlines; what it queued still goes out. */
int sb_simnet_remove(sb_simnet *net, int node);
/* The node's motor changed (deadline, hot, listen list): recompute its deadline and routes. */
int sb_simnet_touch(sb_simnet *net, int node);
/* Queue a frame at node as of ready_s (CanBusModel.schedule). tag nonzero: the caller keeps the frame's
 * object by the slot returned, and the frame's events carry tag = slot + 1 (0: a frame made in C).
 * Returns the slot (>= 0); SB_E_RANGE: ready_s before bus_now_s; SB_E_FULL; SB_E_ARG. */
int sb_simnet_send(sb_simnet *net, int node, uint32_t id, int flags, const uint8_t *data, size_t len,
                   double ready_s, uint32_t tag);
/* Run (SB_RUN_ADVANCE or SB_RUN_AHEAD, | SB_RUN_STOP_RX); events into ev[0..cap), *n_events of them.
 * Returns SB_RUN_* or a negative status. */
int sb_simnet_run(sb_simnet *net, double until_s, double before_s, double host_time_s, int mode,
                  sb_netevent *ev, int cap, int *n_events);
/* The host's turn (CoreCanNetwork.host_turn): run to until_s as SB_RUN_ADVANCE (before_s and
 * host_time_s INFINITY) and bring now_s up to it; then, on a finite bit rate, as SB_RUN_AHEAD past
 * host_time_s = until_s; then next_s = sb_simnet_next_event(net, 0). Events of both runs go into
 * out->ev, out->n_events of them. It stops where a run returns anything but SB_RUN_IDLE (that status),
 * or with SB_RUN_LOG_FULL between the runs once the log holds log_limit entries; out->stage says where
 * it stopped, and the caller goes on from there with sb_simnet_run. Done, the status is SB_RUN_LOG_FULL
 * if the log holds log_limit entries (the caller settles its links up and drops it), else SB_RUN_IDLE.
 * Returns out->n_events when it is all done with SB_RUN_IDLE (every event then is an SB_EV_RX), else a
 * negative status (SB_E_ARG: nothing was done) or SB_TURN_MORE: out says the rest. */
#define SB_TURN_ADVANCE 0    /* stopped in the advance */
#define SB_TURN_BETWEEN 1    /* the advance is done; the run-ahead has not started */
#define SB_TURN_AHEAD 2      /* stopped in the run-ahead */
#define SB_TURN_DONE 3       /* all done: next_s is valid */
#define SB_TURN_EVENTS 256
#define SB_TURN_MORE -100    /* returned: not done, or done with the log to drop (out->status) */

typedef struct {
    int32_t status;          /* SB_RUN_* or a negative status (SB_E_ARG: nothing was done) */
    int32_t stage;           /* SB_TURN_* */
    int32_t n_events;
    int32_t pad;
    double next_s;           /* stage SB_TURN_DONE: when the next event happens (INFINITY: none) */
    sb_netevent ev[256];     /* SB_TURN_EVENTS */
} sb_netturn;

int sb_simnet_turn(sb_simnet *net, double until_s, int64_t log_limit, sb_netturn *out);
/* The host's sb_simnet_send (node 0, its frame kept by slot: tag 1) with id and flags in one key:
 * id | flags << 29. */
int sb_simnet_host_send(sb_simnet *net, uint32_t key, const uint8_t *data, size_t len, double ready_s);
/* When the next event of the network happens (INFINITY: none): a step in progress, a transmission
 * ending, a node's deadline. bus_only: the bus's own (CanBusModel.next_event_s). */
double sb_simnet_next_event(sb_simnet *net, int bus_only);
/* The transmission that completes next (CanBusModel.next_completion): 1 with *end_s, *node; 0: idle. */
int sb_simnet_next_completion(sb_simnet *net, double *end_s, int *node);
/* Settle a link up (BusLink.catch_up): missed frames, of which odd, and the ends of frames the node
 * did not send since the last call (every_end 0: only the last). ends: cap >= SB_NET_LOG. */
int sb_simnet_catch_up(sb_simnet *net, int node, int every_end, int64_t *missed, int64_t *missed_odd,
                       double *ends, int cap, int *n_ends);
/* Forget logged frame ends every linked node has settled up for. Returns the entries left. */
int sb_simnet_drop_log(sb_simnet *net);
/* The latest ready time of a queued frame in (now_s, limit_s] (-INFINITY: none): run_until_idle. */
double sb_simnet_last_ready(const sb_simnet *net, double limit_s);
/* Wire time of a frame at the network's rates (negative: bad frame). */
double sb_simnet_frame_time(const sb_simnet *net, uint32_t id, int flags, const uint8_t *data, size_t len);
