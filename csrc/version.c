/* The package version and ABI the core was compiled for; the Python wrapper refuses a stale build. */
#include "sb_internal.h"

#ifndef SB_CORE_VERSION
#error "SB_CORE_VERSION is set by src/servobus/_build_core.py"
#endif

const char *sb_core_version(void)
{
    return SB_CORE_VERSION;
}

int sb_core_abi(void)
{
    return SB_CORE_ABI;
}
