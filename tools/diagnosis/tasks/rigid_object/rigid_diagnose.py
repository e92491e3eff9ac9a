"""`diagnose` for rigid_object scenarios: where a recording of a tossed body and a model
of it disagree, which physics the model left out, and how much better the patched model
predicts held-out episodes.

The model is a backend of tools/diagnosis/backends/model_backend.py (`--model`): `lcs`, the
controller's Anitescu LCS (rigid_model.py), or `drake`, Drake's SAP plant of the
scenario's true world (drake_backend.py). Each has its effect library
(rigid_effects.py); effects are parameter changes, nuisances (compliance, calibration)
are labelled as such.
1. Split by episode (tools/diagnosis/tasks/rigid_object/episodes.py): held-out (never used to choose or fit
   anything), and the rest into a fit part and a validation part; twin episodes (copies
   up to a yaw and a shift) always land on one side together.
2. Locate: the model steps once from every recorded state of the fit episodes; samples
   are labelled flight / impact / sliding / rest from the data (lowest corner height,
   speeds), and runs of samples whose one-step velocity error exceeds 3x the flight
   phase's error (the sensing noise floor) are reported as mismatch windows, with the
   contact-mode agreement (model impulse or contact > 0 vs data in contact and
   off-ballistic).
3. Effects: each is fitted alone on the fit episodes by a grid over its value (coarse,
   then FINE_POINTS between the best value's neighbours; the objective is the 20 %
   trimmed mean of the per-episode errors, for the drake backend paired: of their
   changes from the current model, PAIRED_FIT), refined by a parabola, with a 95% interval
   from bootstrapping episodes. A two-parameter effect (`refit`, e.g. contact stiffness
   with friction: softer contact changes how far a landing cube slides) is scored at
   each value with its refit key at REFIT_FACTORS times its current value, keeping the
   best (a profile; no fine points); the refitted value goes with it. Greedy forward
   selection: the candidates that lower the fit error are checked on the validation
   episodes in order of fit error, at most MAX_TRIES a round, and the first whose
   bootstrap 95% interval of the paired improvement is above zero, with at least
   MIN_GAIN relative, is kept (a round whose MAX_TRIES best all fail ends the
   selection); then the next round runs with the kept ones in place (at most
   MAX_EFFECTS). That is the over-fitting guard: every added effect must pay on
   episodes it was not fitted on (the held-out episodes, never used to choose, then
   show what the choice is worth).
4. The held-out episodes are rolled out with the nominal and the patched model (with the
   bootstrap interval of the paired per-episode drop); the patched scenario is written
   with the chosen values in its keys.
The score is the one `evaluate` reports: an episode's mean-over-time position error as
% of the object's size, from a full open-loop rollout from the episode's start, estimated
by tools/diagnosis/tasks/rigid_object/initial_state.py (`--initial-state`), the same for every model.
Rollouts run on `workers` processes.
"""
from __future__ import annotations

import time

import numpy as np

from adaptive_c3.models.rigid_object import RigidObjectParams
from adaptive_c3.tools.diagnosis.tasks.rigid_object.episodes import find_twins, split_episodes, twin_groups
from adaptive_c3.tools.diagnosis.tasks.rigid_object.episodes import (episode_errors, recording_episodes,
                                                  summarise)
from adaptive_c3.tools.diagnosis.backends.model_backend import Scorer, check_model
from adaptive_c3.tools.diagnosis.tasks.rigid_object.rigid_effects import (EFFECTS, current_value, library,
                                                       not_identifiable, with_values)
from adaptive_c3.tools.progress import Progress

__all__ = ["EFFECTS", "diagnose_rigid", "with_values", "refine_minimum",
           "bootstrap_interval", "paired_gain"]

