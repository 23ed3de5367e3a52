/* CAN / CAN FD frame timing: the bits a data frame occupies, counted as src/servobus/timing.py does
 * (its pure-Python bodies live on as the oracle in tests/reference/timing.py).
 *
 * One pass over the frame's bit stream in transmission order, nothing stored: a small state follows
 * the stuffing run (ISO 11898-1: a complementary bit after five equal bits, stuff bits counting
 * towards the next run) and, for classic frames, the CRC-15 register over SOF .. data. The header
 * fields go bit by bit; data bytes go through byte tables (sim_timing_tables.h, generated), since the
 * engine times every frame it carries. */
#include <math.h>

#include "sb_internal.h"
#include "sim_timing_tables.h"

#define INTERFRAME_BITS 3                       /* intermission */
#define TRAILER_BITS (1 + 2 + 7 + INTERFRAME_BITS) /* CRC delimiter, ACK slot + delimiter, EOF, intermission */
#define CAN_CRC15_POLY 0x4599u
#define STD_ID_MAX 0x7FFu
#define EXT_ID_MAX 0x1FFFFFFFu

typedef struct {
    int bits;       /* bits of the stream so far (stuff bits not included) */
    int stuff;      /* stuff bits a transmitter inserted so far */
    unsigned run;   /* run state: bit * 4 + length - 1, length 1..4 (gen_timing_tables.py) */
    uint32_t crc;   /* CRC-15 register (classic frames; harmless to run for FD) */
} bitstream;

/* The stream after its SOF: a dominant bit, a run of one, and a CRC register still 0. */
static void start(bitstream *s)
{
    s->bits = 1;
    s->stuff = 0;
    s->run = 0;
    s->crc = 0;
}

static void push_bit(bitstream *s, unsigned bit)
{
    unsigned feedback = bit ^ ((s->crc >> 14) & 1u);
    s->crc = (s->crc << 1) & 0x7FFFu;
    if (feedback)
        s->crc ^= CAN_CRC15_POLY;
    s->bits++;
    if (bit != s->run >> 2) {
        s->run = bit * 4;             /* a new run of one */
    } else if ((s->run & 3) == 3) {   /* the fifth equal bit: stuffed */
        s->stuff++;
        s->run = (1u - bit) * 4;      /* the complementary stuff bit starts the next run */
    } else {
        s->run++;
    }
}

/* 8 bits through the tables: the same as eight push_bit() calls. */
static void push_byte(bitstream *s, unsigned byte)
{
    unsigned step = can_stuff_table[s->run][byte];
    s->run = step & 7u;
    s->stuff += (int)(step >> 3);
    s->crc = ((s->crc << 8) ^ can_crc15_table[((s->crc >> 7) ^ byte) & 0xFFu]) & 0x7FFFu;
    s->bits += 8;
}

/* `width` (<= 64) bits of `value`, most significant first. */
static void push_bits(bitstream *s, uint64_t value, int width)
{
    while (width >= 8) {
        width -= 8;
        push_byte(s, (unsigned)(value >> width) & 0xFFu);
    }
    for (int i = width - 1; i >= 0; i--)
        push_bit(s, (unsigned)(value >> i) & 1u);
}

static void push_data(bitstream *s, const uint8_t *data, size_t len)
{
    for (size_t i = 0; i < len; i++)
        push_byte(s, data[i]);
}

/* The bits after SOF up to RTR/RRS and IDE (standard) or up to RTR/RRS (extended), as
 * timing._arbitration_and_control has them; *width gets their number. */
static uint64_t arbitration(uint32_t id, int extended, int *width)
{
    if (extended) {
        /* base id (11), SRR and IDE (recessive), id extension (18), RTR/RRS (dominant) */
        *width = 11 + 2 + 18 + 1;
        return ((((uint64_t)(id >> 18) << 2) | 3u) << 18 | (id & 0x3FFFFu)) << 1;
    }
    *width = 11 + 2; /* id, RTR/RRS and IDE (dominant) */
    return (uint64_t)id << 2;
}

