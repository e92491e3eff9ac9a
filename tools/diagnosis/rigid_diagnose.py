"""`diagnose` for rigid_object scenarios: where a recording of a tossed body and the rigid
model (tools/diagnosis/rigid_model.py) disagree, which physics the model left out, and
how much better the patched model predicts held-out episodes.

1. Split by episode (tools/diagnosis/episodes.py): held-out (never used to choose or fit
   anything), and the rest into a fit part and a validation part; twin episodes (copies
   up to a yaw and a shift) always land on one side together.
2. Locate: the model steps once from every recorded state of the fit episodes; samples
   are labelled flight / impact / sliding / rest from the data (lowest corner height,
   speeds), and runs of samples whose one-step velocity error exceeds 3x the flight
   phase's error (the sensing noise floor) are reported as mismatch windows, with the
   contact-mode agreement (model impulse > 0 vs data in contact and off-ballistic).
3. Effects (EFFECTS): each is fitted alone on the fit episodes by a grid over its value,
   refined by a parabola, with a 95% interval from bootstrapping episodes. Greedy forward
   selection: the effect that lowers the fit error most is kept only if it also lowers
   the validation episodes' error, with a bootstrap 95% interval of the paired
   improvement above zero and at least MIN_GAIN relative; then the next one is tried
   with the kept ones in place (at most MAX_EFFECTS). That is the over-fitting guard:
   every added effect must pay on episodes it was not fitted on.
4. The held-out episodes are rolled out with the nominal and the patched model; the
   patched scenario is written with the chosen values in its `contact` / `patch` keys.
The score is the one `evaluate` reports: an episode's mean-over-time position error as
% of the object's size, from a full open-loop rollout from the episode's first state.
"""
from __future__ import annotations

import copy
import multiprocessing
import time
from dataclasses import dataclass

import numpy as np

from adaptive_c3.models.rigid_object import RigidObjectParams
from adaptive_c3.tools.diagnosis.rigid_model import key_value
from adaptive_c3.tools.diagnosis.episodes import find_twins, split_episodes, twin_groups
from adaptive_c3.tools.diagnosis.evaluate import (episode_errors, recording_episodes,
                                                  summarise)
from adaptive_c3.tools.progress import Progress

MAX_EFFECTS = 3
MIN_GAIN = 0.02          # relative validation improvement an effect must bring
BOOTSTRAP = 2000
FAILED_SCORE = 500.0     # % of size scored for an episode whose rollout failed


@dataclass(frozen=True)
class RigidEffect:
    name: str
    key: str             # scenario key the value goes to
    grid: tuple          # values tried
    unit: str
    physics: str         # what it means, in words
    integer: bool = False


EFFECTS = (
    RigidEffect("table_offset", "patch.table_offset",
                (-5e-3, -4e-3, -3e-3, -2e-3, -1e-3, 0.0, 1e-3, 2e-3, 3e-3, 4e-3),
                "m", "the table top is not where the model puts it (calibration or geometry)"),
    RigidEffect("size_offset", "patch.size_offset", (-3e-3, -2e-3, -1e-3, 0.0, 1e-3, 2e-3, 3e-3),
                "m", "the object's contact geometry is larger or smaller than modelled"),
    RigidEffect("restitution", "patch.restitution", (0.0, 0.1, 0.2, 0.35, 0.5),
                "1", "impacts bounce back (the rigid model's impacts are perfectly inelastic)"),
    RigidEffect("friction_cone", "contact.friction_edges", (4, 6, 8, 12, 16), "edges",
                "friction is isotropic: the model's polyhedral cone of few edges gives less "
                "friction to slides between its edges (4 edges: 71 % of mu on the diagonal)",
                integer=True),
    RigidEffect("friction", "contact.friction", (0.08, 0.12, 0.18, 0.25, 0.35, 0.5),
                "1", "the friction coefficient differs from the model's"),
    RigidEffect("torsional_friction", "patch.torsional_friction", (0.0, 1e-3, 3e-3, 1e-2, 3e-2),
                "m", "contact patches resist spinning about the table normal (torsional "
                "friction; the rigid model's point contacts do not)"),
    RigidEffect("compliance", "contact.eps_c", (1e-4, 1e-3, 1e-2, 3e-2, 1e-1),
                "1/kg", "contact is compliant (the model's contact regulariser is too stiff)"),
    RigidEffect("inertia_scale", "patch.inertia_scale", (0.6, 0.8, 1.0, 1.25, 1.5),
                "1", "the rotational inertia differs from a solid box's"),
    RigidEffect("r_comp", "patch.r_comp", (-0.1, -0.05, -0.02, 0.0, 0.02, 0.05, 0.1),
                "m/s", "a constant residual on every complementarity row (the learner's r_comp)"),
)
NOT_IDENTIFIABLE = {
    "mass_scale": "no input acts on the body: scaling its mass and inertia together leaves "
                  "its motion unchanged (inertia_scale is tried instead)",
    "rolling_friction": "the rigid model has no rolling resistance term yet (a cube "
                        "tumbles on its edges rather than rolls); not tried",
}