MAX_EFFECTS = 3
MAX_TRIES = 3            # candidates (best fit first) checked on the validation episodes a round
MIN_GAIN = 0.02          # relative validation improvement an effect must bring
BOOTSTRAP = 2000
TRIM = 0.2               # fraction of episodes cut at each end by the fit objective
FINE_POINTS = 4          # values added between the coarse grid's best point's neighbours
REFIT_FACTORS = (0.94, 0.97, 1.0, 1.03)   # a two-parameter effect's refit key, x its value
MAX_EXTEND = 3           # grid steps an effect may grow past each end (RigidEffect.extend)
DEFAULT_FIT_EPISODES = {"lcs": 30, "drake": 60}   # diagnose's --fit-episodes (a Drake
                         # rollout costs ~1/30 of an LCS one; 60 cube tosses: 348 s on 2 cores)
PAIRED_FIT = ("drake",)  # backends fitted by the paired objective (see objective): Drake's
                         # default is within ~1 % of size of its candidates on the real tosses,
                         # a change far below the toss-to-toss spread the unpaired one carries


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


def objective(S: np.ndarray, ref: np.ndarray | None = None) -> np.ndarray:
    """The fit objective over the last axis (episodes): their TRIM-trimmed mean error. The
    reported metric is a median over episodes; a plain mean lets the few chaotic tosses a
    small change sends elsewhere decide (on the real cube tosses the mean preferred a solid
    cube's inertia while 2/3 of the tosses fit a hollow one better), a median is too
    ragged for the grid's parabola.
    ref (paired; [..., episodes], the current model's errors on the same episodes): the
    trimmed mean of ref plus the trimmed mean of the per-episode differences S - ref, i.e.
    the statistic validation judges (a paired change), on the scale of an error."""
    from scipy.stats import trim_mean
    if ref is None:
        return trim_mean(S, TRIM, axis=-1)
    return trim_mean(ref, TRIM, axis=-1) + trim_mean(S - ref, TRIM, axis=-1)


def _refine_grid(grid, S: np.ndarray, score, ref=None) -> tuple[list, np.ndarray]:
    """The grid with FINE_POINTS values spread between the neighbours of its best point
    (by objective, paired with ref), and their scores (score(values) -> [values,
    episodes]) merged in."""
    i = int(np.argmin(objective(S, ref)))
    lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
    fine = [float(v) for v in np.linspace(lo, hi, FINE_POINTS + 2)[1:-1]
            if min(abs(v - g) for g in grid) > 1e-12 * max(1.0, abs(v))]
    if not fine:
        return list(grid), S
    merged = np.vstack([S, score(fine)])
    values = list(grid) + fine
    order = np.argsort(values)
    return [float(values[k]) for k in order], merged[order]


def profile_scores(score, base, eff, values, ref=None) -> tuple[np.ndarray, list]:
    """([len(values), episodes] scores, [{key: value}] per row) of effect eff at each of
    values on top of the scenario base (score(scenarios) -> [scenarios, episodes]). An
    effect with a `refit` key (a two-parameter effect) is scored at each value with that
    key at REFIT_FACTORS times its current value, and keeps the best (objective) of them:
    the rows are that profile, the dicts the refitted values (ref: see objective)."""
    if not eff.refit:
        return score([with_values(base, {eff.key: v}) for v in values]), [{}] * len(values)
    companions = [current_value(base, eff.refit) * f for f in REFIT_FACTORS]
    S = score([with_values(base, {eff.key: v, eff.refit: c})
               for v in values for c in companions])
    S = S.reshape(len(values), len(companions), -1)
    pick = np.argmin(objective(S, ref), axis=1)
    return (S[np.arange(len(values)), pick],
            [{eff.refit: float(companions[k])} for k in pick])


