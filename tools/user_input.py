"""What every command shares about user input: the error a user can fix, and how a
scenario argument (a path, or the name of a shipped scenario) becomes a file.

Imported by cli.py and by the commands it delegates to (never the other way round)."""
from __future__ import annotations

from pathlib import Path


class UserError(Exception):
    """Raised for mistakes the user can fix; printed as one line."""


def resolve_scenario_path(name: str) -> Path:
    """A path as given, or the name of a shipped scenario."""
    from adaptive_c3.scenarios.schema import SCENARIO_DIR
    path = Path(name)
    if path.is_file():
        return path
    for candidate in (SCENARIO_DIR / name, SCENARIO_DIR / f"{name}.yaml", SCENARIO_DIR / path.name):
        if candidate.is_file():
            return candidate
    raise UserError(f"scenario file not found: {name}")