/* The FD DLC code of a length, or -1 if FD cannot carry it. */
static int fd_dlc(size_t len)
{
    if (len <= 8)
        return (int)len;
    switch (len) {
    case 12: return 9;
    case 16: return 10;
    case 20: return 11;
    case 24: return 12;
    case 32: return 13;
    case 48: return 14;
    case 64: return 15;
    }
    return -1;
}

int sb_can_frame_bits(uint32_t id, int flags, const uint8_t *data, size_t len, int *nominal_bits, int *data_bits)
{
    int extended = (flags & SB_FRAME_EXT) != 0;
    int fd = (flags & SB_FRAME_FD) != 0;
    int brs = (flags & SB_FRAME_BRS) != 0;
    bitstream s;
    int width;

    if (nominal_bits == NULL || data_bits == NULL || (data == NULL && len > 0))
        return SB_E_ARG;
    if ((flags & ~(SB_FRAME_EXT | SB_FRAME_FD | SB_FRAME_BRS)) != 0 || (brs && !fd))
        return SB_E_ARG;
    if (id > (extended ? EXT_ID_MAX : STD_ID_MAX))
        return SB_E_ARG;

    if (!fd) {
        if (len > 8)
            return SB_E_ARG;
        uint64_t head = arbitration(id, extended, &width);
        if (extended) { /* r1 */
            head <<= 1;
            width++;
        }
        head = (head << 5) | len; /* r0 (dominant), DLC */
        start(&s);                /* SOF */
        push_bits(&s, head, width + 5);
        push_data(&s, data, len);
        push_bits(&s, s.crc, 15); /* the CRC-15 of SOF .. data, stuffed like them */
        *nominal_bits = s.bits + s.stuff + TRAILER_BITS;
        *data_bits = 0;
        return SB_OK;
    }

    int dlc = fd_dlc(len);
    if (dlc < 0)
        return SB_E_ARG;
    /* FDF (recessive), res (dominant), BRS */
    uint64_t head = arbitration(id, extended, &width) << 3 | 4u | (unsigned)brs;
    start(&s); /* SOF */
    push_bits(&s, head, width + 3);
    /* The nominal rate runs up to and including BRS; the data rate from ESI to the CRC. */
    int nominal_head = s.bits;
    int stuffed_in_nominal = s.stuff;
    push_bits(&s, (unsigned)dlc, 5); /* ESI (dominant: error-active), DLC */
    push_data(&s, data, len);
    int crc_bits = len <= 16 ? 17 : 21;
    /* Stuff count (4 bits) + CRC, with a fixed stuff bit before the stuff count and after every
     * fourth bit of the two (ISO 11898-1:2015, 10.5). */
    int crc_field = 4 + crc_bits + 1 + (4 + crc_bits) / 4;
    int data_phase = s.bits - nominal_head + (s.stuff - stuffed_in_nominal) + crc_field;
    int nominal = nominal_head + stuffed_in_nominal + TRAILER_BITS;
    if (brs) {
        *nominal_bits = nominal;
        *data_bits = data_phase;
    } else {
        *nominal_bits = nominal + data_phase;
        *data_bits = 0;
    }
    return SB_OK;
}

double sb_can_frame_time(uint32_t id, int flags, const uint8_t *data, size_t len, double bitrate, double data_bitrate)
{
    int nominal_bits, data_bits;

    /* !(x > 0) refuses NaN too; a NaN data rate would make a NaN time. */
    if (!(bitrate > 0) || isnan(data_bitrate))
        return SB_E_ARG;
    int status = sb_can_frame_bits(id, flags, data, len, &nominal_bits, &data_bits);
    if (status != SB_OK)
        return status;
    if (data_bitrate <= 0)
        data_bitrate = bitrate;
    if (!(flags & SB_FRAME_FD))
        return (double)nominal_bits / bitrate;
    /* The same operations in the same order as timing.frame_time_s (bit-identical results). */
    return (double)nominal_bits / bitrate + (double)data_bits / data_bitrate;
}
