/* ---- simulator: CAN / CAN FD frame timing (sim_timing.c) ----
 * Bits a frame occupies on the wire, stuff bits, CRC and intermission included, counted exactly as
 * src/servobus/timing.py does (the reference): classic frames with their real CRC-15 and dynamic
 * stuffing; CAN FD with dynamic stuffing to the end of the data field and the fixed-stuff CRC field. */
#define SB_FRAME_EXT 1   /* 29-bit identifier */
#define SB_FRAME_FD 2    /* CAN FD format */
#define SB_FRAME_BRS 4   /* CAN FD bit-rate switch */

/* *nominal_bits at the nominal rate and *data_bits at the data rate (0 unless FD with BRS).
 * SB_E_ARG (nothing written): data NULL with len > 0, an output NULL, a length the format cannot carry
 * (classic 0..8, FD 0..8/12/16/20/24/32/48/64), an id too wide, unknown flags, BRS without FD. */
int sb_can_frame_bits(uint32_t id, int flags, const uint8_t *data, size_t len, int *nominal_bits, int *data_bits);
/* Seconds on the wire (servobus.timing.frame_time_s); data_bitrate <= 0: the nominal rate. An
 * infinite bitrate gives 0. Negative (SB_E_ARG) on bad input, a bitrate not > 0 or a NaN rate.
 * Bit-identical to the Python formula: bits / bitrate (+ data_bits / data_bitrate for FD). */
double sb_can_frame_time(uint32_t id, int flags, const uint8_t *data, size_t len, double bitrate, double data_bitrate);
