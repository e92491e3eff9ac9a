"""`adaptive-c3 diagnose RECORDING --scenario SCENARIO.yaml [--out DIR]`.

Locates where a recording and the scenario's model disagree, names the physical effect
the model leaves out (from the library in `effects`), fits it with a 95%
interval, writes a patched scenario and shows the held-out fit improve:
DIR/report.json, DIR/report.html (+ PNG plots), DIR/patched_scenario.yaml.

Tasks: cartpole (a constant LCS) and ball_rolling (the controller model's Anitescu LCS
linearised at every recording sample, tools/diagnosis/tasks/ball_rolling/effects_ball.py; the recording
must be sampled at 100 Hz); with `--model drake` ball rolling is diagnosed against Drake's
plant of the scenario's world instead (tasks/ball_rolling/drake_ball.py: the same engine,
effects in Drake's terms, the patch written to the scenario's `drake:` section and the
report saying what the finding means for the controller's LCS). rigid_object scenarios (free bodies tossed onto a table, many
episodes, full open-loop rollouts) are diagnosed by tools/diagnosis/tasks/rigid_object/rigid_diagnose.py.

Ball rolling, besides (tools/diagnosis/engine/evidence.py): a sensor delay is fitted first and
kept in the model (report `nuisance`); rolling resistance, drag and a constant force are
also fitted and judged on the windows where the ball rolls or rests without the EE; the
report says `verdict` named | ambiguous | none, lists the `ambiguous` set with held-out
scores and the `separating_excitation`, and which windows carried the `evidence`.

Patched scenarios: where an effect maps onto a scenario key it sets the key
(contact_offset -> model.wall_offset_error, contact_stiffness -> model.wall_stiffness;
ball rolling: contact_offset[ee_ball] -> model.ee_radius, mass_scale -> model.ball_mass);
every other effect goes into an `effects:` list. The scenario schema does not know that
list, so `run` refuses such a file; `diagnose` reads it (the listed effects become part
of the model it checks), so re-diagnosing with the patched scenario should say `none`.
"""
from __future__ import annotations

import functools
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

from adaptive_c3.scenarios.schema import ScenarioError, load_scenario
from adaptive_c3.tools.diagnosis.backends.effects import (EFFECTS, Candidate, applicable_candidates,
                                                cartpole_spec, patch)
from adaptive_c3.tools.diagnosis.backends.patched_scenario import patched_scenario_text
from adaptive_c3.tools.diagnosis.engine.evidence import (Z_AMBIG, evidence_windows, fit_row,
                                                  free_ball_verdict, not_excluded,
                                                  may_answer, require_support, strike_onsets,
                                                  top_pushes_only, widen_for_phases,
                                                  size_z, window_phases, worse_z)
from adaptive_c3.tools.diagnosis.engine.fit import Problem, evaluate, widen_for_nuisance
from adaptive_c3.tools.diagnosis.engine.selection import MIN_REDUCTION, fit_nuisance, select
from adaptive_c3.tools.diagnosis.engine.boundary import (below_size, confirm_on_left_out,
                                                         left_out_scores, ruled_out_members,
                                                         size_test_problem)
from adaptive_c3.tools.diagnosis.engine.beyond_size import answers_beyond_size, beyond_size
from adaptive_c3.tools.diagnosis.engine.direct_reading import read_directly, shown_directly
from adaptive_c3.tools.diagnosis.engine.left_out_rivals import rivals_on_left_out
from adaptive_c3.tools.diagnosis.engine.user_model_check import per_episode_ssr, worse_than_user
from adaptive_c3.tools.diagnosis.engine.held_out import widen_to_held_out
from adaptive_c3.tools.diagnosis.engine.joint_refit import refit_with_calibration
from adaptive_c3.tools.diagnosis.engine.profiled_size import Sizer
from adaptive_c3.tools.diagnosis.engine.locate import (calibrate_noise, contact_summary,
                                                       estimate_noise, locate, make_windows,
                                                       prediction_floor)
from adaptive_c3.tools.recording import RecordingError, load_recording

HORIZON = 10          # rollout steps for fitting, locating and the reported errors
BLOCK_STEPS = 200     # longest time block for cross-validation of 1-2 episode recordings


def _user_error(msg):
    from adaptive_c3.tools.user_input import UserError
    return UserError(msg)


