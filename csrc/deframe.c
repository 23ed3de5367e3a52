/* Incremental stream de-framers for the serial links: MyActuator RS485 (myactuator-v4.md §1.2), the
 * hollow converter's transparent mode (hollow.md §9.4) and Modbus RTU (hollow.md §9.5).
 *
 * Contract: bytes in any chunking; whole, checked frames out; the remainder kept in the fixed buffer.
 * A byte that cannot start a frame is dropped and counted. A complete candidate whose CRC fails is
 * dropped one byte at a time too (its first byte may have been noise before a real frame), and
 * counts as one CRC error if it stood where a frame was expected. Nothing here can read outside
 * buf[0 .. len): every parse step checks `avail` before it looks. */
#include <limits.h>
#include <string.h>

#include "sb_internal.h"

/* PARSE_BAD_KIND: the state names no known de-framer (checked on entry, so never expected). */
enum parse_result { PARSE_FRAME, PARSE_NEED_MORE, PARSE_BAD_HEADER, PARSE_BAD_CRC, PARSE_BAD_KIND };

static inline int crc16_ok(const uint8_t *b, size_t n)
{
    uint16_t crc = sb_crc16_modbus_raw(b, n - 2, 0xFFFF);
    return b[n - 2] == (uint8_t)crc && b[n - 1] == (uint8_t)(crc >> 8);
}

static enum parse_result parse_rs485(const uint8_t *b, size_t avail, int max_len, size_t *flen)
{
    size_t n;

    if (b[0] != 0x3E)
        return PARSE_BAD_HEADER;
    if (avail < 3)
        return PARSE_NEED_MORE;
    if (b[2] == 0 || b[2] > max_len)
        return PARSE_BAD_HEADER;
    n = (size_t)b[2] + 5;
    if (avail < n)
        return PARSE_NEED_MORE;
    *flen = n;
    return crc16_ok(b, n) ? PARSE_FRAME : PARSE_BAD_CRC;
}

static enum parse_result parse_transparent(const uint8_t *b, size_t avail, size_t *flen)
{
    uint32_t crc, sent;

    if (avail < SB_TRANSPARENT_FRAME)
        return PARSE_NEED_MORE;
    crc = sb_crc32_ieee_raw(b, 17, 0);
    sent = (uint32_t)b[17] | ((uint32_t)b[18] << 8) | ((uint32_t)b[19] << 16) | ((uint32_t)b[20] << 24);
    *flen = SB_TRANSPARENT_FRAME;
    return crc == sent ? PARSE_FRAME : PARSE_BAD_CRC;
}

/* Modbus RTU has no length field common to all frames: each function (and direction) implies one.
 * With both directions enabled a frame may have two candidate lengths; the CRC decides, shorter
 * first. Only what the hollow converter speaks: 0x03, 0x10 and their exception replies. */
static enum parse_result parse_modbus(const uint8_t *b, size_t avail, int dirs, size_t *flen)
{
    size_t cand[2];
    int ncand = 0, pending = 0, checked = 0;

