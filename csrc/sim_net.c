/* The simulated CAN network: src/servobus/sim/network.py + sim/canbus.py in C (see sim_net.h).
 * Every rule below mirrors a line of the reference; comments name the reference's function. */
#include <math.h>
#include <string.h>
#include "sb_internal.h"

enum { PHASE_NONE = 0, PHASE_POLL = 1, PHASE_DELIVER = 2 };

static int node_ok(const sb_simnet *net, int node)
{
    return node >= 1 && node < SB_NET_NODES
        && (net->nodes[node].kind == SB_NODE_CORE || net->nodes[node].kind == SB_NODE_PYTHON);
}

static int rate_ok(double bitrate, double data_bitrate)
{
    return bitrate > 0 && !isnan(bitrate) && data_bitrate >= 0 && !isnan(data_bitrate);
}

int sb_simnet_init(sb_simnet *net, double bitrate, double data_bitrate)
{
    if (!net || !rate_ok(bitrate, data_bitrate))
        return SB_E_ARG;
    memset(net, 0, sizeof *net);
    net->bitrate = bitrate;
    net->data_bitrate = data_bitrate;
    net->in_flight = -1;
    net->choice_node = -1;
    net->done_head = net->done_tail = -1;
    for (int i = 0; i < SB_NET_FRAMES; i++)
        net->slots[i].next = i + 1 < SB_NET_FRAMES ? i + 1 : -1;
    net->free_slot = 0;
    for (int i = 0; i < SB_NET_NODES; i++) {
        net->nodes[i].head = net->nodes[i].tail = -1;
        net->nodes[i].deadline_s = INFINITY;
        net->motors[i].py_deadline_s = INFINITY;
    }
    net->nodes[0].kind = SB_NODE_HOST;
    return SB_OK;
}

int sb_simnet_set_rates(sb_simnet *net, double bitrate, double data_bitrate)
{
    if (!net || !rate_ok(bitrate, data_bitrate))
        return SB_E_ARG;
    net->bitrate = bitrate;
    net->data_bitrate = data_bitrate;
    net->rate_epoch++;  /* CanBusModel._rates_changed: times are recomputed, the choice too */
    net->chosen = 0;
    return SB_OK;
}

/* ---- routes ---- */

static void routes_clear(sb_simnet *net)
{
    memset(net->routes, 0, sizeof net->routes);
    net->n_routes = 0;
}

static uint64_t route_mask(sb_simnet *net, uint32_t id)
{
    uint32_t h = (id * 2654435761u) >> 23;  /* 9 bits: SB_NET_ROUTES slots */
    for (int probe = 0; probe < SB_NET_ROUTES; probe++) {
        sb_netroute *r = &net->routes[(h + probe) & (SB_NET_ROUTES - 1)];
        if (r->used && r->id == id)
            return r->mask;
        if (!r->used)
            break;
    }
    /* SimCanNetwork._recipients: every device listening to id (or to everything). */
    uint64_t mask = 0;
    for (int i = 0; i < net->n_order; i++) {
        const sb_netnode *n = &net->nodes[net->order[i]];
        int hit = n->listen_all;
        for (int j = 0; !hit && j < n->n_listen; j++)
            hit = n->listen[j] == id;
        if (hit)
            mask |= (uint64_t)1 << net->order[i];
    }
    if (net->n_routes >= SB_NET_ROUTES * 3 / 4)
        routes_clear(net);
    for (int probe = 0; probe < SB_NET_ROUTES; probe++) {
        sb_netroute *r = &net->routes[(h + probe) & (SB_NET_ROUTES - 1)];
        if (!r->used) {
            r->used = 1;
            r->id = id;
            r->mask = mask;
            net->n_routes++;
            break;
        }
    }
    return mask;
}

/* ---- families ---- */

static int family_c(const sb_simnet *net, int node)
{
    const sb_simmotor *m = &net->motors[node];
    return net->nodes[node].kind == SB_NODE_CORE && m->hot
        && (m->family == SB_FAMILY_MYACTUATOR || m->family == SB_FAMILY_LK || m->family == SB_FAMILY_HOLLOW);
}