# ------------------------------------------------------------------ scoring
def with_values(scenario, values: dict):
    """A copy of the scenario with `section.field` keys set (key_value's types)."""
    s = copy.deepcopy(scenario)
    for key, v in values.items():
        section, field = key.split(".")
        setattr(getattr(s, section), field, key_value(key, v))
    return s


def _score_job(job):
    """Per-episode mean position error (% of size) of one scenario on some episodes."""
    from adaptive_c3.tools.diagnosis.rigid_model import RigidModelError, RigidObjectModel
    scenario, episodes, dt, size = job
    model = RigidObjectModel(scenario, dt)
    out = []
    for x in episodes:
        try:
            with np.errstate(all="ignore"):
                x_hat = model.rollout(x[0], len(x) - 1)
            score = episode_errors(x_hat, x, size)["position_pct_mean"]
            out.append(score if np.isfinite(score) else FAILED_SCORE)
        except (RigidModelError, ValueError, np.linalg.LinAlgError):
            out.append(FAILED_SCORE)
    return out


class Scorer:
    """Scores lists of scenarios on a fixed episode set, on `workers` processes."""

    def __init__(self, episodes: list, dt: float, size: float, workers: int = 2):
        self.episodes, self.dt, self.size = episodes, dt, size
        self.workers = max(1, int(workers))
        self._pool = None
        if self.workers > 1:
            self._pool = multiprocessing.get_context("fork").Pool(self.workers)

    def __call__(self, scenarios: list, progress=None) -> np.ndarray:
        """[len(scenarios), episodes] scores."""
        chunks = np.array_split(np.arange(len(self.episodes)), self.workers)
        jobs = [(s, [self.episodes[i] for i in c], self.dt, self.size)
                for s in scenarios for c in chunks if len(c)]
        mapper = self._pool.imap if self._pool else map
        parts = []
        for i, part in enumerate(mapper(_score_job, jobs)):
            parts.append(part)
            if progress:
                progress(i + 1, len(jobs))
        per = len([c for c in chunks if len(c)])
        return np.array([sum(parts[k * per:(k + 1) * per], []) for k in range(len(scenarios))])

    def close(self):
        if self._pool:
            self._pool.terminate()


def refine_minimum(grid, means, integer: bool = False) -> float:
    """The minimiser of a parabola through the best grid point and its neighbours (the
    best grid point itself for integer effects)."""
    g, m = np.asarray(grid, float), np.asarray(means, float)
    i = int(np.argmin(m))
    if integer or i == 0 or i == len(g) - 1:
        return float(g[i])
    x0, x1, x2 = g[i - 1:i + 2]
    y0, y1, y2 = m[i - 1:i + 2]
    den = (x0 - x1) * (x0 - x2) * (x1 - x2)
    a = (x2 * (y1 - y0) + x1 * (y0 - y2) + x0 * (y2 - y1)) / den
    b = (x2 ** 2 * (y0 - y1) + x1 ** 2 * (y2 - y0) + x0 ** 2 * (y1 - y2)) / den
    if a <= 0:
        return float(x1)
    return float(np.clip(-b / (2 * a), x0, x2))


def bootstrap_interval(grid, S: np.ndarray, rng, integer: bool = False) -> tuple[float, float]:
    """95% interval of the refined minimiser over episode resamples of S [grid, episodes]."""
    E = S.shape[1]
    picks = rng.integers(0, E, size=(BOOTSTRAP, E))
    means = S[:, picks].mean(axis=2).T            # [BOOTSTRAP, grid]
    best = np.array([refine_minimum(grid, m, integer) for m in means])
    lo, hi = np.percentile(best, [2.5, 97.5])
    return float(lo), float(hi)


