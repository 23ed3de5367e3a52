/* CAN / CAN FD frame timing: the bits a data frame occupies, counted as src/servobus/timing.py does
 * (its pure-Python bodies live on as the oracle in tests/reference/timing.py).
 *
 * One pass over the frame's bit stream in transmission order, nothing stored: a small state follows
 * the stuffing run (ISO 11898-1: a complementary bit after five equal bits, stuff bits counting
 * towards the next run) and, for classic frames, the CRC-15 register over SOF .. data. */
#include <math.h>

#include "sb_internal.h"

#define INTERFRAME_BITS 3                       /* intermission */
#define TRAILER_BITS (1 + 2 + 7 + INTERFRAME_BITS) /* CRC delimiter, ACK slot + delimiter, EOF, intermission */
#define CAN_CRC15_POLY 0x4599u
#define STD_ID_MAX 0x7FFu
#define EXT_ID_MAX 0x1FFFFFFFu

typedef struct {
    int bits;       /* bits of the stream so far (stuff bits not included) */
    int stuff;      /* stuff bits a transmitter inserted so far */
    int run_bit;    /* value of the current run (-1 before the first bit) */
    int run_len;
    uint32_t crc;   /* CRC-15 register (classic frames; harmless to run for FD) */
} bitstream;

static void push_bit(bitstream *s, unsigned bit)
{
    unsigned feedback = bit ^ ((s->crc >> 14) & 1u);
    s->crc = (s->crc << 1) & 0x7FFFu;
    if (feedback)
        s->crc ^= CAN_CRC15_POLY;
    s->bits++;
    if ((int)bit == s->run_bit) {
        s->run_len++;
    } else {
        s->run_bit = (int)bit;
        s->run_len = 1;
    }
    if (s->run_len == 5) {
        s->stuff++;
        s->run_bit = 1 - (int)bit; /* the complementary stuff bit starts the next run */
        s->run_len = 1;
    }
}

/* `width` bits of `value`, most significant first. */
static void push_bits(bitstream *s, uint32_t value, int width)
{
    for (int i = width - 1; i >= 0; i--)
        push_bit(s, (value >> i) & 1u);
}

/* SOF .. RTR/RRS and IDE (standard) or SOF .. RTR/RRS (extended), as timing._arbitration_and_control. */
static void push_arbitration(bitstream *s, uint32_t id, int extended)
{
    push_bit(s, 0); /* SOF */
    if (extended) {
        push_bits(s, id >> 18, 11);
        push_bit(s, 1); /* SRR */
        push_bit(s, 1); /* IDE */
        push_bits(s, id & 0x3FFFFu, 18);
        push_bit(s, 0); /* RTR / RRS */
    } else {
        push_bits(s, id, 11);
        push_bit(s, 0); /* RTR / RRS */
        push_bit(s, 0); /* IDE */
    }
}

static void push_data(bitstream *s, const uint8_t *data, size_t len)
{
    for (size_t i = 0; i < len; i++)
        push_bits(s, data[i], 8);
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
    bitstream s = {0, 0, -1, 0, 0};

    if (nominal_bits == NULL || data_bits == NULL || (data == NULL && len > 0))
        return SB_E_ARG;
    if ((flags & ~(SB_FRAME_EXT | SB_FRAME_FD | SB_FRAME_BRS)) != 0 || (brs && !fd))
        return SB_E_ARG;
    if (id > (extended ? EXT_ID_MAX : STD_ID_MAX))
        return SB_E_ARG;

    if (!fd) {
        if (len > 8)
            return SB_E_ARG;
        push_arbitration(&s, id, extended);
        if (extended)
            push_bit(&s, 0); /* r1 */
        push_bit(&s, 0);     /* r0 */
        push_bits(&s, (uint32_t)len, 4);
        push_data(&s, data, len);
        push_bits(&s, s.crc, 15); /* the CRC-15 of SOF .. data, stuffed like them */
        *nominal_bits = s.bits + s.stuff + TRAILER_BITS;
        *data_bits = 0;
        return SB_OK;
    }

    int dlc = fd_dlc(len);
    if (dlc < 0)
        return SB_E_ARG;
    push_arbitration(&s, id, extended);
    push_bit(&s, 1);            /* FDF */
    push_bit(&s, 0);            /* res */
    push_bit(&s, (unsigned)brs);
    /* The nominal rate runs up to and including BRS; the data rate from ESI to the CRC. */
    int nominal_head = s.bits;
    int stuffed_in_nominal = s.stuff;
    push_bit(&s, 0);            /* ESI (error-active) */
    push_bits(&s, (uint32_t)dlc, 4);
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
