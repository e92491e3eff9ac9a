"""C3, the ADMM contact-implicit MPC: the solver, its QP step, the complementarity
projections, and the LeafSystem that wraps the solver.

Generic core: imports systems.contact and libraries only."""