static double family_deadline(const sb_simmotor *m)
{
    switch (m->family) {
    case SB_FAMILY_MYACTUATOR: return sb_ma_next_deadline(m);
    case SB_FAMILY_LK: return sb_lk_next_deadline(m);
    case SB_FAMILY_HOLLOW: return sb_hollow_next_deadline(m);
    }
    return INFINITY;
}

/* A live node's deadline_s, the earliest of them kept (next_deadline) where it stays known cheaply. */
static void set_deadline(sb_simnet *net, int node, double d)
{
    double old = net->nodes[node].deadline_s;
    net->nodes[node].deadline_s = d;
    if (d < net->deadline_min)
        net->deadline_min = d;
    else if (old == net->deadline_min && d != old)
        net->deadline_known = 0;  /* the earliest moved later: ask every node again when needed */
}

static void node_deadline(sb_simnet *net, int node)
{
    double d = net->motors[node].py_deadline_s;
    if (isnan(d))
        d = INFINITY;
    if (family_c(net, node)) {
        double f = family_deadline(&net->motors[node]);
        if (f < d)
            d = f;
    }
    set_deadline(net, node, d);
}

/* ---- the bus: CanBusModel ---- */

/* A frame's wire time, from the cache of recent frames by content (CanBusModel.frame_time_s keeps one
 * too: a control loop sends the same requests, and gets the same replies, over and over). */
static double frame_time(sb_simnet *net, const sb_simframe *f)
{
    uint32_t h = 2166136261u ^ f->id;
    h = (h ^ f->flags) * 16777619u;
    h = (h ^ f->len) * 16777619u;
    for (int i = 0; i < f->len; i++)
        h = (h ^ f->data[i]) * 16777619u;
    sb_nettime *c = &net->times[h & (SB_NET_TIMES - 1)];
    if (c->epoch == net->rate_epoch + 1 && c->id == f->id && c->flags == f->flags && c->len == f->len
        && memcmp(c->data, f->data, f->len) == 0)
        return c->dur_s;
    double dur = sb_can_frame_time(f->id, f->flags, f->data, f->len, net->bitrate, net->data_bitrate);
    c->epoch = net->rate_epoch + 1;  /* 0: an empty entry */
    c->id = f->id;
    c->flags = f->flags;
    c->len = f->len;
    memcpy(c->data, f->data, f->len);
    c->dur_s = dur;
    return dur;
}

static double slot_duration(sb_simnet *net, sb_netslot *s)
{
    if (s->dur_epoch != net->rate_epoch || s->dur_s < 0) {
        s->dur_s = frame_time(net, &s->f);
        s->dur_epoch = net->rate_epoch;
    }
    return s->dur_s;
}

/* arbitration_priority() as one number: base id, then standard before extended, then the extension. */
static uint32_t priority_key(const sb_simframe *f)
{
    if (f->flags & SB_FRAME_EXT)
        return ((f->id >> 18) << 19) | (1u << 18) | (f->id & 0x3FFFF);
    return f->id << 19;
}

/* The node's head's priority, then the node's first (joined_s, seq): negative if a ranks before b. */
static int rank_cmp(const sb_simnet *net, int a, int b)
{
    const sb_netnode *na = &net->nodes[a], *nb = &net->nodes[b];
    if (na->head_key != nb->head_key)
        return na->head_key < nb->head_key ? -1 : 1;
    if (na->first_joined_s != nb->first_joined_s)
        return na->first_joined_s < nb->first_joined_s ? -1 : 1;
    return na->first_seq < nb->first_seq ? -1 : (na->first_seq > nb->first_seq);
}

