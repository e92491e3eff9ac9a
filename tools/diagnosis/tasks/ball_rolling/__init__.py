"""Ball rolling: the time-varying Anitescu LCS of EE and ball (effects_ball), the push
gait of its recordings with the changes a diagnosis proposes (ball_excitation), and the
`--model drake` world: Drake's SAP plant of EE sphere, ball and table (ball_plant), the
forces Drake lacks (ball_forces) and the backend that replays windows through it
(drake_ball, drake_ball_rollout)."""
