"""The `adaptive-c3` command line and what it runs: runners and sweeps here, and the
wings diagnosis/, bench/, hardware/ and studies/.

May import everything below it (diagrams/, systems/, models/, scenarios/)."""