/* CanBusModel._arbitrate: the next winner, when it starts and for how long, not committed. */
static void arbitrate(sb_simnet *net)
{
    if (net->chosen)
        return;
    int best = -1;
    uint32_t best_key = 0;
    double start = net->free_at_s, first = INFINITY;  /* first: the earliest ready time after start */
    for (uint64_t m = net->active; m; m &= m - 1) {
        int k = __builtin_ctzll(m);
        const sb_netnode *n = &net->nodes[k];
        if (n->head_t > start) {
            if (n->head_t < first)
                first = n->head_t;
        } else if (best < 0 || n->head_key < best_key || (n->head_key == best_key && rank_cmp(net, k, best) < 0)) {
            best = k;
            best_key = n->head_key;
        }
    }
    if (best < 0 && net->active) {  /* none ready while the wire is busy: idle until the first is ready */
        start = first;
        for (uint64_t m = net->active; m; m &= m - 1) {
            int k = __builtin_ctzll(m);
            const sb_netnode *n = &net->nodes[k];
            if (n->head_t <= start
                && (best < 0 || n->head_key < best_key || (n->head_key == best_key && rank_cmp(net, k, best) < 0))) {
                best = k;
                best_key = n->head_key;
            }
        }
    }
    net->choice_node = best;
    if (best >= 0) {
        net->choice_start_s = start;
        net->choice_dur_s = slot_duration(net, &net->slots[net->nodes[best].head]);
    }
    net->chosen = 1;
}

/* CanBusModel._start */
static void start_choice(sb_simnet *net)
{
    int k = net->choice_node;
    sb_netnode *n = &net->nodes[k];
    int s = n->head;
    n->head = net->slots[s].next;
    if (n->head < 0) {
        n->tail = -1;
        net->active &= ~((uint64_t)1 << k);
    } else {
        n->head_key = priority_key(&net->slots[n->head].f);
        n->head_t = net->slots[n->head].f.t;
    }
    n->queued--;
    net->slots[s].next = -1;
    net->chosen = 0;
    net->in_flight = s;
    net->in_start_s = net->choice_start_s;
    net->in_end_s = net->choice_start_s + net->choice_dur_s;
    net->free_at_s = net->in_end_s;
    net->busy_s += net->choice_dur_s;
    net->frames++;
}

/* CanBusModel.advance: completed transmissions go to the done list, in order. */
static void bus_advance(sb_simnet *net, double until_s)
{
    if (until_s > net->bus_now_s)
        net->bus_now_s = until_s;
    for (;;) {
        if (net->in_flight < 0) {
            arbitrate(net);
            if (net->choice_node < 0 || net->choice_start_s > until_s)
                return;
            start_choice(net);
        }
        if (net->in_end_s > until_s)
            return;
        int s = net->in_flight;
        net->slots[s].f.t = net->in_end_s;  /* from now on: its end */
        net->slots[s].next = -1;
        if (net->done_tail >= 0)
            net->slots[net->done_tail].next = s;
        else
            net->done_head = s;
        net->done_tail = s;
        net->in_flight = -1;
    }
}

static double bus_next_event(sb_simnet *net)
{
    if (net->in_flight >= 0)
        return net->in_end_s;
    arbitrate(net);
    return net->choice_node < 0 ? INFINITY : net->choice_start_s + net->choice_dur_s;
}

/* CanBusModel._join with joined_s = ready_s (schedule). */
static int join(sb_simnet *net, int node, uint32_t id, int flags, const uint8_t *data, size_t len,
                double ready_s, uint32_t tag)
{
    if (ready_s < net->bus_now_s)
        return SB_E_RANGE;
    if (net->free_slot < 0)
        return SB_E_FULL;
    int s = net->free_slot;
    sb_netslot *slot = &net->slots[s];
    net->free_slot = slot->next;
    net->used_slots++;
    slot->f.t = ready_s;
    slot->f.id = id;
    slot->f.flags = (uint8_t)flags;
    slot->f.len = (uint8_t)len;
    slot->f.node = (int16_t)node;
    slot->f.tag = tag ? (uint32_t)s + 1 : 0;  /* the caller keeps its object by slot */
    if (len)
        memcpy(slot->f.data, data, len);
    slot->joined_s = ready_s;
    slot->seq = net->seq++;
    slot->dur_epoch = net->rate_epoch;
    slot->dur_s = -1.0;
    slot->next = -1;
    sb_netnode *n = &net->nodes[node];
    if (!n->has_first || ready_s < n->first_joined_s
        || (ready_s == n->first_joined_s && slot->seq < n->first_seq)) {
        n->has_first = 1;
        n->first_joined_s = ready_s;
        n->first_seq = slot->seq;
    }
    n->queued++;
    if (n->tail < 0) {
        n->head = n->tail = s;
        n->head_key = priority_key(&slot->f);
        n->head_t = ready_s;
        net->active |= (uint64_t)1 << node;
        net->chosen = 0;
    } else if (net->slots[n->tail].joined_s <= ready_s) {  /* the usual case: behind every other */
        net->slots[n->tail].next = s;
        n->tail = s;
    } else if (ready_s < net->slots[n->head].joined_s) {  /* the new head: arbitration changes */
        slot->next = n->head;
        n->head = s;
        n->head_key = priority_key(&slot->f);
        n->head_t = ready_s;
        net->chosen = 0;
    } else {
        int p = n->head;
        while (net->slots[p].next >= 0 && net->slots[net->slots[p].next].joined_s <= ready_s)
            p = net->slots[p].next;
        slot->next = net->slots[p].next;
        net->slots[p].next = s;
    }
    return s;
}

