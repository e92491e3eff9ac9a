"""Schema of the ball-rolling scenarios (Franka Panda rolls a ball, or a fruit, along a circle).

Registered with the scenario loader under `task: ball_rolling`.
"""
import dataclasses as dc
import math
from typing import List

from adaptive_c3.scenarios.common import (C3Config, LearnerConfig, ScenarioError,
                                          _validate_common, register_task)


@dc.dataclass
class RollingModel:
    """The controller's prior (a sphere) and how the true object differs from it."""
    object: str = "ball"             # ball | orange | lime (the true object)
    ball_radius: float = 0.0315      # the controller's model radius, m
    radius_error: float = 0.005      # model radius - true radius, m (paper: 5 mm)
    ball_mass: float = 0.132         # kg, the controller model's ball
    true_mass_scale: float = 1.0     # the simulated truth's ball mass / ball_mass (the
                                     # ball's inertia scales with it)
    ee_radius: float = 0.0195        # end-effector tip sphere, m
    ee_mass: float = 1.0             # kg, the controller model's EE (about the arm's
                                     # apparent mass at the tip; the reference uses 0.01)
    friction: float = 1.0            # mu of the model's contacts
    true_friction: float = 1.0       # mu of the simulated truth (every geometry)
    true_ee_friction: float = -1.0   # mu of the truth's EE-ball pair alone (< 0: what
                                     # Drake combines from the EE's 1 and true_friction)
    friction_edges: int = 4          # n_e per contact
    eps_c: float = 0.01              # Anitescu regulariser
    planning_dt: float = 0.1         # LCS step, s
    learner_dt: float = 0.025         # the learner's LCS step, s (0: planning_dt). Shorter
                                     # steps shrink Anitescu's sliding artefact (a sliding
                                     # contact separates by mu |v_slip| dt in the model),
                                     # which the learner would read as a gap offset
    open_pair_gate: bool = False     # true: an open pair out of one step's reach gets no
                                     # friction rows in the LCS (Anitescu's relaxed cone
                                     # otherwise lets an open pair push or brake: issue 30;
                                     # AnitescuLinearizer.open_pair_tol = OPEN_PAIR_TOL)
    learner_input: str = "motion"    # applied: the impedance's tip force + the model EE's
                                     # weight; motion: the force that reproduces the EE's
                                     # measured motion on the model EE


@dc.dataclass
class TargetPath:
    """The ball's target: a point on a circle that leads the ball by lead_deg."""
    center: List[float] = dc.field(default_factory=lambda: [0.55, 0.0])  # m, robot base frame
    radius: float = 0.1              # m
    lead_deg: float = 20.0           # deg ahead of the ball along the circle


@dc.dataclass
class Gait:
    """Roll phase (C3 plans with contact) then return phase (lift, move behind, lower).
    Heights are m above the model's EE-on-top-of-ball height (2 R_model + r_ee), which
    the learned EE-ball gap offset lowers (systems/rolling/gait.py)."""
    roll_s: float = 0.6              # fruits need 1.0 (fruit_sweep.yaml): a shorter push
                                     # leaves them short of the ridge to their next resting
                                     # facet and they roll back; a ball under that fruit gait
                                     # with the camera on coasts off the table after 3.7 turns
    return_s: float = 0.5
    settle_s: float = 0.5            # initial move to the start pose before rolling
    back_distance: float = 0.02      # m behind the ball centre in the return phase
    roll_height: float = -0.005      # roll-phase EE target
    lift_height: float = 0.03        # lift and side-step height
    place_height: float = -0.005     # where the EE is put down (negative: pressing)
    max_ee_speed: float = 0.12       # clamp on the commanded EE speed in the roll phase,
                                     # m/s (reference: 1; faster pushes make the ball
                                     # coast off the circle)
    return_ee_weight: float = 1.0e4  # C3 weight on EE position in the return phase
    min_height: float = -0.005       # floor of the commanded EE height
    roll_lead: float = 1.0           # roll-phase EE target: 0 over the ball, 1 over its target
    return_mode: str = "waypoint"    # c3 | waypoint (straight lines to the gait's targets)
    return_speed: float = 0.5        # m/s, EE speed in waypoint return phases
    place_xy_tolerance: float = 0.0  # m; > 0: lower the EE in the place phase only once
                                     # the measured EE is this close (x-y) to its place point
    use_learned_gap: bool = True     # the learned EE-ball gap offset lowers the gait's
                                     # heights (and the "gap" floor); false: gap 0 there
    floor: str = "gap"               # gap: the commanded EE height >= touching height -
                                     # gap + min_height (moves with the learned gap);
                                     # table: >= ee_radius + table_clearance above the
                                     # table (independent of the learner and the model ball)
    table_clearance: float = 0.005   # m, the "table" floor's clearance of the EE sphere


