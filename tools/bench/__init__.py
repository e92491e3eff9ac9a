"""`adaptive-c3 bench`: one module per benchmark (each exposes run_bench(quick) -> rows)
and runner.py, which times them and writes the rows with ratios against baselines.

May import tools/ shared modules, diagrams/, systems/, models/, scenarios/."""