def extend_grid(eff, grid, S: np.ndarray, with_: list, score_values, ref=None):
    """(grid, S, with_) grown past an end while the effect's bootstrap interval reaches it:
    an interval clipped by the grid says nothing about the values beyond (the real cube's
    centre-of-mass offset read [6.1, 12.0] mm on a grid ending at 12 mm). One more value a
    grid step past that end, inside eff.extend, is scored (score_values(values) -> (S rows,
    with_ dicts), as profile_scores) at most MAX_EXTEND times a side. The check draws its
    own fixed-seed resamples, so a grid that needs no growth leaves every later draw as
    it was."""
    if not eff.extend or eff.integer:
        return grid, S, with_
    grid, with_ = list(grid), list(with_)
    grown = {-1: 0, 1: 0}
    while True:
        lo, hi = bootstrap_interval(grid, S, np.random.default_rng(0), False, ref)
        wanted = []
        for side, end, step, reach in ((-1, grid[0], grid[1] - grid[0], lo <= grid[0]),
                                       (1, grid[-1], grid[-1] - grid[-2], hi >= grid[-1])):
            value = end + side * step
            if reach and grown[side] < MAX_EXTEND and eff.extend[0] <= value <= eff.extend[1]:
                wanted.append((side, float(value)))
        if not wanted:
            return grid, S, with_
        S_new, with_new = score_values([v for _, v in wanted])
        for (side, value), row, w in zip(wanted, S_new, with_new):
            grown[side] += 1
            if side < 0:
                grid, S, with_ = [value] + grid, np.vstack([row[None], S]), [w] + with_
            else:
                grid, S, with_ = grid + [value], np.vstack([S, row[None]]), with_ + [w]


