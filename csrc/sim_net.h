/* ---- simulator: the engine, one simulated CAN network (sim_net.c) ---- */