/* A frame the wire can carry: flags, id width and length (CAN FD's eleven sizes only) as the frame
 * timing counts them, so every queued frame has a positive wire time. */
static int check_frame(uint32_t id, int flags, const uint8_t *data, size_t len)
{
    /* sb_can_frame_bits' refusals, without counting the bits (frame_time does, once per content) */
    int fd = (flags & SB_FRAME_FD) != 0;
    if ((data == NULL && len > 0) || (flags & ~(SB_FRAME_EXT | SB_FRAME_FD | SB_FRAME_BRS)) != 0
        || ((flags & SB_FRAME_BRS) && !fd) || id > ((flags & SB_FRAME_EXT) ? 0x1FFFFFFFu : 0x7FFu))
        return 0;
    if (len <= 8)
        return 1;
    return fd && (len == 12 || len == 16 || len == 20 || len == 24 || len == 32 || len == 48 || len == 64);
}

int sb_simnet_send(sb_simnet *net, int node, uint32_t id, int flags, const uint8_t *data, size_t len,
                   double ready_s, uint32_t tag)
{
    if (!net || node < 0 || node >= SB_NET_NODES || isnan(ready_s) || !check_frame(id, flags, data, len))
        return SB_E_ARG;
    if (node != 0 && !node_ok(net, node))
        return SB_E_ARG;
    return join(net, node, id, flags, data, len, ready_s, tag);
}

/* ---- nodes ---- */

static int in_use(const sb_simnet *net, int node)
{
    /* a removed node's slot is free again once nothing it sent is queued, on the wire or delivering */
    if (net->nodes[node].queued)
        return 1;
    if (net->in_flight >= 0 && net->slots[net->in_flight].f.node == node)
        return 1;
    for (int s = net->done_head; s >= 0; s = net->slots[s].next)
        if (net->slots[s].f.node == node)
            return 1;
    return 0;
}

int sb_simnet_add(sb_simnet *net, int kind, int linked, int has_first, double first_joined_s, int64_t first_seq)
{
    if (!net || (kind != SB_NODE_CORE && kind != SB_NODE_PYTHON))
        return SB_E_ARG;
    int node = -1;
    for (int k = 1; k < SB_NET_NODES && node < 0; k++)
        if (net->nodes[k].kind == SB_NODE_FREE || (net->nodes[k].kind == SB_NODE_GONE && !in_use(net, k)))
            node = k;
    if (node < 0 || net->n_order >= SB_NET_NODES - 1)
        return SB_E_FULL;
    sb_netnode *n = &net->nodes[node];
    memset(n, 0, sizeof *n);
    n->kind = kind;
    n->linked = linked != 0;
    n->head = n->tail = -1;
    n->deadline_s = INFINITY;
    n->has_first = has_first != 0;
    n->first_joined_s = first_joined_s;
    n->first_seq = first_seq;
    n->cursor = net->log_count;  /* frames before it joined are not its concern */
    n->mark_odd = net->log_odd;
    memset(&net->motors[node], 0, sizeof net->motors[node]);
    net->motors[node].py_deadline_s = INFINITY;
    net->order[net->n_order++] = (int16_t)node;
    net->deadline_known = 0;
    routes_clear(net);
    return node;
}

