"""The LCM side: the bridge to a Franka driver, the simulated driver that speaks only
the robot's LCM messages, the shared channel layout, and `record convert` (LCM log ->
recording).

May import tools/ shared modules, diagrams/, systems/, models/, scenarios/."""
