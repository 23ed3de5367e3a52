/* ---- simulator: the hollow family's C path (sim_hollow.c) ----
 * Its state struct lives in sb_simmotor.state; its Python glue is servobus/protocols/hollow/sim/. */
typedef struct {
    int placeholder;  /* replaced by the family's state */
} sb_hollow_state;
