/* ---- simulator: the lk family's C path (sim_lk.c) ----
 * Its state struct lives in sb_simmotor.state; its Python glue is servobus/protocols/lk/sim/. */
typedef struct {
    int placeholder;  /* replaced by the family's state */
} sb_lk_state;
