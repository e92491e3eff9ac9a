"""One sub-wing per task: what a task's model, effects, excitation and report add to the
engine. A task imports the engine, the backends and itself, never another task or the
harness."""
