"""The Franka Panda side: the impedance law and controller, the point-EE impedance,
the simulated torque driver pieces, and the watchdog that guards commands.

May import the generic core and models/."""
