"""Ball rolling: the time-varying Anitescu LCS of EE and ball (effects_ball) and the push
gait of its recordings, with the changes a diagnosis proposes (ball_excitation)."""
