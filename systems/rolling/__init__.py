"""The ball/fruit-rolling task: the gait (roll and return phases), the planner that
runs C3 on the rolling LCS, and the state estimator.

May import the generic core, perception/, franka/ and models/."""
