"""Rigid objects (e.g. tossed cubes): episodes and twins, the initial-state estimate, the
effect libraries of both backends, the diagnosis, its report and the two-backend comparison."""
