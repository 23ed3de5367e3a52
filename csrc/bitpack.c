/* Field scaling (float <-> integer code) and the bit layouts of the MIT-style and hollow frames.
 *
 * Packing is two steps per frame: every field's value becomes a code (encode(), shared by all
 * layouts), then one small put_* function places the codes into bytes. Unpacking is the mirror:
 * get_* extracts codes, decode() scales them. A batch is one call, so a control tick over many
 * motors costs one FFI crossing. Layout bit tables: myactuator-v4.md §5, hollow.md §4, §5.3, §7. */
#include <math.h>
#include <string.h>

#include "sb_internal.h"

#define MAX_FIELDS 8

typedef struct {
    int size;              /* bytes */
    int nfields;
    int bits[MAX_FIELDS];  /* width of each field; negative = signed two's complement */
} layout_desc;

static const layout_desc LAYOUTS[SB_LAYOUT_COUNT + 1] = {
    [SB_LAYOUT_MIT_COMMAND] = {8, 5, {16, 12, 12, 12, 12}},
    [SB_LAYOUT_HOLLOW_SETPOINT] = {8, 5, {16, 12, 12, 12, 12}},
    [SB_LAYOUT_MIT_REPLY] = {6, 4, {8, 16, 12, 12}},
    [SB_LAYOUT_HOLLOW_EXT_REPLY] = {8, 4, {8, -32, 12, 12}},
    [SB_LAYOUT_HOLLOW_FD_COMMAND] = {16, 8, {-40, -32, -16, 8, 8, 8, 8, 8}},
    [SB_LAYOUT_HOLLOW_FD_REPLY] = {16, 8, {-40, -32, -16, 8, 8, 8, -8, 8}},
};

static const layout_desc *find_layout(int layout)
{
    if (layout < 1 || layout > SB_LAYOUT_COUNT)
        return NULL;
    return &LAYOUTS[layout];
}

int sb_layout_size(int layout)
{
    const layout_desc *l = find_layout(layout);
    return l ? l->size : 0;
}

int sb_layout_fields(int layout)
{
    const layout_desc *l = find_layout(layout);
    return l ? l->nfields : 0;
}

int sb_layout_field_bits(int layout, int field)
{
    const layout_desc *l = find_layout(layout);
    if (!l || field < 0 || field >= l->nfields)
        return 0;
    return l->bits[field];
}

/* ---- scaling ---- */

/* A field the formulas below can use. A zero codes or span (or a NaN anywhere) would make the code
 * NaN, and converting NaN to an integer is undefined behaviour; so would an infinite origin. */
static int field_ok(const sb_field *f)
{
    return isfinite(f->lo) && isfinite(f->hi) && isfinite(f->origin) && isfinite(f->codes) &&
           isfinite(f->span) && f->lo <= f->hi && f->codes > 0 && f->span > 0;
}

/* Checks shared by sb_pack and sb_unpack: the pointers, the stride, that `cap` holds n slots of
 * `per_slot` (compared by division, so n * per_slot cannot overflow), and every field. */
static int check_batch(const layout_desc *l, const sb_field *fields, const void *in, size_t n,
                       size_t stride, const void *out, size_t cap, size_t per_slot)
{
    if (stride < (size_t)l->size)
        return SB_E_ARG;
    if (n == 0)
        return SB_OK;
    if (!fields || !in || !out || n > cap / per_slot)
        return SB_E_ARG;
    for (int k = 0; k < l->nfields; k++)
        if (!field_ok(&fields[k]))
            return SB_E_ARG;
    return SB_OK;
}

static inline int encode(const sb_field *f, double x, int bits, int flags, int64_t *code)
{
    int64_t lo, hi;
    double v;

    if (isnan(x))
        return SB_E_NAN;
    if (!(x >= f->lo && x <= f->hi)) {
        if (!(flags & SB_PACK_SATURATE))
            return SB_E_RANGE;
        x = x < f->lo ? f->lo : f->hi;
    }
    /* The order (x - origin) * codes / span is part of the contract: it makes the manuals' MIT
     * example exact (22.5 * 65535 / 25 = 58981.5, a tie that rounds up to 58982). */
    v = round((x - f->origin) * f->codes / f->span);
    if (bits < 0) {
        hi = ((int64_t)1 << (-bits - 1)) - 1;
        lo = -hi - 1;
    } else {
        lo = 0;
        hi = ((int64_t)1 << bits) - 1;
    }
    *code = v <= (double)lo ? lo : v >= (double)hi ? hi : (int64_t)v;
    return SB_OK;
}