int sb_simnet_remove(sb_simnet *net, int node)
{
    if (!net || !node_ok(net, node) || net->phase != PHASE_NONE)
        return SB_E_ARG;
    int j = 0;
    for (int i = 0; i < net->n_order; i++)
        if (net->order[i] != node)
            net->order[j++] = net->order[i];
    net->n_order = j;
    net->deadline_known = 0;
    net->nodes[node].kind = SB_NODE_GONE;
    net->nodes[node].linked = 0;
    net->nodes[node].deadline_s = INFINITY;
    net->nodes[node].listen_all = 0;
    net->nodes[node].n_listen = 0;
    routes_clear(net);
    return SB_OK;
}

int sb_simnet_touch(sb_simnet *net, int node)
{
    if (!net || !node_ok(net, node))
        return SB_E_ARG;
    sb_simmotor *m = &net->motors[node];
    sb_netnode *n = &net->nodes[node];
    int count = m->n_listen < 0 ? 0 : (m->n_listen > SB_SIM_MAX_LISTEN ? SB_SIM_MAX_LISTEN : m->n_listen);
    int all = m->listen_all != 0;
    if (all != n->listen_all || count != n->n_listen || memcmp(m->listen, n->listen, sizeof m->listen[0] * (size_t)count)) {
        n->listen_all = all;
        n->n_listen = count;
        memcpy(n->listen, m->listen, sizeof m->listen[0] * (size_t)count);
        routes_clear(net);
    }
    node_deadline(net, node);
    return SB_OK;
}

/* ---- the step: SimCanNetwork._step ---- */

static double next_deadline(sb_simnet *net)
{
    if (net->deadline_known)
        return net->deadline_min;
    double d = INFINITY;
    for (int i = 0; i < net->n_order; i++) {
        double x = net->nodes[net->order[i]].deadline_s;
        if (x < d)
            d = x;
    }
    net->deadline_min = d;
    net->deadline_known = 1;
    return d;
}

double sb_simnet_next_event(sb_simnet *net, int bus_only)
{
    if (!net)
        return NAN;
    if (bus_only)
        return bus_next_event(net);
    if (net->phase != PHASE_NONE)
        return net->phase_t;
    double t = bus_next_event(net);
    double d = next_deadline(net);
    return d < t ? d : t;
}

int sb_simnet_next_completion(sb_simnet *net, double *end_s, int *node)
{
    if (!net || !end_s || !node)
        return SB_E_ARG;
    if (net->in_flight >= 0) {
        *end_s = net->in_end_s;
        *node = net->slots[net->in_flight].f.node;
        return 1;
    }
    arbitrate(net);
    if (net->choice_node < 0)
        return 0;
    *end_s = net->choice_start_s + net->choice_dur_s;
    *node = net->choice_node;
    return 1;
}

typedef struct {
    sb_netevent *ev;
    int cap;
    int n;
} evbuf;

static sb_netevent *emit(evbuf *b, int kind, int node, double t)
{
    sb_netevent *e = &b->ev[b->n++];
    e->kind = kind;
    e->node = node;
    e->t = t;
    return e;
}

/* Queue what a family's C path answered, from node, in order. */
static int queue_out(sb_simnet *net, int node, int n_out)
{
    if (n_out < 0 || n_out > SB_NET_OUT)
        return SB_E_ARG;
    for (int i = 0; i < n_out; i++) {
        const sb_simframe *f = &net->out[i];
        if (isnan(f->t) || !check_frame(f->id, f->flags, f->data, f->len))
            return SB_E_ARG;
        int s = join(net, node, f->id, f->flags, f->data, f->len, f->t, 0);
        if (s < 0)
            return s;
    }
    return SB_OK;
}

static int family_receive(sb_simnet *net, int node, const sb_simframe *in, double t, int *n_out)
{
    sb_simmotor *m = &net->motors[node];
    *n_out = 0;
    switch (m->family) {
    case SB_FAMILY_MYACTUATOR: return sb_ma_receive(m, in, t, net->out, SB_NET_OUT, n_out);
    case SB_FAMILY_LK: return sb_lk_receive(m, in, t, net->out, SB_NET_OUT, n_out);
    case SB_FAMILY_HOLLOW: return sb_hollow_receive(m, in, t, net->out, SB_NET_OUT, n_out);
    }
    return SB_HOT_COLD;
}

