/* SLCAN (LAWICEL ASCII) receive lines: what a USB-CAN adapter sends its host, cut at CR, checked,
 * and turned into fixed-size frame records (the rules are in servobus_core.h).
 *
 * One pass over the input, one byte at a time: a byte either ends a line (CR, BEL), is skipped (LF
 * at a line start), is held (at most the longest valid line), or is dropped and counted (the rest
 * of an over-long line). Nothing grows: the state is the fixed line buffer and the counters. Every
 * parse step reads only line[0 .. len). */
#include <limits.h>
#include <string.h>

#include "sb_internal.h"

#define SLCAN_CR 0x0D
#define SLCAN_LF 0x0A
#define SLCAN_BEL 0x07
#define SLCAN_MAX_LINE_PLAIN (SB_SLCAN_MAX_LINE - 4)

enum line_result { LINE_FRAME, LINE_REMOTE, LINE_BAD };

static const uint8_t fd_lengths[16] = {0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64};

/* The value of one hex digit, or -1. */
static int hex_digit(uint8_t c)
{
    if (c >= '0' && c <= '9')
        return c - '0';
    if (c >= 'A' && c <= 'F')
        return c - 'A' + 10;
    if (c >= 'a' && c <= 'f')
        return c - 'a' + 10;
    return -1;
}

/* n hex digits (n <= 8) as a number; 0 when one is not a hex digit (*value untouched then). */
static int hex_number(const uint8_t *b, size_t n, uint32_t *value)
{
    uint32_t v = 0;

    for (size_t i = 0; i < n; i++) {
        int d = hex_digit(b[i]);
        if (d < 0)
            return 0;
        v = (v << 4) | (uint32_t)d;
    }
    *value = v;
    return 1;
}

/* The frame kind a line's first byte names: 1 with the flags and whether it is remote, or 0 for a
 * byte that starts no frame line (checked after the switch, which lists every frame byte). */
static int frame_kind(uint8_t c, uint8_t *flags, int *remote)
{
    *remote = 0;
    switch (c) {
    case 't': *flags = 0; return 1;
    case 'T': *flags = SB_SLCAN_EXTENDED; return 1;
    case 'r': *flags = 0; *remote = 1; return 1;
    case 'R': *flags = SB_SLCAN_EXTENDED; *remote = 1; return 1;
    case 'd': *flags = SB_SLCAN_FD; return 1;
    case 'D': *flags = SB_SLCAN_EXTENDED | SB_SLCAN_FD; return 1;
    case 'b': *flags = SB_SLCAN_FD | SB_SLCAN_BRS; return 1;
    case 'B': *flags = SB_SLCAN_EXTENDED | SB_SLCAN_FD | SB_SLCAN_BRS; return 1;
    }
    return 0;
}

/* A frame line (without its CR) into *f. The caller has checked frame_kind(b[0]). */
static enum line_result parse_frame(const uint8_t *b, size_t n, int timestamps, uint8_t flags, int remote,
                                    sb_slcan_frame *f)
{
    const int extended = (flags & SB_SLCAN_EXTENDED) != 0;
    const size_t id_digits = extended ? 8 : 3;
    const size_t header = 1 + id_digits + 1;
    uint32_t id, dlc, stamp = 0;
    size_t length, expected;

    if (n < header)
        return LINE_BAD;
    if (!hex_number(b + 1, id_digits, &id) || id > (extended ? 0x1FFFFFFFu : 0x7FFu))
        return LINE_BAD;
    if (!hex_number(b + 1 + id_digits, 1, &dlc))
        return LINE_BAD;
    if (flags & SB_SLCAN_FD) {
        length = fd_lengths[dlc];
    } else {
        if (dlc > 8)
            return LINE_BAD;
        length = dlc;
    }
    expected = header + (remote ? 0 : 2 * length) + (timestamps ? 4 : 0);
    if (n != expected)
        return LINE_BAD;
    for (size_t i = 0; i < (remote ? 0 : length); i++) {
        int hi = hex_digit(b[header + 2 * i]), lo = hex_digit(b[header + 2 * i + 1]);
        if (hi < 0 || lo < 0)
            return LINE_BAD;
        f->data[i] = (uint8_t)((hi << 4) | lo);
    }
    if (timestamps && !hex_number(b + n - 4, 4, &stamp))
        return LINE_BAD;
    if (remote)
        return LINE_REMOTE;
    f->id = id;
    f->flags = flags;
    f->len = (uint8_t)length;
    f->timestamp = (uint16_t)stamp;
    return LINE_FRAME;
}