def bootstrap_interval(grid, S: np.ndarray, rng, integer: bool = False,
                       ref: np.ndarray | None = None) -> tuple[float, float]:
    """95% interval of the refined minimiser over episode resamples of S [grid, episodes]
    (ref, if paired, resampled with them)."""
    E = S.shape[1]
    picks = rng.integers(0, E, size=(BOOTSTRAP, E))
    means = objective(S[:, picks], None if ref is None else ref[picks]).T   # [BOOTSTRAP, grid]
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
                   baseline: bool = False, show: int = 3, effects=None, model: str = "lcs",
                   initial_state: str = "ballistic") -> dict:
    """The whole diagnosis of a rigid_object recording; returns a result dict (no files).
    model: the backend diagnosed (model_backend.MODELS); its effect library is
    rigid_effects.library(model). initial_state: how every rollout's start is estimated
    (initial_state.METHODS), the same for every model compared.
    baseline (model lcs): also Drake's SAP simulation on the held-out episodes, as it is
    and with its knobs tuned on the same fit episodes (tools/diagnosis/tasks/rigid_object/drake_baseline.py).
    effects: names from the library to try (default all)."""
    from adaptive_c3.tools.diagnosis.tasks.rigid_object.initial_state import METHODS, initial_states
    from adaptive_c3.tools.diagnosis.backends.model_backend import make_model
    from adaptive_c3.tools.diagnosis.tasks.rigid_object.rigid_locate import locate
    from adaptive_c3.tools.user_input import UserError
    start = time.perf_counter()
    rng = np.random.default_rng(seed)
    check_model(model)
    if initial_state not in METHODS:
        raise UserError(f"unknown --initial-state '{initial_state}' (known: {', '.join(METHODS)})")
    full = library(model)
    chosen_lib = [e for e in full if effects is None or e.name in effects]
    if effects is not None and len(chosen_lib) != len(set(effects)):
        known = ", ".join(e.name for e in full)
        raise UserError(f"unknown effects in {list(effects)} for --model {model} (known: {known})")
    episodes, dt = recording_episodes(rec)
    if len(episodes) < 5:
        raise UserError(f"diagnose needs at least 5 episodes to hold some out, got {len(episodes)}")
    parts = split(rec, episodes, held_out_fraction, seed)
    fit_ids = parts["fit"]
    if len(fit_ids) > max_fit_episodes:
        fit_ids = sorted(rng.choice(fit_ids, max_fit_episodes, replace=False).tolist())
    params = RigidObjectParams.from_scenario(scenario)
    size = params.size
    xs = {e: episodes[e][1] for e in episodes}
    x0s = initial_states(xs, dt, initial_state, params.half_size, params.table_height)

    located = locate(make_model(model, scenario, dt), {e: episodes[e] for e in fit_ids}, dt)

    def scorer(ids):
        return Scorer([xs[e] for e in ids], dt, size, workers, model, [x0s[e] for e in ids])

    fit_score, val_score = scorer(fit_ids), scorer(parts["validation"])
    total = sum((len(e.grid) + 2) * (len(REFIT_FACTORS) if e.refit else 1) + FINE_POINTS
                for e in chosen_lib) * MAX_EFFECTS + 2
    bar = Progress(total, f"diagnose ({model}): fitting effects", unit="fits", enabled=progress)
    done = [0]

    def tick(n=1):
        done[0] += n
        bar.update(done[0])

    try:
        chosen = {}                  # key -> value
        S0 = fit_score([scenario])[0]
        V0 = val_score([scenario])[0]
        tick(2)
        rounds, remaining = [], list(chosen_lib)
        for _ in range(MAX_EFFECTS):
            if not remaining:
                break
            base = with_values(scenario, chosen)
            ref = S0 if model in PAIRED_FIT else None
            cands = []
            for eff in remaining:
                here = current_value(base, eff.key)
                grid = sorted(set(eff.grid) | ({here} if here is not None else set()))
                per = len(REFIT_FACTORS) if eff.refit else 1     # rollouts of a value
                S, with_ = profile_scores(fit_score, base, eff, grid, ref)
                tick(len(grid) * per)

                def more(values):           # values past the grid's end (called right here)
                    tick(len(values) * per)
                    return profile_scores(fit_score, base, eff, values, ref)
                grid, S, with_ = extend_grid(eff, grid, S, with_, more, ref)
                if not eff.integer and not eff.refit:   # coarse to fine: FINE_POINTS between
                    grid, S = _refine_grid(grid, S, lambda vs: fit_score(   # the best's neighbours
                        [with_values(base, {eff.key: v}) for v in vs]), ref)
                    with_ = [{}] * len(grid)
                    tick(FINE_POINTS)
                means = objective(S, ref)
                best = refine_minimum(grid, means, eff.integer)
                (S_best,), (best_with,) = profile_scores(fit_score, base, eff, [best], ref)
                tick(per)
                if objective(S_best, ref) > means.min():      # the objective is not a parabola there
                    i = int(np.argmin(means))
                    best, S_best, best_with = float(grid[i]), S[i], with_[i]
                cands.append(dict(name=eff.name, key=eff.key, unit=eff.unit, physics=eff.physics,
                                  kind=eff.kind, lcs=eff.lcs, refitted=best_with,
                                  value=best, ci95=list(bootstrap_interval(grid, S, rng, eff.integer,
                                                                           ref)),
                                  grid=list(map(float, grid)), grid_fit_mean=means.tolist(),
                                  fit_mean=float(objective(S_best, ref)),
                                  fit_gain_relative=float(1 - objective(S_best, ref)
                                                          / objective(S0, ref))))
            cands.sort(key=lambda c: c["fit_mean"])
            tries = []
            for top in [c for c in cands if c["fit_mean"] < objective(S0, ref)][:MAX_TRIES]:
                top_values = {top["key"]: top["value"], **top["refitted"]}
                V1 = val_score([with_values(base, top_values)])[0]
                gain = paired_gain(V0, V1, rng)
                accepted = bool(gain["ci95"][0] > 0 and gain["relative"] >= MIN_GAIN)
                tries.append(dict(name=top["name"], validation_gain=gain, accepted=accepted))
                if accepted:
                    break
            if not tries:            # no candidate lowers the fit error: report the best one
                rounds.append(dict(candidates=cands, tried=cands[0]["name"], tries=[],
                                   validation_gain=None, accepted=False))
                break
            rounds.append(dict(candidates=cands, tried=tries[-1]["name"], tries=tries,
                               validation_gain=tries[-1]["validation_gain"],
                               accepted=tries[-1]["accepted"],
                               kept=top if tries[-1]["accepted"] else None))
            if not tries[-1]["accepted"]:
                break
            chosen.update(top_values)
            S0, V0 = fit_score([with_values(base, top_values)])[0], V1
            remaining = [e for e in remaining if e.key != top["key"]]
    finally:
        bar.close()
        fit_score.close()
        val_score.close()

    patched = with_values(scenario, chosen)
    runs = [("nominal", model, scenario), ("diagnosed", model, patched)]
    drake_tuned = None
    if baseline and model == "lcs":
        from adaptive_c3.tools.diagnosis.tasks.rigid_object.drake_baseline import tune_drake, with_drake
        drake_tuned, _ = tune_drake(scenario, [xs[e] for e in fit_ids], dt)
        runs += [("drake", "drake", scenario),
                 ("drake_tuned", "drake", with_drake(scenario, **drake_tuned))]
    held, rollouts = held_out_runs(runs, parts["held_out"], episodes, x0s, dt, size, workers,
                                   show)
    held_gain = paired_gain(
        np.array([r["position_pct_mean"] for r in held["nominal"]["per_episode"]]),
        np.array([r["position_pct_mean"] for r in held["diagnosed"]["per_episode"]]), rng)
    selected = [dict(r["kept"], validation_gain=r["validation_gain"])
                for r in rounds if r["accepted"]]
    return dict(dt=dt, size=size, model=model, initial_state=initial_state, split=parts,
                fit_episodes=fit_ids, located=located, rounds=rounds, selected=selected,
                chosen=chosen, patched=patched, not_identifiable=not_identifiable(model),
                held_out=held, held_out_gain=held_gain, rollouts=rollouts,
                drake_tuned=drake_tuned, seconds=time.perf_counter() - start)