static int family_poll(sb_simnet *net, int node, double t, int *n_out)
{
    sb_simmotor *m = &net->motors[node];
    *n_out = 0;
    switch (m->family) {
    case SB_FAMILY_MYACTUATOR: return sb_ma_poll(m, t, net->out, SB_NET_OUT, n_out);
    case SB_FAMILY_LK: return sb_lk_poll(m, t, net->out, SB_NET_OUT, n_out);
    case SB_FAMILY_HOLLOW: return sb_hollow_poll(m, t, net->out, SB_NET_OUT, n_out);
    }
    return SB_HOT_COLD;
}

/* The due nodes of a step, polled in the order they were added (SimCanNetwork._due and _step). */
static int run_polls(sb_simnet *net, evbuf *b)
{
    double t = net->phase_t;
    while (net->phase_pos < net->n_order) {
        int k = net->order[net->phase_pos];
        if (!(net->phase_due & ((uint64_t)1 << k))) {
            net->phase_pos++;
            continue;
        }
        if (b->n >= b->cap)
            return SB_RUN_EVENTS_FULL;
        net->phase_due &= ~((uint64_t)1 << k);
        net->phase_pos++;
        int python = 1;
        if (family_c(net, k) && family_deadline(&net->motors[k]) <= t) {
            int n_out = 0;
            int r = family_poll(net, k, t, &n_out);
            if (r == SB_HOT_DONE) {
                int q = queue_out(net, k, n_out);
                if (q < 0)
                    return q;
                double py = net->motors[k].py_deadline_s;
                python = py <= t;  /* the Python model's own deadline came too */
            } else if (r != SB_HOT_COLD) {
                return SB_E_ARG;
            }
        }
        if (python) {
            emit(b, SB_EV_POLL, k, t);
            set_deadline(net, k, INFINITY);  /* asked again after its poll (touch) */
            return SB_RUN_STOPPED;
        }
        node_deadline(net, k);
    }
    net->phase = PHASE_NONE;
    return SB_RUN_IDLE;
}

static void free_slot(sb_simnet *net, int s)
{
    net->slots[s].next = net->free_slot;
    net->free_slot = s;
    net->used_slots--;
}

/* SimCanNetwork._deliver, for each completed transmission in turn. */
static int run_deliveries(sb_simnet *net, evbuf *b, int flags)
{
    while (net->done_head >= 0) {
        int s = net->done_head;
        sb_simframe *f = &net->slots[s].f;
        int src = f->node;
        int odd = (f->flags & (SB_FRAME_EXT | SB_FRAME_FD)) != 0;
        if (net->phase_pos < 0) {  /* its first visit: the log and the sender's own count */
            int64_t at = net->log_count - net->log_base;
            net->log_end[at] = f->t;
            net->log_src[at] = (int16_t)src;
            net->log_count++;
            net->log_odd += odd;
            if (src > 0 && net->nodes[src].linked) {
                net->nodes[src].own++;
                net->nodes[src].own_odd += odd;
            }
            net->phase_pos = 0;
        }
        if (net->phase_pos < net->n_order) {
            uint64_t mask = route_mask(net, f->id);
            while (net->phase_pos < net->n_order) {
                int k = net->order[net->phase_pos];
                if (k == src || !(mask & ((uint64_t)1 << k))) {
                    net->phase_pos++;
                    continue;
                }
                if (b->n >= b->cap)
                    return SB_RUN_EVENTS_FULL;
                net->phase_pos++;
                sb_netnode *n = &net->nodes[k];
                if (n->linked) {
                    n->taken++;
                    n->taken_odd += odd;
                }
                if (family_c(net, k)) {
                    int n_out = 0;
                    int r = family_receive(net, k, f, f->t, &n_out);
                    if (r == SB_HOT_DONE) {
                        int q = queue_out(net, k, n_out);
                        if (q < 0)
                            return q;
                        node_deadline(net, k);
                        continue;
                    }
                    if (r != SB_HOT_COLD)
                        return SB_E_ARG;
                }
                sb_netevent *e = emit(b, SB_EV_DELIVER, k, f->t);
                e->frame = *f;
                return SB_RUN_STOPPED;
            }
        }
        if (src != 0) {  /* the host receives every frame but its own */
            if (net->phase_pos == net->n_order) {
                if (b->n >= b->cap)
                    return SB_RUN_EVENTS_FULL;
                sb_netevent *e = emit(b, SB_EV_RX, 0, f->t);
                e->frame = *f;
                net->phase_pos++;
                if (flags & SB_RUN_STOP_RX)
                    return SB_RUN_STOPPED;
            }
        }
        net->done_head = net->slots[s].next;
        if (net->done_head < 0)
            net->done_tail = -1;
        free_slot(net, s);
        net->phase_pos = -1;
    }
    net->phase = PHASE_NONE;
    return SB_RUN_IDLE;
}