@dc.dataclass
class RollingLearnerConfig(LearnerConfig):
    """The learner, plus where the ball-rolling task uses its residual."""
    tie_residual: str = "pairs"      # pairs: one value per contact pair (the EE-ball rows
                                     # share one, the ball-table rows another); none: every
                                     # row free, as the paper's r_comp
    residual_in_lcs: bool = True     # C3 plans with the LCS plus r_comp; false: without


@dc.dataclass
class ImpedanceGains:
    translational_stiffness: float = 500.0
    translational_damping: float = 45.0
    rotational_stiffness: float = 900.0
    rotational_damping: float = 20.0
    nullspace_stiffness: float = 4.0
    nullspace_damping: float = 4.0
    ee_tilt_deg: float = 15.0
    q_null: List[float] = dc.field(default_factory=lambda: [0.0, 0.361, 0.0, -2.223, 0.0, 2.584, 0.0])
    feedforward: bool = True         # add the planned contact force
    operational_space: bool = False  # weight the feedback by the task inertia (critically
                                     # damped on the arm) instead of the reference's J'F


@dc.dataclass
class CameraConfig:
    enabled: bool = True             # False: the estimator reads the true ball pose plus
                                     # position_noise_m of noise (default 0: noise-free)
    rate_hz: float = 80.0
    width: int = 160                 # px; 320 x 240 until issue 18: the render cost twice
    height: int = 120                # as much, the estimate 0.3 mm (mean) closer (docs/performance.md)
    position_noise_m: float = 0.0    # extra noise on the estimate (camera off only)
    filter_alpha: float = 0.5        # low-pass weight of the newest measurement


@dc.dataclass
class SafetyLimits:
    """The 1 kHz impedance loop's safety layer (systems/franka/safety_monitor.py): a
    breach is a safe stop (damping, then no more commands, exit code 3); the *_warn_*
    rates only print a warning. Times on the loop's clock unless noted."""
    status_gap_s: float = 0.05           # no new PANDA_STATUS for longer, or two statuses
                                         # further apart (their utime, the driver's clock)
    status_min_rate_hz: float = 500.0    # PANDA_STATUS below this in two rate windows running
    status_warn_rate_hz: float = 900.0   # ... below this: warning
    plan_warn_rate_hz: float = 180.0     # EE_PLAN below this: warning (the planner sends
                                         # one every 5 ms while it keeps real time)
    rate_window_s: float = 0.2           # the window the rates are measured over
    plan_max_age_s: float = 0.5          # the plan's utime this far behind the status's
    ball_max_age_s: float = 0.25         # no usable BALL_ESTIMATE for longer (once one came)
    saturation_s: float = 0.05           # a joint's torque at its limit for longer
    joint_margin_deg: float = 2.0        # a joint closer than this to its limit (Panda's)
    ee_speed_max: float = 1.0            # m/s, EE tip speed
    workspace_min: List[float] = dc.field(default_factory=lambda: [0.25, -0.4, 0.0])
    workspace_max: List[float] = dc.field(default_factory=lambda: [0.85, 0.4, 0.45])
                                         # m, the box the EE tip must stay in, base frame
    malformed_run: int = 10              # this many bad messages in a row on one channel
    stop_ramp_s: float = 0.3             # damping commands (-kd v) for this long after a stop
    stop_damping_scale: float = 1.0      # kd = this x the driver's [37.5 50 37.5 25 5 3.75 2.5]
    warn_interval_s: float = 5.0         # at most one line per kind of warning this often