def held_out_runs(runs, ids, episodes: dict, x0s: dict, dt: float, size: float,
                  workers: int, show: int = 3) -> tuple[dict, dict]:
    """({tag: {summary, per_episode}}, {episode: {t, data, tag: rollout}} for the first
    `show` ids) of runs [(tag, model, scenario)] rolled out from the starts x0s."""
    held, rollouts = {}, {}
    shown = list(ids)[:show]
    for tag, model, scen in runs:
        sc = Scorer([episodes[e][1] for e in ids], dt, size, workers, model,
                    [x0s[e] for e in ids])
        try:
            _, (x_hats,) = sc.run([scen], keep=True)
        finally:
            sc.close()
        rows = []
        for e, x_hat in zip(ids, x_hats):
            x = episodes[e][1]
            rows.append({"episode": e, **episode_errors(x_hat, x, size)})
            if e in shown and x_hat is not None:
                rollouts.setdefault(e, {"t": episodes[e][0], "data": x})[tag] = x_hat
        held[tag] = dict(summary=summarise(rows), per_episode=rows)
    return held, rollouts


def cmd_diagnose_rigid(args, scenario, scenario_text: str, rec) -> int:
    """`adaptive-c3 diagnose` for a rigid_object scenario (called by diagnose.py)."""
    from pathlib import Path

    from adaptive_c3.tools.diagnosis.tasks.rigid_object.rigid_report import write_report
    from adaptive_c3.tools.user_input import UserError
    if not 0 < args.held_out < 1:
        raise UserError(f"--held-out must be in (0, 1), got {args.held_out}")
    model = check_model(getattr(args, "model", None) or "lcs")
    fit_episodes = (args.fit_episodes if args.fit_episodes is not None
                    else DEFAULT_FIT_EPISODES[model])
    if fit_episodes < 2 or args.workers < 1:
        raise UserError("--fit-episodes must be >= 2 and --workers >= 1")
    out = Path(args.out) if args.out else Path("runs") / (
        f"diagnose-{Path(args.recording).stem}-{time.strftime('%Y%m%d-%H%M%S')}")
    out.mkdir(parents=True, exist_ok=True)
    result = diagnose_rigid(rec, scenario, held_out_fraction=args.held_out,
                            max_fit_episodes=fit_episodes, workers=args.workers,
                            baseline=args.baseline == "drake",
                            effects=tuple(args.effects.split(",")) if args.effects else None,
                            model=model,
                            initial_state=getattr(args, "initial_state", None) or "ballistic")
    report = write_report(out, result, scenario_text, result["rollouts"])
    print(report["summary"])
    print(f"report in {out}: report.json, report.html, patched_scenario.yaml")
    return 0