    if (avail < 2)
        return PARSE_NEED_MORE;
    /* A wire byte, not a kind: any other function cannot start a frame, so it is noise. */
    if (b[1] != 0x03 && b[1] != 0x10 && b[1] != 0x83 && b[1] != 0x90)
        return PARSE_BAD_HEADER;
    switch (b[1]) {
    case 0x03:
        if (dirs & SB_MODBUS_REQUESTS)
            cand[ncand++] = 8;  /* addr fn start(2) count(2) crc(2) */
        if (dirs & SB_MODBUS_REPLIES) {
            if (avail < 3) {
                pending = 1;
            } else if (b[2] >= 2 && b[2] <= 250 && !(b[2] & 1)) {
                cand[ncand++] = 5 + (size_t)b[2];  /* addr fn count data crc(2) */
            }
        }
        break;
    case 0x10:
        if (dirs & SB_MODBUS_REPLIES)
            cand[ncand++] = 8;  /* addr fn start(2) count(2) crc(2) */
        if (dirs & SB_MODBUS_REQUESTS) {
            if (avail < 7) {
                pending = 1;
            } else {
                unsigned count = ((unsigned)b[4] << 8) | b[5];
                if (count >= 1 && count <= 123 && b[6] == 2 * count)
                    cand[ncand++] = 9 + (size_t)b[6];  /* addr fn start count n data crc */
            }
        }
        break;
    case 0x83:
    case 0x90:
        if (dirs & SB_MODBUS_REPLIES)
            cand[ncand++] = 5;  /* addr fn|0x80 exception-code crc(2) */
        break;
    }
    /* Candidates are appended in increasing length except for 0x03 both-ways; sort the pair. */
    if (ncand == 2 && cand[0] > cand[1]) {
        size_t t = cand[0];
        cand[0] = cand[1];
        cand[1] = t;
    }
    for (int i = 0; i < ncand; i++) {
        if (avail < cand[i]) {
            pending = 1;
            continue;
        }
        checked = 1;
        if (crc16_ok(b, cand[i])) {
            *flen = cand[i];
            return PARSE_FRAME;
        }
    }
    if (pending)
        return PARSE_NEED_MORE;
    return checked ? PARSE_BAD_CRC : PARSE_BAD_HEADER;
}

/* Every kind is listed with its options; an unknown kind is SB_E_LAYOUT. */
static int check_kind(int kind, int option)
{
    switch (kind) {
    case SB_DEFRAME_MYACTUATOR_RS485:
        return option >= 1 && option <= 255 ? SB_OK : SB_E_ARG;
    case SB_DEFRAME_HOLLOW_TRANSPARENT:
        return option == 0 ? SB_OK : SB_E_ARG;
    case SB_DEFRAME_MODBUS_RTU:
        return option >= 1 && option <= (SB_MODBUS_REQUESTS | SB_MODBUS_REPLIES) ? SB_OK : SB_E_ARG;
    }
    return SB_E_LAYOUT;
}

/* The state is caller memory (Python can write its fields), so every entry point checks it before
 * trusting kind, option or len: a bad len would let memcpy/memmove run past buf. */
static int check_state(const sb_deframer *d)
{
    int status;

    if (!d)
        return SB_E_ARG;
    status = check_kind(d->kind, d->option);
    if (status != SB_OK)
        return status;
    return d->len <= SB_DEFRAME_CAPACITY ? SB_OK : SB_E_ARG;
}

size_t sb_deframer_max_frame(const sb_deframer *d)
{
    if (check_state(d) != SB_OK)
        return 0;
    switch (d->kind) {
    case SB_DEFRAME_MYACTUATOR_RS485: return (size_t)d->option + 5;
    case SB_DEFRAME_HOLLOW_TRANSPARENT: return SB_TRANSPARENT_FRAME;
    case SB_DEFRAME_MODBUS_RTU: return SB_MODBUS_MAX_FRAME;
    }
    return 0;
}

int sb_deframer_init(sb_deframer *d, int kind, int option)
{
    int status;

    if (!d)
        return SB_E_ARG;
    memset(d, 0, sizeof *d);
    status = check_kind(kind, option);
    if (status != SB_OK)
        return status;
    d->kind = kind;
    d->option = option;
    d->synced = 1;
    return SB_OK;
}

int sb_deframer_reset(sb_deframer *d)
{
    int status = check_state(d);

    if (status != SB_OK)
        return status;
    d->discarded_bytes += d->len;
    d->len = 0;
    d->synced = 1;
    return SB_OK;
}

static enum parse_result parse(const sb_deframer *d, const uint8_t *b, size_t avail, size_t *flen)
{
    switch (d->kind) {
    case SB_DEFRAME_MYACTUATOR_RS485: return parse_rs485(b, avail, d->option, flen);
    case SB_DEFRAME_HOLLOW_TRANSPARENT: return parse_transparent(b, avail, flen);
    case SB_DEFRAME_MODBUS_RTU: return parse_modbus(b, avail, d->option, flen);
    }
    return PARSE_BAD_KIND;
}