static inline double decode(const sb_field *f, int64_t code)
{
    return (double)code * f->span / f->codes + f->origin;
}

/* ---- byte placement ---- */

static inline void put_be(uint8_t *o, int n, int64_t code)
{
    uint64_t u = (uint64_t)code;
    for (int i = n - 1; i >= 0; i--) {
        o[i] = (uint8_t)u;
        u >>= 8;
    }
}

static inline int64_t get_be_signed(const uint8_t *p, int n)
{
    uint64_t u = 0;
    uint64_t sign = (uint64_t)1 << (8 * n - 1);
    for (int i = 0; i < n; i++)
        u = (u << 8) | p[i];
    return (u & sign) ? (int64_t)(u - (sign << 1)) : (int64_t)u;
}

static void put_mit_command(const int64_t *c, uint8_t *o)
{
    uint64_t w = ((uint64_t)c[0] << 48) | ((uint64_t)c[1] << 36) | ((uint64_t)c[2] << 24) |
                 ((uint64_t)c[3] << 12) | (uint64_t)c[4];
    put_be(o, 8, (int64_t)w);
}

static void get_mit_command(const uint8_t *b, int64_t *c)
{
    uint64_t w = 0;
    for (int i = 0; i < 8; i++)
        w = (w << 8) | b[i];
    c[0] = (int64_t)(w >> 48);
    c[1] = (int64_t)((w >> 36) & 0xFFF);
    c[2] = (int64_t)((w >> 24) & 0xFFF);
    c[3] = (int64_t)((w >> 12) & 0xFFF);
    c[4] = (int64_t)(w & 0xFFF);
}

/* FF x7 followed by F9..FE is a hollow special command (start, stop, mode, zero), so a setpoint
 * must never look like one (hollow.md §4.1, A35): step the position one code down instead. */
static void put_hollow_setpoint(const int64_t *c, uint8_t *o)
{
    put_mit_command(c, o);
    if (o[7] >= 0xF9 && o[7] <= 0xFE && o[0] == 0xFF && o[1] == 0xFF && o[2] == 0xFF &&
        o[3] == 0xFF && o[4] == 0xFF && o[5] == 0xFF && o[6] == 0xFF)
        o[1] = 0xFE;
}

static void put_mit_reply(const int64_t *c, uint8_t *o)
{
    o[0] = (uint8_t)c[0];
    o[1] = (uint8_t)(c[1] >> 8);
    o[2] = (uint8_t)c[1];
    o[3] = (uint8_t)(c[2] >> 4);
    o[4] = (uint8_t)(((c[2] & 0xF) << 4) | (c[3] >> 8));
    o[5] = (uint8_t)c[3];
}

static void get_mit_reply(const uint8_t *b, int64_t *c)
{
    c[0] = b[0];
    c[1] = ((int64_t)b[1] << 8) | b[2];
    c[2] = ((int64_t)b[3] << 4) | (b[4] >> 4);
    c[3] = ((int64_t)(b[4] & 0xF) << 8) | b[5];
}

static void put_hollow_ext_reply(const int64_t *c, uint8_t *o)
{
    uint32_t x = (uint32_t)c[1];
    int64_t mit[4] = {c[0], x & 0xFFFF, c[2], c[3]};
    put_mit_reply(mit, o);
    o[6] = (uint8_t)(x >> 24);
    o[7] = (uint8_t)(x >> 16);
}

static void get_hollow_ext_reply(const uint8_t *b, int64_t *c)
{
    uint32_t x = ((uint32_t)b[6] << 24) | ((uint32_t)b[7] << 16) | ((uint32_t)b[1] << 8) | b[2];
    get_mit_reply(b, c);
    c[1] = (x & 0x80000000u) ? (int64_t)x - ((int64_t)1 << 32) : (int64_t)x;
}

/* CAN FD request and reply share the byte positions; only field 6's sign differs (temperature). */
static void put_hollow_fd(const int64_t *c, uint8_t *o)
{
    put_be(o, 5, c[0]);
    put_be(o + 5, 4, c[1]);
    put_be(o + 9, 2, c[2]);
    for (int i = 3; i < 8; i++)
        o[8 + i] = (uint8_t)c[i];
}

