"""Recipes: functions that wire systems into Drake Diagrams from a loaded scenario.

May import systems/, models/ and scenarios/; never tools/."""
