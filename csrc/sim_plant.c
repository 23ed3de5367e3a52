/* Placeholder until the plant lands: every call is refused or does nothing. */
#include "sb_internal.h"

int sb_plant_init(sb_plant *pl, const sb_plant_params *params, double now_s, double max_step_s)
{
    (void)pl; (void)params; (void)now_s; (void)max_step_s;
    return SB_E_ARG;
}
void sb_plant_advance(sb_plant *pl, double now_s) { (void)pl; (void)now_s; }
void sb_plant_set_control(sb_plant *pl, const sb_control *control) { (void)pl; (void)control; }
void sb_plant_set_acceleration(sb_plant *pl, double a) { (void)pl; (void)a; }
void sb_plant_set_external_torque(sb_plant *pl, double t) { (void)pl; (void)t; }
void sb_plant_set_state(sb_plant *pl, const sb_plant_state *s) { (void)pl; (void)s; }
void sb_plants_advance(sb_plant *plants, size_t n, double now_s) { (void)plants; (void)n; (void)now_s; }