static int continue_phase(sb_simnet *net, evbuf *b, int flags)
{
    if (net->phase == PHASE_POLL)
        return run_polls(net, b);
    if (net->phase == PHASE_DELIVER)
        return run_deliveries(net, b, flags);
    return SB_RUN_IDLE;
}

static void begin_step(sb_simnet *net, double t)
{
    if (t > net->now_s)
        net->now_s = t;
    uint64_t due = 0;
    if (next_deadline(net) <= t) {
        for (int i = 0; i < net->n_order; i++) {
            int k = net->order[i];
            if (net->nodes[k].deadline_s <= t)
                due |= (uint64_t)1 << k;
        }
    }
    net->phase_t = t;
    if (due) {
        net->phase = PHASE_POLL;
        net->phase_due = due;
        net->phase_pos = 0;
        return;
    }
    bus_advance(net, t);
    net->phase = PHASE_DELIVER;
    net->phase_pos = -1;
}

int sb_simnet_run(sb_simnet *net, double until_s, double before_s, double host_time_s, int mode,
                  sb_netevent *ev, int cap, int *n_events)
{
    if (!net || !n_events || (cap > 0 && !ev) || cap < 0 || (mode & ~(SB_RUN_AHEAD | SB_RUN_STOP_RX))
        || isnan(until_s) || isnan(before_s) || isnan(host_time_s))
        return SB_E_ARG;
    *n_events = 0;
    evbuf b = {ev, cap, 0};
    int ahead = mode & SB_RUN_AHEAD;
    int r;
    for (;;) {
        r = continue_phase(net, &b, mode);
        if (r != SB_RUN_IDLE)
            break;
        double t = sb_simnet_next_event(net, 0);
        if (t == INFINITY || t >= before_s || (!ahead && t > until_s))
            break;
        if (ahead) {  /* SimCanNetwork.run_ahead's conditions */
            const sb_netnode *host = &net->nodes[0];
            if (host->head < 0 || net->slots[host->head].joined_s > host_time_s)
                break;
            double end;
            int node;
            if (sb_simnet_next_completion(net, &end, &node) == 1 && end <= t && node != 0)
                break;
        }
        /* room in the log for everything that could end in this step */
        if (net->log_count - net->log_base + net->used_slots + 1 > SB_NET_LOG) {
            r = SB_RUN_LOG_FULL;
            break;
        }
        begin_step(net, t);
    }
    *n_events = b.n;
    return r;
}

/* ---- the host's turn: SimTransport's timer in one call ---- */

static int turn(sb_simnet *net, double until_s, int64_t log_limit, sb_netturn *out)
{
    sb_netevent *ev = out->ev;
    int cap = SB_TURN_EVENTS;
    out->stage = SB_TURN_ADVANCE;
    out->next_s = INFINITY;
    int r = sb_simnet_run(net, until_s, INFINITY, INFINITY, SB_RUN_ADVANCE, ev, cap, &out->n_events);
    if (r != SB_RUN_IDLE)
        return r;
    if (until_s > net->now_s)  /* CoreCanNetwork.advance: the network's time reaches until_s */
        net->now_s = until_s;
    out->stage = SB_TURN_BETWEEN;
    if (net->log_count - net->log_base >= log_limit)
        return SB_RUN_LOG_FULL;  /* the caller settles its links up first (its _tidy) */
    if (isfinite(net->bitrate)) {  /* run_ahead: over what the host can neither see nor change */
        out->stage = SB_TURN_AHEAD;
        int n = out->n_events, more = 0;
        r = sb_simnet_run(net, INFINITY, INFINITY, until_s, SB_RUN_AHEAD, ev + n, cap - n, &more);
        out->n_events = n + more;
        if (r != SB_RUN_IDLE)
            return r;
    }
    out->stage = SB_TURN_DONE;
    out->next_s = sb_simnet_next_event(net, 0);
    return net->log_count - net->log_base >= log_limit ? SB_RUN_LOG_FULL : SB_RUN_IDLE;
}

