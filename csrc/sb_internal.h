/* Private to csrc/: the standard headers the public header assumes, then the public header. */
#ifndef SB_INTERNAL_H
#define SB_INTERNAL_H
#include <stddef.h>
#include <stdint.h>
#include "servobus_core.h"
/* The simulator's headers, in the order the cdef reads them (src/servobus/_build_core.py: HEADERS). */
#include "sim_plant.h"
#include "sim_timing.h"
#include "sim_core.h"
#include "sim_myactuator.h"
#include "sim_lk.h"
#include "sim_hollow.h"
#include "sim_net.h"

/* The CRC loops without the public functions' argument checks, for callers inside csrc/ that own
 * their buffers (the de-framers). Same conventions as sb_crc16_modbus / sb_crc32_ieee. */
uint16_t sb_crc16_modbus_raw(const uint8_t *data, size_t len, uint16_t crc);
uint32_t sb_crc32_ieee_raw(const uint8_t *data, size_t len, uint32_t crc);
#endif
