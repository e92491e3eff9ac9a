"""Typed scenario schemas, loaded with Drake's `yaml_load_typed`.

A scenario file names its `task` (`cartpole` or `ball_rolling`); the task picks
the schema. Scenarios may `include:` another file (path relative to the
including file) and override any of its keys; `--set key.path=value` on the
command line overrides last. All values are validated before anything is
built: an unknown key, a wrong type or an out-of-range value raises
`ScenarioError` with one line naming the key.
"""

import dataclasses as dc
import math
import typing
from pathlib import Path
from typing import List, Optional

import yaml
from pydrake.common.yaml import yaml_load_typed

SCENARIO_DIR = Path(__file__).resolve().parent


class ScenarioError(ValueError):
    """A scenario could not be loaded; the message is one line for the user."""


# ---------------------------------------------------------------- sections
@dc.dataclass
class C3Config:
    """C3 MPC settings. Diagonals are over z = [x, lambda, u] (g_diag, u_diag),
    x (q_diag) and u (r_diag); empty lists mean the task's reference values."""
    horizon: int = 10
    admm_iter: int = 10
    rate_hz: float = 80.0          # replanning rate, Hz
    projection: str = "c3plus"     # c3plus | qp | exact
    qp_backend: str = "kkt"        # kkt | osqp
    rho_scale: float = 2.0
    warm_start: bool = True
    q_diag: List[float] = dc.field(default_factory=list)
    r_diag: List[float] = dc.field(default_factory=list)
    g_diag: List[float] = dc.field(default_factory=list)
    u_diag: List[float] = dc.field(default_factory=list)


@dc.dataclass
class LearnerConfig:
    """Online residual learner (paper Algorithm 1)."""
    enabled: bool = False
    learning_rate: float = 5e-3    # Adam step size xi
    epsilon: float = 1e-3          # loss parameter, > 0
    gamma: float = 1e-2            # 0 < gamma < sigma_min(F + F')
    batch_size: int = 10           # n_b
    rate_hz: float = 20.0          # update rate, Hz
    max_step: float = 0.01         # bound on one update of any entry
    lr_decay_steps: float = 0.0    # optional: step size xi / (1 + t / this), t = Adam steps; 0 = off
    qd_diag: List[float] = dc.field(default_factory=list)  # Q_d diagonal (empty = identity)


@dc.dataclass
class Disturbance:
    """A velocity kick added to the state at time `at_s` (units of the state)."""
    at_s: float = 0.0
    delta_state: List[float] = dc.field(default_factory=list)


@dc.dataclass
class CartpoleModel:
    wall_stiffness: float = 50.0        # ks, N/m
    wall_distance: float = 0.35         # true wall offsets, m
    wall_offset_error: List[float] = dc.field(default_factory=lambda: [0.0, 0.0])  # delta_phi, m


@dc.dataclass
class CartpoleScenario:
    task: str = "cartpole"
    name: str = "cartpole"
    controller: str = "c3"              # c3 | lqr
    model: CartpoleModel = dc.field(default_factory=CartpoleModel)
    c3: C3Config = dc.field(default_factory=C3Config)
    learner: LearnerConfig = dc.field(default_factory=LearnerConfig)
    initial_state: List[float] = dc.field(default_factory=lambda: [0.1, -0.3, 0.0, 0.0])
    disturbances: List[Disturbance] = dc.field(default_factory=list)
    measurement_noise: List[float] = dc.field(default_factory=list)  # std per state
    sim_duration_s: float = 8.0
    stabilise_tolerance: float = 0.05   # |x|_inf below this counts as stabilised
    seed: int = 0


TASKS = {}   # task name -> (schema dataclass, validator function)


def register_task(name: str, schema, validator) -> None:
    """Let a task add its schema and its range checks."""
    TASKS[name] = (schema, validator)


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


def _register_builtin_tasks():
    import adaptive_c3.scenarios.ball_rolling_schema  # noqa: F401  (registers itself)