int sb_simnet_turn(sb_simnet *net, double until_s, int64_t log_limit, sb_netturn *out)
{
    if (!out)
        return SB_E_ARG;
    out->n_events = 0;
    if (!net || isnan(until_s)) {
        out->stage = SB_TURN_ADVANCE;
        return out->status = SB_E_ARG;
    }
    out->status = turn(net, until_s, log_limit, out);
    if (out->status == SB_RUN_IDLE && out->stage == SB_TURN_DONE)
        return out->n_events;
    return out->status < 0 ? out->status : SB_TURN_MORE;
}

int sb_simnet_host_send(sb_simnet *net, uint32_t key, const uint8_t *data, size_t len, double ready_s)
{
    return sb_simnet_send(net, 0, key & 0x1FFFFFFFu, (int)(key >> 29), data, len, ready_s, 1);
}

/* ---- links: BusLink ---- */

int sb_simnet_catch_up(sb_simnet *net, int node, int every_end, int64_t *missed, int64_t *missed_odd,
                       double *ends, int cap, int *n_ends)
{
    if (!net || !node_ok(net, node) || !missed || !missed_odd || !ends || !n_ends || cap < SB_NET_LOG)
        return SB_E_ARG;
    sb_netnode *n = &net->nodes[node];
    int64_t start = n->cursor;
    if (start < net->log_base)
        return SB_E_ARG;  /* the log was dropped past this link: a bug in the caller */
    n->cursor = net->log_count;
    *missed = (net->log_count - start) - (n->own - n->mark_own) - (n->taken - n->mark_taken);
    *missed_odd = (net->log_odd - n->mark_odd) - (n->own_odd - n->mark_own_odd) - (n->taken_odd - n->mark_taken_odd);
    n->mark_odd = net->log_odd;
    n->mark_own = n->own;
    n->mark_own_odd = n->own_odd;
    n->mark_taken = n->taken;
    n->mark_taken_odd = n->taken_odd;
    int64_t first = start - net->log_base, last = net->log_count - net->log_base;
    int count = 0;
    if (every_end) {
        for (int64_t i = first; i < last; i++)
            if (net->log_src[i] != node)
                ends[count++] = net->log_end[i];
    } else {
        for (int64_t i = last - 1; i >= first; i--)
            if (net->log_src[i] != node) {
                ends[count++] = net->log_end[i];
                break;
            }
    }
    *n_ends = count;
    return SB_OK;
}

int sb_simnet_drop_log(sb_simnet *net)
{
    if (!net)
        return SB_E_ARG;
    int64_t keep = net->log_count;
    for (int k = 1; k < SB_NET_NODES; k++)
        if (net->nodes[k].linked && net->nodes[k].cursor < keep)
            keep = net->nodes[k].cursor;
    int64_t drop = keep - net->log_base, left = net->log_count - keep;
    if (drop > 0) {
        memmove(net->log_end, net->log_end + drop, sizeof net->log_end[0] * (size_t)left);
        memmove(net->log_src, net->log_src + drop, sizeof net->log_src[0] * (size_t)left);
        net->log_base = keep;
    }
    return (int)left;
}

double sb_simnet_last_ready(const sb_simnet *net, double limit_s)
{
    if (!net)
        return NAN;
    double found = -INFINITY;
    for (uint64_t m = net->active; m; m &= m - 1)
        for (int s = net->nodes[__builtin_ctzll(m)].head; s >= 0; s = net->slots[s].next) {
            double r = net->slots[s].f.t;
            if (r > net->now_s && r <= limit_s && r > found)
                found = r;
        }
    return found;
}

double sb_simnet_frame_time(const sb_simnet *net, uint32_t id, int flags, const uint8_t *data, size_t len)
{
    if (!net || !check_frame(id, flags, data, len))
        return SB_E_ARG;
    return sb_can_frame_time(id, flags, data, len, net->bitrate, net->data_bitrate);
}