@dc.dataclass
class DrakeWorld:
    """The world `diagnose --model drake` replays ball-rolling recordings through: Drake's
    MultibodyPlant with SAP and point contact (EE tip sphere driven by the recorded EE
    force, ball, table). `run` does not read it. 0 (or -1 for friction) = the `model`
    section's value; what a drake diagnosis finds is written here."""
    time_step: float = 0.0           # s, SAP step; 0 = the recording's step / 4
    point_stiffness: float = 1.0e5   # N/m, every geometry (a pair: half, in series)
    relaxation_time: float = 2.0e-3  # s, SAP's dissipation time scale, every geometry
    friction: List[float] = dc.field(default_factory=lambda: [-1.0, -1.0])  # mu of
                                     # [ee_ball, ball_table]; < 0 = model.friction
    table_height: float = 0.0        # m, world z of the table top
    ee_radius: float = 0.0           # m; 0 = model.ee_radius
    ball_radius: float = 0.0         # m; 0 = model.ball_radius
    ball_mass: float = 0.0           # kg; 0 = model.ball_mass
    rolling_resistance: float = 0.0  # m: torque c m g opposing the ball's rolling (on the table)
    torsional_friction: float = 0.0  # m: torque c m g opposing its spin about the vertical
    viscous_drag: float = 0.0        # N s/m, force -c v on the ball
    external_force: List[float] = dc.field(default_factory=lambda: [0.0, 0.0])  # N, world x, y


@dc.dataclass
class BallRollingScenario:
    task: str = "ball_rolling"
    name: str = "ball_rolling"
    robot: str = "panda"             # panda | point_ee (the controller's own EE model as the truth)
    point_ee_mass: float = 1.0       # kg, the point EE's mass when robot: point_ee
    model: RollingModel = dc.field(default_factory=RollingModel)
    c3: C3Config = dc.field(default_factory=lambda: C3Config(horizon=5, rate_hz=80.0, rho_scale=2.0))
    learner: RollingLearnerConfig = dc.field(default_factory=lambda: RollingLearnerConfig(
        enabled=True, learning_rate=5e-3, epsilon=2e-5, gamma=1e-2, rate_hz=20.0))
    target: TargetPath = dc.field(default_factory=TargetPath)
    gait: Gait = dc.field(default_factory=Gait)
    impedance: ImpedanceGains = dc.field(default_factory=ImpedanceGains)
    camera: CameraConfig = dc.field(default_factory=CameraConfig)
    safety: SafetyLimits = dc.field(default_factory=SafetyLimits)
    drake: DrakeWorld = dc.field(default_factory=DrakeWorld)
    ball_start_angle_deg: float = 0.0   # where on the circle the ball starts (0 = +y of centre)
    sim_time_step: float = 0.001        # true plant step, s
    sim_duration_s: float = 60.0
    initial_state: List[float] = dc.field(default_factory=list)   # unused (start from the gait)
    seed: int = 0


def validate_ball_rolling(s: BallRollingScenario) -> None:
    _validate_common(s)

    def need(cond, msg):
        if not cond:
            raise ScenarioError(msg)

    def positive(path, value):
        need(math.isfinite(value) and value > 0, f"{path} must be > 0, got {value}")

    m = s.model
    need(m.object in ("ball", "orange", "lime"), f"model.object must be ball, orange or lime, got '{m.object}'")
    need(s.robot in ("panda", "point_ee"), f"robot must be panda or point_ee, got '{s.robot}'")
    for key in ("ball_radius", "ball_mass", "true_mass_scale", "ee_radius", "ee_mass",
                "friction", "true_friction", "eps_c", "planning_dt"):
        positive(f"model.{key}", getattr(m, key))
    need(math.isfinite(m.radius_error) and abs(m.radius_error) < 0.5 * m.ball_radius,
         f"model.radius_error must be smaller than half the radius, got {m.radius_error}")
    need(math.isfinite(m.learner_dt) and 0 <= m.learner_dt <= m.planning_dt,
         f"model.learner_dt must be in [0, planning_dt], got {m.learner_dt}")
    need(math.isfinite(m.true_ee_friction) and (m.true_ee_friction < 0
                                                or 0 < m.true_ee_friction < 2 * m.true_friction),
         "model.true_ee_friction must be < 0 (off) or in (0, 2 x model.true_friction) "
         f"(Drake combines a pair's coefficients), got {m.true_ee_friction}")
    need(m.learner_input in ("applied", "motion"), f"model.learner_input must be applied or motion, got '{m.learner_input}'")
    need(m.friction_edges in (4, 8), f"model.friction_edges must be 4 or 8, got {m.friction_edges}")
    need(len(s.target.center) == 2 and all(math.isfinite(v) for v in s.target.center),
         "target.center must be [x, y]")
    positive("target.radius", s.target.radius)
    g = s.gait
    need(g.return_mode in ("c3", "waypoint"), f"gait.return_mode must be c3 or waypoint, got '{g.return_mode}'")
    need(g.floor in ("gap", "table"), f"gait.floor must be gap or table, got '{g.floor}'")
    need(math.isfinite(g.table_clearance) and 0 <= g.table_clearance < 0.2,
         f"gait.table_clearance must be in [0, 0.2) m, got {g.table_clearance}")
    need(s.learner.tie_residual in ("pairs", "none"),
         f"learner.tie_residual must be pairs or none, got '{s.learner.tie_residual}'")
    for key in ("roll_s", "return_s", "back_distance", "lift_height", "max_ee_speed",
                "return_ee_weight", "return_speed"):
        positive(f"gait.{key}", getattr(g, key))
    need(g.settle_s >= 0, "gait.settle_s must be >= 0")
    need(math.isfinite(g.place_xy_tolerance) and g.place_xy_tolerance >= 0,
         f"gait.place_xy_tolerance must be >= 0, got {g.place_xy_tolerance}")
    for key in ("roll_height", "place_height"):
        need(math.isfinite(getattr(g, key)) and abs(getattr(g, key)) < 0.2,
             f"gait.{key} must be a height within 0.2 m, got {getattr(g, key)}")
    imp = s.impedance
    for key in ("translational_stiffness", "translational_damping", "rotational_stiffness",
                "rotational_damping"):
        positive(f"impedance.{key}", getattr(imp, key))
    need(len(imp.q_null) == 7, "impedance.q_null must have 7 joint angles")
    positive("camera.rate_hz", s.camera.rate_hz)
    need(16 <= s.camera.width <= 4096 and 16 <= s.camera.height <= 4096, "camera size out of range")
    need(0 < s.camera.filter_alpha <= 1, "camera.filter_alpha must be in (0, 1]")
    positive("sim_time_step", s.sim_time_step)
    _validate_safety(s.safety, need, positive)
    _validate_drake(s.drake, need, positive)
    if len(s.c3.q_diag) not in (0, 19):
        raise ScenarioError(f"c3.q_diag must have 19 entries for ball rolling, got {len(s.c3.q_diag)}")



