/* The lk family's C path: none yet, every frame goes to the Python model. */
#include <math.h>
#include "sb_internal.h"

int sb_lk_receive(sb_simmotor *m, const sb_simframe *in, double now_s, sb_simframe *out, int cap, int *n_out)
{
    (void)m; (void)in; (void)now_s; (void)out; (void)cap;
    *n_out = 0;
    return SB_HOT_COLD;
}

int sb_lk_poll(sb_simmotor *m, double now_s, sb_simframe *out, int cap, int *n_out)
{
    (void)m; (void)now_s; (void)out; (void)cap;
    *n_out = 0;
    return SB_HOT_COLD;
}

double sb_lk_next_deadline(const sb_simmotor *m)
{
    (void)m;
    return INFINITY;
}
