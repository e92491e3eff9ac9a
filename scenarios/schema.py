"""Typed scenario schemas, loaded with Drake's `yaml_load_typed`.

A scenario file names its `task` (`cartpole`, `ball_rolling` or `rigid_object`;
required, in the file or one it includes); the task picks the schema. Scenarios may `include:` another file (path relative to the
including file) and override any of its keys; `--set key.path=value` on the
command line overrides last. All values are validated before anything is
built: an unknown key, a wrong type or an out-of-range value raises
`ScenarioError` with one line naming the key.
"""

import dataclasses as dc
import math
import typing
from pathlib import Path
from typing import List

import yaml
from pydrake.common.yaml import yaml_load_typed

from adaptive_c3.scenarios import (ball_rolling_schema, cartpole_schema,  # noqa: F401 (they
                                    rigid_object_schema)                 # register their tasks)
from adaptive_c3.scenarios.common import TASKS, ScenarioError

SCENARIO_DIR = Path(__file__).resolve().parent


# ---------------------------------------------------------------- loading
def _deep_merge(base: dict, override: dict) -> dict:
    out = dict(base)
    for key, value in override.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = _deep_merge(out[key], value)
        else:
            out[key] = value
    return out


def _read_yaml(path: Path, seen=()) -> dict:
    if not path.is_file():
        raise ScenarioError(f"scenario file not found: {path}")
    try:
        data = yaml.safe_load(path.read_text()) or {}
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f" line {mark.line + 1}" if mark else ""
        raise ScenarioError(f"{path}:{where} is not valid YAML ({getattr(e, 'problem', e)})")
    if not isinstance(data, dict):
        raise ScenarioError(f"{path}: a scenario must be a mapping of keys to values")
    include = data.pop("include", None)
    if include is not None:
        inc = (path.parent / str(include)).resolve()
        if inc in seen:
            raise ScenarioError(f"{path}: include cycle through {inc}")
        data = _deep_merge(_read_yaml(inc, seen + (inc,)), data)
    return data


def parse_override(text: str):
    """'a.b.c=value' -> (['a','b','c'], value parsed as YAML)."""
    if "=" not in text:
        raise ScenarioError(f"--set expects key.path=value, got '{text}'")
    key, value = text.split("=", 1)
    if not key.strip():
        raise ScenarioError(f"--set expects key.path=value, got '{text}'")
    try:
        parsed = yaml.safe_load(value)
    except yaml.YAMLError:
        raise ScenarioError(f"--set {key}: value '{value}' is not valid YAML")
    if isinstance(parsed, str):   # YAML 1.1 reads '2e-4' as text; a number is meant
        try:
            parsed = float(parsed) if parsed.lower() not in ("nan", "inf", "-inf") else parsed
        except ValueError:
            pass
    return key.strip().split("."), parsed


def apply_override(data: dict, path: list[str], value) -> None:
    node = data
    for part in path[:-1]:
        child = node.get(part)
        if child is None:
            child = node[part] = {}
        if not isinstance(child, dict):
            raise ScenarioError(f"--set {'.'.join(path)}: '{part}' is not a section")
        node = child
    node[path[-1]] = value


def _check_types(schema, data, where: str) -> None:
    """Walk the raw YAML against the dataclass schema and name the first bad key."""
    if not isinstance(data, dict):
        raise ScenarioError(f"{where or 'scenario'}: expected a mapping, got {data!r}")
    fields = {f.name: f for f in dc.fields(schema)}
    hints = typing.get_type_hints(schema)
    for key, value in data.items():
        path = f"{where}.{key}" if where else str(key)
        if key not in fields:
            raise ScenarioError(f"unknown key '{path}' (allowed: {', '.join(fields)})")
        _check_value(hints[key], value, path)


def _check_value(hint, value, path: str) -> None:
    origin = typing.get_origin(hint)
    args = typing.get_args(hint)
    if origin is typing.Union and type(None) in args:
        if value is None:
            return
        hint = next(a for a in args if a is not type(None))
        origin, args = typing.get_origin(hint), typing.get_args(hint)
    if dc.is_dataclass(hint):
        _check_types(hint, value, path)
    elif origin in (list, List):
        if not isinstance(value, list):
            raise ScenarioError(f"{path}: expected a list, got {value!r}")
        for i, item in enumerate(value):
            _check_value(args[0], item, f"{path}[{i}]")
    elif hint is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ScenarioError(f"{path}: expected a number, got {value!r}")
        if math.isnan(value):
            raise ScenarioError(f"{path}: NaN is not allowed")
    elif hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ScenarioError(f"{path}: expected an integer, got {value!r}")
    elif hint is bool:
        if not isinstance(value, bool):
            raise ScenarioError(f"{path}: expected true or false, got {value!r}")
    elif hint is str:
        if not isinstance(value, str):
            raise ScenarioError(f"{path}: expected a string, got {value!r}")


def load_scenario(path, overrides: list[str] = ()):
    """Load, include, override, type-check and validate a scenario file.

    Returns (scenario dataclass, merged YAML text)."""
    path = Path(path)
    data = _read_yaml(path.resolve())
    for text in overrides:
        key, value = parse_override(text)
        apply_override(data, key, value)
    if not data:
        raise ScenarioError(f"{path}: the scenario is empty (it needs at least 'task:', one of "
                            f"{', '.join(sorted(TASKS))})")
    if "task" not in data:
        raise ScenarioError(f"{path}: no 'task:' (one of {', '.join(sorted(TASKS))}), "
                            "in the file or a file it includes")
    task = data["task"]
    if task not in TASKS:
        raise ScenarioError(f"unknown task '{task}' (known: {', '.join(sorted(TASKS))})")
    schema, validate = TASKS[task]
    _check_types(schema, data, "")
    text = yaml.safe_dump(data, sort_keys=False)
    try:
        scenario = yaml_load_typed(schema=schema, data=text)
    except (RuntimeError, ValueError) as e:  # _check_types should catch these first
        raise ScenarioError(f"{path.name}: {str(e).splitlines()[0]}")
    validate(scenario)
    return scenario, text


def shipped_scenarios() -> list[str]:
    return sorted(p.name for p in SCENARIO_DIR.glob("*.yaml"))
