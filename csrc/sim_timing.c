/* Placeholder until frame timing lands. */
#include "sb_internal.h"

int sb_can_frame_bits(uint32_t id, int flags, const uint8_t *data, size_t len, int *nominal_bits, int *data_bits)
{
    (void)id; (void)flags; (void)data; (void)len; (void)nominal_bits; (void)data_bits;
    return SB_E_ARG;
}
double sb_can_frame_time(uint32_t id, int flags, const uint8_t *data, size_t len, double bitrate, double data_bitrate)
{
    (void)id; (void)flags; (void)data; (void)len; (void)bitrate; (void)data_bitrate;
    return SB_E_ARG;
}