static void get_hollow_fd(const uint8_t *b, int64_t *c, int signed_byte14)
{
    c[0] = get_be_signed(b, 5);
    c[1] = get_be_signed(b + 5, 4);
    c[2] = get_be_signed(b + 9, 2);
    for (int i = 3; i < 8; i++)
        c[i] = b[8 + i];
    if (signed_byte14)
        c[6] = (int8_t)b[14];
}

/* Every layout is listed: an unknown one is an error, never another layout's bytes. */
static int put_codes(int layout, const int64_t *c, uint8_t *o)
{
    switch (layout) {
    case SB_LAYOUT_MIT_COMMAND: put_mit_command(c, o); return SB_OK;
    case SB_LAYOUT_HOLLOW_SETPOINT: put_hollow_setpoint(c, o); return SB_OK;
    case SB_LAYOUT_MIT_REPLY: put_mit_reply(c, o); return SB_OK;
    case SB_LAYOUT_HOLLOW_EXT_REPLY: put_hollow_ext_reply(c, o); return SB_OK;
    case SB_LAYOUT_HOLLOW_FD_COMMAND:
    case SB_LAYOUT_HOLLOW_FD_REPLY: put_hollow_fd(c, o); return SB_OK;
    }
    return SB_E_LAYOUT;
}

static int get_codes(int layout, const uint8_t *b, int64_t *c)
{
    switch (layout) {
    case SB_LAYOUT_MIT_COMMAND:
    case SB_LAYOUT_HOLLOW_SETPOINT: get_mit_command(b, c); return SB_OK;
    case SB_LAYOUT_MIT_REPLY: get_mit_reply(b, c); return SB_OK;
    case SB_LAYOUT_HOLLOW_EXT_REPLY: get_hollow_ext_reply(b, c); return SB_OK;
    case SB_LAYOUT_HOLLOW_FD_COMMAND: get_hollow_fd(b, c, 0); return SB_OK;
    case SB_LAYOUT_HOLLOW_FD_REPLY: get_hollow_fd(b, c, 1); return SB_OK;
    }
    return SB_E_LAYOUT;
}

/* ---- batch entry points ---- */

int sb_pack(int layout, const sb_field *fields, const double *values, size_t n, size_t stride,
            int flags, uint8_t *out, size_t out_cap, sb_pack_error *err)
{
    const layout_desc *l = find_layout(layout);
    int64_t codes[MAX_FIELDS];
    int status;

    if (!l)
        return SB_E_LAYOUT;
    if (flags & ~SB_PACK_SATURATE)
        return SB_E_ARG;
    status = check_batch(l, fields, values, n, stride, out, out_cap, stride);
    if (status != SB_OK)
        return status;
    for (size_t i = 0; i < n; i++) {
        const double *row = values + i * (size_t)l->nfields;
        uint8_t *o = out + i * stride;
        for (int k = 0; k < l->nfields; k++) {
            status = encode(&fields[k], row[k], l->bits[k], flags, &codes[k]);
            if (status != SB_OK) {
                if (err) {
                    err->frame = i;
                    err->field = k;
                    err->value = row[k];
                }
                return status;
            }
        }
        status = put_codes(layout, codes, o);
        if (status != SB_OK)
            return status;
        if (stride > (size_t)l->size)
            memset(o + l->size, 0, stride - (size_t)l->size);
    }
    return SB_OK;
}

int sb_unpack(int layout, const sb_field *fields, const uint8_t *frames, size_t n, size_t stride,
              double *values, size_t values_cap)
{
    const layout_desc *l = find_layout(layout);
    int64_t codes[MAX_FIELDS];
    int status;

    if (!l)
        return SB_E_LAYOUT;
    status = check_batch(l, fields, frames, n, stride, values, values_cap, (size_t)l->nfields);
    if (status != SB_OK)
        return status;
    for (size_t i = 0; i < n; i++) {
        const uint8_t *b = frames + i * stride;
        double *row = values + i * (size_t)l->nfields;
        status = get_codes(layout, b, codes);
        if (status != SB_OK)
            return status;
        for (int k = 0; k < l->nfields; k++)
            row[k] = decode(&fields[k], codes[k]);
    }
    return SB_OK;
}
