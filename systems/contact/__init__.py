"""Contact models: the LCS type, LCP solvers, the LCS as a plant, and Anitescu's
linearisation of a MultibodyPlant (numpy core + its LeafSystem).

Generic core: imports numpy, scipy and pydrake only, never models/ or task systems."""
