"""Paper-figure studies: r_comp against standard residual learning, and the gradient
map of the violation loss (the paper's Fig. 3).

May import tools/ shared modules, diagrams/, systems/, models/, scenarios/."""
