/* Private to csrc/: the standard headers the public header assumes, then the public header. */
#ifndef SB_INTERNAL_H
#define SB_INTERNAL_H
#include <stddef.h>
#include <stdint.h>
#include "servobus_core.h"
#endif
