"""Perception: the simulated overhead camera, the Hough-circle ball detector, and the
ball pose sensor (true pose + noise, low-pass filtered) used when the camera is off.

May import the generic core and models/."""