# ------------------------------------------------------------------ scenario with effects
def load_scenario_with_effects(path):
    """(scenario, merged YAML text, base effects [(Candidate, params)]) for a scenario
    file that may carry an `effects:` list written by a previous diagnosis."""
    path = Path(path)
    if not path.is_file():
        raise ScenarioError(f"scenario file not found: {path}")
    try:
        data = yaml.safe_load(path.read_text()) or {}
    except yaml.YAMLError:
        data = None
    if not isinstance(data, dict) or "effects" not in data:
        scenario, text = load_scenario(path)
        return scenario, text, []
    raw = data.pop("effects") or []
    if "include" in data:
        data["include"] = str((path.parent / str(data["include"])).resolve())
    with tempfile.TemporaryDirectory() as tmp:
        tmp_path = Path(tmp) / path.name
        tmp_path.write_text(yaml.safe_dump(data, sort_keys=False))
        scenario, text = load_scenario(tmp_path)
    return scenario, text, _parse_effects(raw, path.name)


def _parse_effects(raw, where):
    if not isinstance(raw, list):
        raise ScenarioError(f"{where}: effects must be a list")
    out = []
    for i, e in enumerate(raw):
        if not isinstance(e, dict) or e.get("name") not in EFFECTS:
            raise ScenarioError(f"{where}: effects[{i}] needs a name from {', '.join(EFFECTS)}")
        vals = e.get("value")
        vals = vals if isinstance(vals, list) else [vals]
        if not all(isinstance(v, (int, float)) and np.isfinite(v) for v in vals):
            raise ScenarioError(f"{where}: effects[{i}].value must be finite numbers")
        out.append((Candidate(e["name"], str(e.get("target") or "")), np.array(vals, float)))
    return out


def model_spec(scenario, model: str = "lcs", workers: int = 2):
    """The diagnosis view of the scenario's model: `lcs` (the controller's LCS) or `drake`
    (ball rolling: Drake's plant of the scenario's world, tasks/ball_rolling/drake_ball.py)."""
    from adaptive_c3.tools.diagnosis.backends.model_backend import check_model
    task = getattr(scenario, "task", "cartpole")
    check_model(model)
    if task == "cartpole":
        if model != "lcs":
            raise _user_error(f"--model {model}: cartpole scenarios are diagnosed with the lcs "
                              f"model only (--model drake: ball_rolling and rigid_object)")
        return cartpole_spec(scenario)
    if task == "ball_rolling":
        if model == "drake":
            from adaptive_c3.tools.diagnosis.tasks.ball_rolling.drake_ball import drake_ball_spec
            return drake_ball_spec(scenario, workers=workers)
        from adaptive_c3.tools.diagnosis.tasks.ball_rolling.effects_ball import ball_spec
        return ball_spec(scenario)
    raise _user_error(f"diagnose supports the cartpole and ball_rolling tasks, not '{task}'")


def fit_weight(spec) -> np.ndarray:
    """[n] 1 for the states fitted and scored, 0 for the ignored ones (e.g. quaternions)."""
    w = getattr(spec, "fit_weight", None)
    return np.ones(len(spec.state_names)) if w is None else np.asarray(w, float)


# ------------------------------------------------------------------ checks
def check_recording(rec, spec):
    if list(rec.state_names) != list(spec.state_names):
        raise RecordingError(
            f"recording state names {list(rec.state_names)} do not match the scenario's "
            f"model {list(spec.state_names)}")
    if list(rec.input_names) != list(spec.input_names):
        raise RecordingError(
            f"recording input names {list(rec.input_names)} do not match the scenario's "
            f"model {list(spec.input_names)}")
    dts = np.concatenate([np.diff(rec.t[idx]) for _, idx in rec.episodes() if len(idx) > 1])
    if len(dts) == 0:
        raise RecordingError("recording has no episode with two or more samples")
    dt = float(np.median(dts))
    if abs(dt - spec.dt) > 0.02 * spec.dt or np.max(np.abs(dts - spec.dt)) > 0.1 * spec.dt:
        raise RecordingError(f"recording is sampled every {dt:.4g} s (not uniformly), the "
                             f"model steps {spec.dt:.4g} s; resample it to the model's step")
    longest = max(len(idx) for _, idx in rec.episodes())
    if longest < 3 * HORIZON:
        raise RecordingError(f"recording is too short: the longest episode has {longest} "
                             f"samples, diagnose needs at least {3 * HORIZON}")


# ------------------------------------------------------------------ folds
FOLDS = 3


