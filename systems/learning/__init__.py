"""Online residual learning: the violation-based implicit loss and its gradient, and
the residual learner (Adam on r_comp) as a LeafSystem.

Generic core: imports systems.contact and libraries only."""