def paired_gain(before: np.ndarray, after: np.ndarray, rng) -> dict:
    """How much an effect lowers the episodes' errors (% of size): the median of the
    per-episode drops (robust to the few tosses a small change sends elsewhere, and
    paired, so a drop shared by most episodes shows even when it is small beside the
    spread between episodes), with a 95 % interval from resampling episodes."""
    d = np.asarray(before, float) - np.asarray(after, float)
    picks = rng.integers(0, len(d), size=(BOOTSTRAP, len(d)))
    lo, hi = np.percentile(np.median(d[picks], axis=1), [2.5, 97.5])
    value = float(np.median(d))
    scale = max(float(np.median(before)), 1e-9)
    return dict(drop=value, ci95=[float(lo), float(hi)], relative=value / scale,
                relative_ci95=[float(lo) / scale, float(hi) / scale],
                statistic="median of the per-episode drops")


# ------------------------------------------------------------------ the diagnosis
def _current_value(scenario, key):
    section, field = key.split(".")
    v = getattr(getattr(scenario, section), field)
    return float(v[0]) if isinstance(v, list) and v else (0.0 if isinstance(v, list) else float(v))


def split(rec, episodes: dict, held_out_fraction: float, seed: int) -> dict:
    """{fit, validation, held_out: sorted ids} with twins on one side, and the twin pairs."""
    pairs = find_twins(rec)
    ids = sorted(episodes)
    groups = twin_groups(ids, [p for p in pairs if p[0] in episodes and p[1] in episodes])
    train, held_out = split_episodes(ids, held_out_fraction, seed, groups)
    fit, validation = split_episodes(train, 0.4, seed + 1,
                                     [g for g in groups if g[0] in set(train)])
    return dict(fit=fit, validation=validation, held_out=held_out, twins=pairs)


