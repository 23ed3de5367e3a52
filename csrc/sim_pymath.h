/* Python's float semantics where the simulator's C must round and compare exactly as the Python
 * device models do (the reference): private to csrc/, not part of the cdef. */
#ifndef SB_SIM_PYMATH_H
#define SB_SIM_PYMATH_H
#include <math.h>

/* min(a, b) / max(a, b): the first of equals, NaN handled as Python's comparisons do. */
static inline double py_min(double a, double b) { return b < a ? b : a; }
static inline double py_max(double a, double b) { return b > a ? b : a; }

/* x % y for floats (CPython's float_rem): the result takes the sign of y. */
static inline double py_mod(double x, double y)
{
    double mod = fmod(x, y);
    if (mod != 0.0) {
        if ((y < 0) != (mod < 0))
            mod += y;
    } else {
        mod = copysign(0.0, y);
    }
    return mod;
}
#endif