def _validate_drake(d: DrakeWorld, need, positive) -> None:
    def finite(v):
        return isinstance(v, (int, float)) and math.isfinite(v)
    positive("drake.point_stiffness", d.point_stiffness)
    for key in ("time_step", "relaxation_time", "ee_radius", "ball_radius", "ball_mass",
                "rolling_resistance", "torsional_friction", "viscous_drag"):
        need(finite(getattr(d, key)) and getattr(d, key) >= 0,
             f"drake.{key} must be >= 0, got {getattr(d, key)}")
    need(finite(d.table_height) and abs(d.table_height) < 0.1,
         f"drake.table_height must be within 0.1 m, got {d.table_height}")
    need(len(d.friction) == 2 and all(finite(v) for v in d.friction),
         "drake.friction must be [ee_ball, ball_table] (< 0: model.friction)")
    need(len(d.external_force) == 2 and all(finite(v) for v in d.external_force),
         "drake.external_force must be [fx, fy] (N)")


def _validate_safety(f: SafetyLimits, need, positive) -> None:
    for key in ("status_gap_s", "rate_window_s", "plan_max_age_s", "ball_max_age_s",
                "saturation_s", "joint_margin_deg", "ee_speed_max", "stop_ramp_s",
                "warn_interval_s"):
        positive(f"safety.{key}", getattr(f, key))
    for key in ("status_min_rate_hz", "status_warn_rate_hz", "plan_warn_rate_hz"):
        need(math.isfinite(getattr(f, key)) and getattr(f, key) >= 0,
             f"safety.{key} must be >= 0, got {getattr(f, key)}")
    need(f.status_min_rate_hz <= f.status_warn_rate_hz,
         "safety.status_min_rate_hz must be <= safety.status_warn_rate_hz")
    need(f.malformed_run >= 1, f"safety.malformed_run must be >= 1, got {f.malformed_run}")
    need(math.isfinite(f.stop_damping_scale) and f.stop_damping_scale >= 1,
         f"safety.stop_damping_scale must be >= 1 (the driver's own damping), got {f.stop_damping_scale}")
    need(len(f.workspace_min) == 3 and len(f.workspace_max) == 3
         and all(math.isfinite(a) and math.isfinite(b) and a < b
                 for a, b in zip(f.workspace_min, f.workspace_max)),
         "safety.workspace_min / workspace_max must be [x, y, z] with min < max")


register_task("ball_rolling", BallRollingScenario, validate_ball_rolling)