/* The line held in s ended with a CR: classify and count it. Returns 1 when it wrote *f. */
static int end_line(sb_slcan *s, sb_slcan_frame *f)
{
    const size_t n = s->len;
    uint8_t flags = 0;
    int remote = 0;

    s->len = 0;
    if (n == 0) {
        s->oks++;
        return 0;
    }
    if (n == 1 && (s->line[0] == 'z' || s->line[0] == 'Z')) {
        s->acks++;
        return 0;
    }
    if (frame_kind(s->line[0], &flags, &remote)) {
        enum line_result r = parse_frame(s->line, n, s->option & SB_SLCAN_TIMESTAMPS, flags, remote, f);
        switch (r) {
        case LINE_FRAME:
            s->frames++;
            return 1;
        case LINE_REMOTE:
            s->remote++;
            return 0;
        case LINE_BAD:
            break;
        }
    }
    s->malformed++;
    s->discarded_bytes += n + 1;
    return 0;
}

static size_t max_line(int option)
{
    return (option & SB_SLCAN_TIMESTAMPS) ? SB_SLCAN_MAX_LINE : SLCAN_MAX_LINE_PLAIN;
}

/* The state is caller memory (Python can write its fields): check it before trusting len. */
static int check_state(const sb_slcan *s)
{
    if (!s || (s->option & ~SB_SLCAN_TIMESTAMPS) || (s->dropping != 0 && s->dropping != 1))
        return SB_E_ARG;
    return s->len <= max_line(s->option) ? SB_OK : SB_E_ARG;
}

int sb_slcan_init(sb_slcan *s, int option)
{
    if (!s)
        return SB_E_ARG;
    memset(s, 0, sizeof *s);
    if (option & ~SB_SLCAN_TIMESTAMPS) {
        s->option = -1;  /* refused by check_state from now on */
        return SB_E_ARG;
    }
    s->option = option;
    return SB_OK;
}

size_t sb_slcan_max_line(const sb_slcan *s)
{
    return check_state(s) == SB_OK ? max_line(s->option) : 0;
}

int sb_slcan_reset(sb_slcan *s)
{
    int status = check_state(s);

    if (status != SB_OK)
        return status;
    s->discarded_bytes += s->len;
    s->len = 0;
    s->dropping = 0;
    return SB_OK;
}

int sb_slcan_feed(sb_slcan *s, const char *data, size_t len, size_t *consumed, sb_slcan_frame *out,
                  size_t max_frames)
{
    const uint8_t *b = (const uint8_t *)data;
    size_t i, nframes = 0, limit;
    int status;

    if (!consumed)
        return SB_E_ARG;
    *consumed = 0;
    status = check_state(s);
    if (status != SB_OK)
        return status;
    if ((len && !data) || !out || max_frames == 0)
        return SB_E_ARG;
    if (max_frames > INT_MAX)
        max_frames = INT_MAX;
    limit = max_line(s->option);
    for (i = 0; i < len && nframes < max_frames; i++) {
        const uint8_t c = b[i];
        if (c == SLCAN_CR) {
            if (s->dropping) {
                s->dropping = 0;
                s->discarded_bytes++;
            } else if (end_line(s, out + nframes)) {
                nframes++;
            }
        } else if (c == SLCAN_BEL) {
            s->bells++;
            if (s->len) {  /* an unfinished line: the adapter's error cut it off */
                s->malformed++;
                s->discarded_bytes += s->len;
                s->len = 0;
            }
            s->dropping = 0;
        } else if (s->dropping) {
            s->discarded_bytes++;
        } else if (c == SLCAN_LF && s->len == 0) {
            continue;
        } else if (s->len < limit) {
            s->line[s->len++] = c;
        } else {
            s->overlong++;
            s->discarded_bytes += s->len + 1;
            s->len = 0;
            s->dropping = 1;
        }
    }
    *consumed = i;
    return (int)nframes;
}