def fold_ids(rec, W) -> tuple[np.ndarray, str]:
    """[W] cross-validation fold per window (-1 = unused) and a note: episodes dealt to
    FOLDS folds, or FOLDS-cyclic time blocks when there are fewer than FOLDS episodes."""
    eps = [e for e, _ in rec.episodes()]
    if len(eps) >= FOLDS:
        return W.episode % FOLDS, f"{FOLDS}-fold cross-validation over {len(eps)} episodes"
    block = int(np.clip(len(rec.t) // (3 * FOLDS), 3 * W.Xt.shape[1], BLOCK_STEPS))
    block_start = W.row // block
    block_end = (W.row + W.Xt.shape[1]) // block
    fold = np.where(block_start == block_end, block_start % FOLDS, -1)   # no straddling
    return fold, f"{FOLDS}-fold cross-validation over {block}-step time blocks"


def error_table(spec, models, W, fold, floor, mask=None, per_episode=None) -> dict | None:
    """Out-of-fold errors: RMSE per state and RMS in noise-floor units. models: fold -> P.
    per_episode (a dict): filled with {episode: SSR in noise units}."""
    from adaptive_c3.tools.diagnosis.backends.effects import rollout
    from adaptive_c3.tools.diagnosis.engine.locate import LAG
    keep = (fold >= 0) if mask is None else (fold >= 0) & mask
    errs, eps = [], []
    for k, P in models.items():
        Wk = W.take(keep & (fold == k))
        if len(Wk):
            X, _ = rollout(P, Wk.X0, Wk.U, Wk.Xt.shape[1], LAG, Wk.row)
            errs.append(X - Wk.Xt)
            eps.append(Wk.episode)
    if not errs:
        return None
    err = np.concatenate(errs, 0)
    fl = floor[:err.shape[1]]
    rmse = np.sqrt(np.mean(err ** 2, axis=(0, 1)))
    scored = fit_weight(spec) > 0
    if per_episode is not None:
        per_episode.update(per_episode_ssr(err, np.concatenate(eps), fl, scored))
    norm = float(np.sqrt(np.mean((err / fl)[..., scored] ** 2)))
    return dict(rmse={n: float(v) for n, v in zip(spec.state_names, rmse)},
                normalised_rms=norm, excess_over_noise=float(np.sqrt(max(norm ** 2 - 1.0, 0.0))),
                windows=int(len(err)))


def long_problem(rec, spec, prob, P0, sigma, stride: int, left_out_stride: int = 0):
    """prob's fit problem with FREE_HORIZON-step rollouts (the free-ball effects' fits;
    None for models without free-ball windows or recordings too short for them). Every
    `stride`-th window, or, for a spec with `free_fit_windows`, about that many of the
    free windows (coasts and rests) evenly: a costly model's sparse stride keeps about a
    third of its windows free, and a large rolling resistance stops the ball within a
    few of them (development draw 90106, 3.7 mm: 99 % of the fit's information in 4 of
    33 free windows; its jackknife interval reached below 0). On development draws 90132
    and 90228 (3.3 and 2.35 mm) the denser free windows named the resistance after one
    follow-up, where the sparse ones left `none` beside it (tools/diagnosis/NOTES.md).

    left_out_stride > 0: (that problem, every left_out_stride-th window it left out, as
    boundary.size_test_problem; None where it kept all) instead."""
    from adaptive_c3.tools.diagnosis.engine.evidence import FREE_HORIZON, FREE_PHASES
    if not getattr(spec, "free_ball", False):
        return (None, None) if left_out_stride else None
    try:
        W = make_windows(rec, FREE_HORIZON)
    except ValueError:
        return (None, None) if left_out_stride else None
    fold, _ = fold_ids(rec, W)
    target = getattr(spec, "free_fit_windows", None)
    if target:
        free = np.isin(window_phases(spec, W), FREE_PHASES)
        step = max(1, int(np.ceil(free.sum() / target)))
        keep = free & ((np.cumsum(free) - 1) % step == 0)
    else:
        keep = np.arange(len(W)) % stride == 0
    floor = prediction_floor(P0, sigma, FREE_HORIZON)
    out = Problem(spec, list(prob.base), W.take(keep), fold[keep], fit_weight(spec) / floor)
    if not left_out_stride:
        return out
    return out, size_test_problem(out, W, fold, keep, left_out_stride)


def fit_windows(spec, W, stride: int) -> np.ndarray:
    """[W] bool: the windows the fit uses: every `stride`-th, and, for a spec with
    `strike_fit_windows`, up to that many more (evenly over the recording) in which a
    strike begins. A costly model's sparse stride rarely lands on a strike, where EE-ball
    friction shows: on development draw 101215 (mu 0.28 against the model's 1, with a
    follow-up of strikes) the 100 windows at a stride of 115 held 23 in contact, and over
    them the fit's error did not change between mu 0.1 and 1.0; over the 100 windows
    where contact began it was least at 0.28 (SSR 1.47e5 against 3.05e5 at mu 1), and
    over the first recording's 35 touchdowns (pushes from above) it barely moved."""
    keep = np.arange(len(W)) % max(int(stride), 1) == 0
    budget = int(getattr(spec, "strike_fit_windows", 0))
    if budget > 0:
        onsets = np.flatnonzero(strike_onsets(spec, W))
        if len(onsets) > budget:
            onsets = onsets[np.unique(np.linspace(0, len(onsets) - 1, budget).round()
                                      .astype(int))]
        keep[onsets] = True
    return keep


def in_windows(W, windows, rec) -> np.ndarray:
    ep_ids = rec.episode[W.row] if rec.episode is not None else np.zeros(len(W), int)
    m = np.zeros(len(W), bool)
    for w in windows:
        m |= (ep_ids == w["episode"]) & (W.t0 >= w["start"]) & (W.t0 <= w["end"])
    return m


# ------------------------------------------------------------------ the diagnosis
def diagnose(rec, spec, base=(), horizon: int = HORIZON, progress: bool | None = None,
             pairs: bool = True) -> dict:
    """Run the whole diagnosis on a loaded recording; returns a result dict (no files)."""
    with np.errstate(all="ignore"):    # trial parameters may blow a rollout up: scored 1e6
        return _diagnose(rec, spec, base, horizon, progress, pairs)


def _diagnose(rec, spec, base, horizon, progress, pairs) -> dict:
    from adaptive_c3.tools.progress import Progress
    start = time.perf_counter()
    base = list(base)
    cands, not_applicable = applicable_candidates(spec)
    # stages: linearise + locate (2), one per candidate fit and pair, the error tables (1)
    n_pair = getattr(spec, "pair_singles", 4)
    bar = Progress(len(cands) + (n_pair * (n_pair - 1) // 2 if pairs else 0) + 3,
                   "diagnose", unit="stages", enabled=progress)
    if hasattr(spec, "prepare"):          # time-varying models linearise along the recording
        spec.prepare(rec)
    bar.update(1)
    P0 = patch(spec, base)
    W1, WH = make_windows(rec, 1), make_windows(rec, horizon)
    sigma = estimate_noise(P0, W1)
    floor = prediction_floor(P0, sigma, horizon)
    foldH, split_note = fold_ids(rec, WH)
    fold1, _ = fold_ids(rec, W1)
    stride = int(getattr(spec, "window_stride", 1))    # costly models: fewer fit windows
    keep = fit_windows(spec, WH, stride)
    prob = Problem(spec, base, WH.take(keep), foldH[keep], fit_weight(spec) / floor)
    if len(prob.folds) < 2:
        raise RecordingError("recording is too short to hold out data for the fit")
    P_user, user_base = P0, list(base)     # the model as the user gave it
    t_nuisance = time.perf_counter()
    nuisance = fit_nuisance(prob)          # e.g. a sensor delay: part of the base model
    t_nuisance = time.perf_counter() - t_nuisance
    base = list(prob.base)
    P0 = patch(spec, base)
    windows, steps = locate(rec, spec, P0, W1, WH, floor, smooth=horizon)
    bar.update(2)
    chosen, fits, none_eval = select(prob, cands, progress=bar, pairs=pairs, offset=2)
    es = int(getattr(spec, "eval_stride", 1))     # costly models: every es-th window
    free_prob, free_left_out = long_problem(rec, spec, prob, P0, sigma, stride, es)
    chosen, judged, fits_free, (scored, none_scored) = free_ball_verdict(
        prob, cands, chosen, fits, none_eval, getattr(spec, "min_reduction", MIN_REDUCTION),
        free_prob=free_prob)
    if any(chosen is f for f in fits):    # a calibration may have taken up part of it
        refit_with_calibration(prob, chosen, nuisance, none_eval)
        base = list(prob.base)
    from adaptive_c3.tools.diagnosis.engine.report import calibration_shift
    shift = calibration_shift(dict(nuisance=nuisance))
    if chosen is not None:
        # widened on the windows it was judged on: for a free-ball choice the free ones,
        # since over the pushes the nuisances loosen a drag's interval until it holds 0
        widen(scored, none_scored, chosen, judged, user_base, nuisance)
    require_support(judged, spec, chosen, fits, none_eval, shift)    # the widened interval
    if below_size(judged, spec, chosen, [*fits_free, *fits], shift):    # too small to matter
        chosen = None
    left_out = size_test_problem(prob, WH, foldH, keep, es)
    left_none = functools.cache(lambda: evaluate(left_out, None))   # `none` there, once
    if any(chosen is f for f in fits):     # judged on all windows (not the free ones)
        confirm_on_left_out(judged, chosen, left_out, left_none, Z_AMBIG, prob, nuisance)
    sized = Sizer(prob, spec)       # sizes with the nuisances they trade against fitted
    not_excluded(judged, spec, fits, none_eval, fits_free, shift=shift, prob=prob,
                 size_prob=left_out, size_none=left_none, part_of_row=rec.extras.get("part"),
                 sized=sized)
    read_directly(judged, spec, rec, size_z())    # a size read from the data, no model
    gone = ruled_out_members(judged)     # every size that matters ruled out: too small
    if chosen is not None and chosen.label() in gone:
        chosen = None
        judged["ambiguous"].sort(key=lambda a: a["name"] != "none")    # `none` leads
    shown = beyond_size(judged, spec, fits, left_out, left_none, worse_z, shift, sized) \
        or shown_directly(judged, fits)
    if answers_beyond_size(shown, chosen, judged["verdict"]):
        chosen = shown
        widen(prob, none_eval, chosen, judged, user_base, nuisance)
    def may_lead(f) -> bool:         # widened as the chosen one was, then may it answer
        evidence = judged.get("evidence")
        widen(scored, none_scored, f, judged, user_base, nuisance)
        if may_answer(spec, f, shift):
            return True
        judged["evidence"] = evidence
        return False
    lead = rivals_on_left_out(judged, chosen, fits, fits_free, left_out, free_left_out,
                              may_lead)
    if lead is not None:             # the chosen effect fell to one fitted as it was
        chosen = lead
    left_out_scores(judged, fits, left_out, left_none)
    P1 = patch(spec, base + (chosen.effects(spec) if chosen else []))
    before = {k: P_user for k in prob.folds}    # before: the user's model, no nuisance
    after = {k: patch(spec, base + (chosen.fold_effects(spec, k) if chosen else []))
             for k in prob.folds}
    # the reported errors in units of the calibrated noise where the backend supports it
    # (the fit keeps the one-step estimate its rules were set with): a perfect model's
    # excess over noise is then ~0. The gain is the one of the model sigma was estimated
    # with (the user's); the floor then propagates it through the base model (a sensor
    # delay's start blends two samples: prediction_floor)
    sigma_report = calibrate_noise(spec, rec, P_user, sigma) \
        if getattr(spec, "calibrated_noise", False) else sigma
    floor_report = prediction_floor(P0, sigma_report, horizon)
    E1, e1 = W1.take(np.arange(len(W1)) % es == 0), fold1[::es]
    EH, eH = WH.take(np.arange(len(WH)) % es == 0), foldH[::es]
    inside1, insideH = in_windows(E1, windows, rec), in_windows(EH, windows, rec)
    errors, per_episode = {}, {"before": {}, "after": {}}
    for tag, models in (("before", before), ("after", after)):
        errors[tag] = dict(
            one_step=error_table(spec, models, E1, e1, floor_report),
            rollout=error_table(spec, models, EH, eH, floor_report, per_episode=per_episode[tag]),
            inside_mismatch_windows=dict(
                one_step=error_table(spec, models, E1, e1, floor_report, inside1),
                rollout=error_table(spec, models, EH, eH, floor_report, insideH)))
    if chosen is not None:          # the answer's own rollouts against the user's model
        worse_than_user(judged, chosen, per_episode["before"], per_episode["after"],
                        fit_row(None, none_eval), fit_row(chosen, none_eval))
    if not getattr(spec, "side_contact", False):     # every proposal made: strikes -> pushes
        top_pushes_only(judged)
    bar.close()
    return dict(spec=spec, base=base, sigma=sigma, floor=floor, sigma_report=sigma_report,
                floor_report=floor_report, windows=windows, steps=steps,
                W1=W1, WH=WH, fold1=fold1, foldH=foldH, split=split_note, chosen=chosen,
                fits=fits, none_eval=none_eval, not_applicable=not_applicable,
                P0=P0, P_user=P_user, P1=P1, P1_folds=after, errors=errors,
                contact=contact_summary(spec, steps), horizon=horizon, judged=judged,
                nuisance=nuisance, fits_free=fits_free, **backend_fields(spec, chosen),
                nuisance_seconds=t_nuisance, seconds=time.perf_counter() - start)


def widen(scored, none_scored, chosen, judged, user_base, nuisance) -> None:
    """The chosen fit's interval widened for what the statistical one leaves out (its
    phases, the nuisances, the held-out spread) on the windows `scored` it was judged on,
    and judged["evidence"]: where its held-out gain sits."""
    widen_for_phases(scored, chosen)
    widen_for_nuisance(scored, chosen, user_base, nuisance)
    widen_to_held_out(scored, chosen)
    Wu = scored.used()
    judged["evidence"] = evidence_windows(scored.spec, Wu, window_phases(scored.spec, Wu),
                                          none_scored[3] - chosen.test_window_ssr,
                                          chosen.cands[0].name)


def backend_fields(spec, chosen) -> dict:
    """The result's model_backend, model_description and, for a backend other than the
    LCS, lcs_counterpart: [{effect, lcs}] per chosen effect (spec.lcs_counterpart)."""
    name = getattr(spec, "model", "lcs")
    out = dict(model_backend=name, model_description=getattr(spec, "description", ""))
    if hasattr(spec, "lcs_counterpart"):
        out["lcs_counterpart"] = [dict(effect=c.label(), lcs=spec.lcs_counterpart(c.label()))
                                  for c in (chosen.cands if chosen is not None else ())]
    return out


def cmd_diagnose(args) -> int:
    from adaptive_c3.tools.user_input import resolve_scenario_path
    from adaptive_c3.tools.diagnosis.engine.report import write_report
    rec = load_recording(args.recording)
    if getattr(args, "also", None):
        from adaptive_c3.tools.recording import concat_recordings
        rec = concat_recordings([rec] + [load_recording(p) for p in args.also])
    scenario, text, base = load_scenario_with_effects(resolve_scenario_path(args.scenario))
    if scenario.task == "rigid_object":
        from adaptive_c3.tools.diagnosis.tasks.rigid_object.rigid_diagnose import cmd_diagnose_rigid
        return cmd_diagnose_rigid(args, scenario, text, rec)
    spec = model_spec(scenario, getattr(args, "model", None) or "lcs",
                      workers=getattr(args, "workers", 2) or 2)
    check_recording(rec, spec)
    if getattr(spec, "model", "lcs") == "drake" and base:
        try:                                  # an `effects:` list of an lcs diagnosis
            patch(spec, base)
        except ValueError as e:
            raise _user_error(f"{args.scenario}: {e}")
    out = Path(args.out) if args.out else Path("runs") / (
        f"diagnose-{Path(args.recording).stem}-{time.strftime('%Y%m%d-%H%M%S')}")
    out.mkdir(parents=True, exist_ok=True)
    try:
        result = diagnose(rec, spec, base)
        patched, notes = patched_scenario_text(text, spec, base, result["chosen"])
        (out / "patched_scenario.yaml").write_text(
            "# written by adaptive-c3 diagnose; " + "; ".join(notes or ["no effect selected"])
            + "\n" + patched)
        report = write_report(out, rec, result, scenario_notes=notes)
    finally:
        if hasattr(spec, "close"):        # the drake backend's worker processes
            spec.close()
    if report["model_backend"] != "lcs":
        print(f"model diagnosed: {report['model_backend']}; for the controller's LCS: "
              + ("; ".join(f"{c['effect']} -> {c['lcs']}" for c in report["lcs_counterpart"])
                 or "nothing to change"))
    sel = ", ".join(s["name"] + (f"[{s['target']}]" if s.get("target") else "")
                    for s in report["selected"])
    print(f"selected: {sel}; held-out rollout error (noise-floor units) "
          f"{report['error_before']['rollout']['normalised_rms']:.3g} -> "
          f"{report['error_after']['rollout']['normalised_rms']:.3g}")
    print(f"report in {out}: report.json, report.html, patched_scenario.yaml")
    return 0