def diagnose_rigid(rec, scenario, held_out_fraction: float = 0.3, max_fit_episodes: int = 30,
                   workers: int = 2, seed: int = 0, progress: bool | None = None,
                   baseline: bool = False, show: int = 3, effects=None) -> dict:
    """The whole diagnosis of a rigid_object recording; returns a result dict (no files).
    baseline: also Drake's SAP simulation on the held-out episodes, as it is and with its
    knobs tuned on the same fit episodes (tools/diagnosis/drake_baseline.py).
    effects: names from EFFECTS to try (default all)."""
    from adaptive_c3.tools.diagnosis.rigid_locate import locate
    from adaptive_c3.tools.diagnosis.rigid_model import RigidObjectModel
    from adaptive_c3.tools.user_input import UserError
    start = time.perf_counter()
    rng = np.random.default_rng(seed)
    library = [e for e in EFFECTS if effects is None or e.name in effects]
    if effects is not None and len(library) != len(set(effects)):
        known = ", ".join(e.name for e in EFFECTS)
        raise UserError(f"unknown effects in {list(effects)} (known: {known})")
    episodes, dt = recording_episodes(rec)
    if len(episodes) < 5:
        raise UserError(f"diagnose needs at least 5 episodes to hold some out, got {len(episodes)}")
    parts = split(rec, episodes, held_out_fraction, seed)
    fit_ids = parts["fit"]
    if len(fit_ids) > max_fit_episodes:
        fit_ids = sorted(rng.choice(fit_ids, max_fit_episodes, replace=False).tolist())
    size = RigidObjectParams.from_scenario(scenario).size
    xs = {e: episodes[e][1] for e in episodes}

    located = locate(RigidObjectModel(scenario, dt), {e: episodes[e] for e in fit_ids}, dt)

    fit_score = Scorer([xs[e] for e in fit_ids], dt, size, workers)
    val_score = Scorer([xs[e] for e in parts["validation"]], dt, size, workers)
    total = sum(len(e.grid) + 2 for e in library) * MAX_EFFECTS + 2
    bar = Progress(total, "diagnose: fitting effects", unit="fits", enabled=progress)
    done = [0]

    def tick(n=1):
        done[0] += n
        bar.update(done[0])

    try:
        chosen = {}                  # key -> value
        S0 = fit_score([scenario])[0]
        V0 = val_score([scenario])[0]
        tick(2)
        rounds, remaining = [], list(library)
        for _ in range(MAX_EFFECTS):
            if not remaining:
                break
            base = with_values(scenario, chosen)
            cands = []
            for eff in remaining:
                grid = sorted(set(eff.grid) | {_current_value(base, eff.key)})
                S = fit_score([with_values(base, {eff.key: v}) for v in grid])
                tick(len(grid))
                means = S.mean(axis=1)
                best = refine_minimum(grid, means, eff.integer)
                S_best = fit_score([with_values(base, {eff.key: best})])[0]
                tick()
                if S_best.mean() > means.min():      # the objective is not a parabola there
                    best, S_best = float(grid[int(np.argmin(means))]), S[int(np.argmin(means))]
                cands.append(dict(name=eff.name, key=eff.key, unit=eff.unit, physics=eff.physics,
                                  value=best, ci95=list(bootstrap_interval(grid, S, rng, eff.integer)),
                                  grid=list(map(float, grid)), grid_fit_mean=means.tolist(),
                                  fit_mean=float(S_best.mean()),
                                  fit_gain_relative=float(1 - S_best.mean() / S0.mean())))
            cands.sort(key=lambda c: c["fit_mean"])
            top = cands[0]
            V1 = val_score([with_values(base, {top["key"]: top["value"]})])[0]
            gain = paired_gain(V0, V1, rng)
            accepted = gain["ci95"][0] > 0 and gain["relative"] >= MIN_GAIN
            rounds.append(dict(candidates=cands, tried=top["name"], validation_gain=gain,
                               accepted=bool(accepted)))
            if not accepted:
                break
            chosen[top["key"]] = top["value"]
            S0, V0 = fit_score([with_values(base, {top["key"]: top["value"]})])[0], V1
            remaining = [e for e in remaining if e.key != top["key"]]
    finally:
        bar.close()
        fit_score.close()
        val_score.close()

    patched = with_values(scenario, chosen)
    predictors = {"nominal": RigidObjectModel(scenario, dt).rollout,
                  "diagnosed": RigidObjectModel(patched, dt).rollout}
    drake_tuned = None
    if baseline:
        from adaptive_c3.tools.diagnosis.drake_baseline import (DrakeRigidSimulator, tune_drake,
                                                                with_drake)
        predictors["drake"] = DrakeRigidSimulator(scenario, dt).rollout
        drake_tuned, _ = tune_drake(scenario, [xs[e] for e in fit_ids], dt)
        predictors["drake_tuned"] = DrakeRigidSimulator(with_drake(scenario, **drake_tuned),
                                                        dt).rollout
    held, rollouts = {}, {}
    shown = parts["held_out"][:show]
    for tag, rollout in predictors.items():
        rows = []
        for e in parts["held_out"]:
            x = xs[e]
            with np.errstate(all="ignore"):
                x_hat = rollout(x[0], len(x) - 1)
            rows.append({"episode": e, **episode_errors(x_hat, x, size)})
            if e in shown:
                rollouts.setdefault(e, {"t": episodes[e][0], "data": x})[tag] = x_hat
        held[tag] = dict(summary=summarise(rows), per_episode=rows)
    selected = [dict(r["candidates"][0], validation_gain=r["validation_gain"])
                for r in rounds if r["accepted"]]
    return dict(dt=dt, size=size, split=parts, fit_episodes=fit_ids, located=located,
                rounds=rounds, selected=selected, chosen=chosen, patched=patched,
                not_identifiable=NOT_IDENTIFIABLE, held_out=held, rollouts=rollouts,
                drake_tuned=drake_tuned, seconds=time.perf_counter() - start)


def cmd_diagnose_rigid(args, scenario, scenario_text: str, rec) -> int:
    """`adaptive-c3 diagnose` for a rigid_object scenario (called by diagnose.py)."""
    from pathlib import Path

    from adaptive_c3.tools.diagnosis.rigid_report import write_report
    from adaptive_c3.tools.user_input import UserError
    if not 0 < args.held_out < 1:
        raise UserError(f"--held-out must be in (0, 1), got {args.held_out}")
    if args.fit_episodes < 2 or args.workers < 1:
        raise UserError("--fit-episodes must be >= 2 and --workers >= 1")
    out = Path(args.out) if args.out else Path("runs") / (
        f"diagnose-{Path(args.recording).stem}-{time.strftime('%Y%m%d-%H%M%S')}")
    out.mkdir(parents=True, exist_ok=True)
    result = diagnose_rigid(rec, scenario, held_out_fraction=args.held_out,
                            max_fit_episodes=args.fit_episodes, workers=args.workers,
                            baseline=args.baseline == "drake",
                            effects=tuple(args.effects.split(",")) if args.effects else None)
    report = write_report(out, result, scenario_text, result["rollouts"])
    print(report["summary"])
    print(f"report in {out}: report.json, report.html, patched_scenario.yaml")
    return 0
