"""What every task's scenario shares: the error type, the C3 and learner sections, the
range checks common to all tasks, and the registry the task schemas add themselves to.

Imports nothing of the project (the task schemas and the loader import this)."""
import dataclasses as dc
import math
from typing import List


class ScenarioError(ValueError):
    """A scenario could not be loaded; the message is one line for the user."""



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
    predict_state: bool = False    # plan from the state predicted at the plan's effect time
    predict_latency_s: float = -1.0  # that lead, s; < 0: measured solve time + transport
    warm_start_shift: str = "knot"  # knot: the last plan moved one LCS step | elapsed: moved
                                    # by the time between the plans' start states
    c3plus_reference: bool = False # C3+ as DAIRLab/c3's C3Plus: G on lam, eta only, final
                                   # QP on delta (systems/c3/solver.py)
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


TASKS = {}   # task name -> (schema dataclass, validator function)


def register_task(name: str, schema, validator) -> None:
    """Let a task add its schema and its range checks."""
    TASKS[name] = (schema, validator)


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
    need(c3.warm_start_shift in ("knot", "elapsed"),
         f"c3.warm_start_shift must be knot or elapsed, got '{c3.warm_start_shift}'")
    need(math.isfinite(c3.predict_latency_s) and c3.predict_latency_s < 1.0,
         f"c3.predict_latency_s must be < 1 s (< 0: measured), got {c3.predict_latency_s}")
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
