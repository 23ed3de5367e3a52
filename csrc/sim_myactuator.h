/* ---- simulator: the myactuator family's C path (sim_myactuator.c) ----
 * Its state struct lives in sb_simmotor.state; its Python glue is servobus/protocols/myactuator/sim/. */
typedef struct {
    int placeholder;  /* replaced by the family's state */
} sb_ma_state;