/* Parse what buf holds into out/lens (from *out_used / *nframes on). With line_idle set, the line
 * has gone quiet, so a frame that still needs bytes will never get them: its first byte is noise.
 * Returns 1 when out or lens cannot take another frame of the maximum size, 0 when buf is parsed as
 * far as it goes, SB_E_LAYOUT for an unknown kind (the buffer is left as it was). */
static int parse_buffer(sb_deframer *d, int line_idle, uint8_t *out, size_t out_cap, size_t *out_used,
                        uint16_t *lens, size_t max_frames, size_t *nframes)
{
    const size_t max_frame = sb_deframer_max_frame(d);
    size_t pos = 0;
    int full = 0;

    while (pos < d->len) {
        size_t flen = 0;
        enum parse_result r;
        if (*nframes >= max_frames || out_cap - *out_used < max_frame) {
            full = 1;
            break;
        }
        r = parse(d, d->buf + pos, d->len - pos, &flen);
        if (r == PARSE_BAD_KIND)
            return SB_E_LAYOUT;
        if (r == PARSE_NEED_MORE) {
            if (!line_idle)
                break;
            r = PARSE_BAD_HEADER;
        }
        if (r == PARSE_FRAME) {
            memcpy(out + *out_used, d->buf + pos, flen);
            *out_used += flen;
            lens[(*nframes)++] = (uint16_t)flen;
            d->frames++;
            d->synced = 1;
            pos += flen;
            continue;
        }
        if (r == PARSE_BAD_CRC && d->synced)
            d->crc_errors++;
        d->synced = 0;
        d->discarded_bytes++;
        pos++;
    }
    if (pos) {
        memmove(d->buf, d->buf + pos, d->len - pos);
        d->len -= pos;
    }
    return full;
}

/* Checks shared by feed and idle: a valid state, and output that can take at least one frame of
 * the maximum size (less could never make progress). Caps max_frames so the count fits an int. */
static int check_output(const sb_deframer *d, const uint8_t *out, size_t out_cap, const uint16_t *lens,
                        size_t *max_frames)
{
    int status = check_state(d);

    if (status != SB_OK)
        return status;
    if (!out || !lens || out_cap < sb_deframer_max_frame(d) || *max_frames == 0)
        return SB_E_ARG;
    if (*max_frames > INT_MAX)
        *max_frames = INT_MAX;
    return SB_OK;
}

int sb_deframer_feed(sb_deframer *d, const char *data, size_t len, size_t *consumed,
                     uint8_t *out, size_t out_cap, uint16_t *lens, size_t max_frames)
{
    size_t taken = 0, nframes = 0, out_used = 0;
    int full;

    if (!consumed)
        return SB_E_ARG;
    *consumed = 0;
    full = check_output(d, out, out_cap, lens, &max_frames);
    if (full != SB_OK)
        return full;
    if (len && !data)
        return SB_E_ARG;
    /* Runs at least once, so an empty feed still returns frames a full output left behind. The
     * buffer holds more than one maximum frame, so a full buffer always parses something. */
    do {
        size_t take = len - taken, room = SB_DEFRAME_CAPACITY - d->len;
        if (take > room)
            take = room;
        if (take) {  /* data may be NULL when len is 0, and memcpy from NULL is undefined even for 0 */
            memcpy(d->buf + d->len, data + taken, take);
            d->len += take;
            taken += take;
        }
        full = parse_buffer(d, 0, out, out_cap, &out_used, lens, max_frames, &nframes);
        if (full < 0) {
            *consumed = 0;
            return full;
        }
    } while (!full && taken < len);
    *consumed = taken;
    return (int)nframes;
}

int sb_deframer_idle(sb_deframer *d, uint8_t *out, size_t out_cap, uint16_t *lens, size_t max_frames)
{
    size_t out_used = 0, nframes = 0;
    int status = check_output(d, out, out_cap, lens, &max_frames);

    if (status != SB_OK)
        return status;
    status = parse_buffer(d, 1, out, out_cap, &out_used, lens, max_frames, &nframes);
    return status < 0 ? status : (int)nframes;
}