def load_scenario(path, overrides: list[str] = ()):
    """Load, include, override, type-check and validate a scenario file.

    Returns (scenario dataclass, merged YAML text)."""
    _register_builtin_tasks()
    path = Path(path)
    data = _read_yaml(path.resolve())
    for text in overrides:
        key, value = parse_override(text)
        apply_override(data, key, value)
    task = data.get("task", "cartpole")
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


def _validate_common(s) -> None:
    """Range checks shared by all tasks."""
    def need(cond, msg):
        if not cond:
            raise ScenarioError(msg)
    need(s.sim_duration_s > 0 and math.isfinite(s.sim_duration_s),
         f"sim_duration_s must be > 0, got {s.sim_duration_s}")
    c3 = s.c3
    need(c3.horizon >= 1, f"c3.horizon must be >= 1, got {c3.horizon}")
    need(c3.admm_iter >= 1, f"c3.admm_iter must be >= 1, got {c3.admm_iter}")
    need(c3.rate_hz > 0 and math.isfinite(c3.rate_hz), f"c3.rate_hz must be > 0, got {c3.rate_hz}")
    need(c3.projection in ("c3plus", "qp", "exact"),
         f"c3.projection must be c3plus, qp or exact, got '{c3.projection}'")
    need(c3.qp_backend in ("kkt", "osqp"), f"c3.qp_backend must be kkt or osqp, got '{c3.qp_backend}'")
    need(c3.rho_scale >= 1 and math.isfinite(c3.rho_scale), f"c3.rho_scale must be >= 1, got {c3.rho_scale}")
    for key in ("q_diag", "r_diag", "g_diag", "u_diag"):
        vals = getattr(c3, key)
        need(all(math.isfinite(v) and v >= 0 for v in vals),
             f"c3.{key} entries must be finite and >= 0, got {vals}")
    ln = s.learner
    need(ln.epsilon > 0 and math.isfinite(ln.epsilon), f"learner.epsilon must be > 0, got {ln.epsilon}")
    need(ln.gamma > 0 and math.isfinite(ln.gamma), f"learner.gamma must be > 0, got {ln.gamma}")
    need(ln.learning_rate > 0 and math.isfinite(ln.learning_rate),
         f"learner.learning_rate must be a finite number > 0, got {ln.learning_rate}")
    need(ln.batch_size >= 1, f"learner.batch_size must be >= 1, got {ln.batch_size}")
    need(ln.rate_hz > 0 and math.isfinite(ln.rate_hz), f"learner.rate_hz must be > 0, got {ln.rate_hz}")
    need(ln.max_step > 0 and math.isfinite(ln.max_step), f"learner.max_step must be > 0, got {ln.max_step}")
    need(all(math.isfinite(v) for v in s.initial_state), "initial_state must be finite")


def validate_cartpole(s: CartpoleScenario) -> None:
    _validate_common(s)
    if s.controller not in ("c3", "lqr"):
        raise ScenarioError(f"controller must be c3 or lqr, got '{s.controller}'")
    if len(s.initial_state) != 4:
        raise ScenarioError(f"initial_state must have 4 entries for the cart-pole, got {len(s.initial_state)}")
    m = s.model
    if not (m.wall_stiffness > 0 and math.isfinite(m.wall_stiffness)):
        raise ScenarioError(f"model.wall_stiffness must be > 0, got {m.wall_stiffness}")
    if not (m.wall_distance > 0 and math.isfinite(m.wall_distance)):
        raise ScenarioError(f"model.wall_distance must be > 0, got {m.wall_distance}")
    if len(m.wall_offset_error) != 2:
        raise ScenarioError("model.wall_offset_error must have 2 entries (left, right wall)")
    for d in s.disturbances:
        if len(d.delta_state) != 4:
            raise ScenarioError("disturbances[].delta_state must have 4 entries")
    if s.measurement_noise and len(s.measurement_noise) != 4:
        raise ScenarioError("measurement_noise must be empty or have 4 entries")


register_task("cartpole", CartpoleScenario, validate_cartpole)


def shipped_scenarios() -> list[str]:
    return sorted(p.name for p in SCENARIO_DIR.glob("*.yaml"))
