/* CRC-16/MODBUS and CRC-32/ISO-HDLC, table-driven, slice-by-8.
 * Both are reflected CRCs: eight input bytes are folded through eight tables per step, so the loop
 * carries one dependency per 8 bytes instead of one per byte. Tables: crc_tables.h (generated). */
#include <string.h>

#include "sb_internal.h"
#include "crc_tables.h"

uint16_t sb_crc16_modbus_raw(const uint8_t *p, size_t len, uint16_t crc)
{
    const uint16_t (*t)[256] = crc16_modbus_table;
    uint32_t c = crc;

    while (len >= 8) {
        c ^= (uint32_t)p[0] | ((uint32_t)p[1] << 8);
        c = t[7][c & 0xFF] ^ t[6][c >> 8] ^ t[5][p[2]] ^ t[4][p[3]] ^
            t[3][p[4]] ^ t[2][p[5]] ^ t[1][p[6]] ^ t[0][p[7]];
        p += 8;
        len -= 8;
    }
    while (len--)
        c = (c >> 8) ^ t[0][(c ^ *p++) & 0xFF];
    return (uint16_t)c;
}

uint32_t sb_crc32_ieee_raw(const uint8_t *p, size_t len, uint32_t crc)
{
    const uint32_t (*t)[256] = crc32_ieee_table;
    uint32_t c = ~crc;

    while (len >= 8) {
        uint32_t lo;
        memcpy(&lo, p, 4);  /* unaligned-safe; compiles to one load */
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__
        lo = __builtin_bswap32(lo);
#endif
        c ^= lo;
        c = t[7][c & 0xFF] ^ t[6][(c >> 8) & 0xFF] ^ t[5][(c >> 16) & 0xFF] ^ t[4][c >> 24] ^
            t[3][p[4]] ^ t[2][p[5]] ^ t[1][p[6]] ^ t[0][p[7]];
        p += 8;
        len -= 8;
    }
    while (len--)
        c = (c >> 8) ^ t[0][(c ^ *p++) & 0xFF];
    return ~c;
}

/* The public entry points: the one check the loops above cannot make, then the loop. */
int32_t sb_crc16_modbus(const char *data, size_t len, uint16_t crc)
{
    if (len && !data)
        return SB_E_ARG;
    return sb_crc16_modbus_raw((const uint8_t *)data, len, crc);
}

int64_t sb_crc32_ieee(const char *data, size_t len, uint32_t crc)
{
    if (len && !data)
        return SB_E_ARG;
    return sb_crc32_ieee_raw((const uint8_t *)data, len, crc);
}
