"""report.json and report.html (with PNG plots, also embedded as base64) of `diagnose`."""
from __future__ import annotations

import base64
import html
import json
from pathlib import Path

import numpy as np

from adaptive_c3.tools.diagnosis.backends.effects import CALIBRATION_TOLERANCE, EFFECTS
from adaptive_c3.tools.diagnosis.engine.report_plots import report_plots


def physical_interval(spec, cand, value, lo, hi, sd):
    """(value, lo, hi, sd) of one fitted parameter read as the physical effect through
    the model's measured model form (spec.model_form_bias {label: (b, b_sd, gain,
    gain_sd)}: on data of another engine the model's best fit reads b + gain * truth
    for a truth above 0 and b + truth below it): the value is mapped back and the
    spreads of b and gain are added to the interval's sd in quadrature, at the
    interval's own quantile. Unchanged for effects without a listed model form."""
    mf = (getattr(spec, "model_form_bias", None) or {}).get(cand.label())
    if not mf:
        return value, lo, hi, sd
    b, b_sd, gain, gain_sd = mf
    q = (hi - lo) / (2.0 * sd) if sd > 0 else 1.96
    g = gain if value > b else 1.0
    v = (value - b) / g
    sd2 = float(np.sqrt((sd / g) ** 2 + (b_sd / g) ** 2
                        + (v * gain_sd / gain if v > 0 else 0.0) ** 2))
    return float(v), float(v - q * sd2), float(v + q * sd2), sd2


def effect_params(fit, spec, shift=None):
    """The fit's effects as report rows. shift {pair: m}: calibration offsets fitted as
    nuisance, added to a contact_offset / r_comp of the same pair (whose value is then
    the offset from the user's model). `by_phase`: the value refitted on each phase's
    windows alone (coast, rest, light / firm pushes), where the interval's model-form
    allowance comes from."""
    out, i = [], 0
    for c in fit.cands:
        p = c.num_params(spec)
        names, units = c.param_names(spec), c.units(spec)
        pairs = (spec.pair_names if c.name == "r_comp" else [c.target] * p)
        add = [(shift or {}).get(pairs[j], 0.0) if c.name in ("contact_offset", "r_comp")
               else 0.0 for j in range(p)]
        params = []
        for j in range(p):
            raw = float(fit.values[i + j]) + add[j]
            v, lo, hi, sd = physical_interval(spec, c, raw, float(fit.ci[i + j, 0]) + add[j],
                                              float(fit.ci[i + j, 1]) + add[j],
                                              float(fit.sd[i + j]))
            params.append(dict(name=names[j], value=v, unit=units[j], ci95=[lo, hi], sd=sd))
            if v != raw:        # the model's own best value (what a patch of it uses)
                params[-1]["model_value"] = raw
        row = dict(name=c.name, target=c.target, params=params)
        by_phase = getattr(fit, "phase_estimates", None)     # evidence.widen_for_phases
        if by_phase:
            row["by_phase"] = {ph: [float(v[i + j]) + add[j] for j in range(p)]
                               for ph, v in by_phase.items()}
        out.append(row)
        i += p
    return out


NUISANCE_NOTES = {
    "": "fitted first and kept in the model for every candidate",
    "actuator_delay": "fitted first and kept in the model for every candidate (the "
                      "recorded states lag the recorded inputs)",
    "sensor_delay": "fitted first and kept in the model for every candidate (the "
                    "recorded states lag the true ones; the model's predictions are "
                    "delayed the same way)",
    "calibration_offset": f"fitted first (within +-{1e3 * CALIBRATION_TOLERANCE:g} mm: how "
                          "well a table height or tool radius is known) and kept in the "
                          "model for every candidate; a selected contact_offset of the same "
                          "pair includes it",
}


def calibration_shift(result) -> dict:
    """{pair: m}: the calibration offsets kept as nuisance (see _params)."""
    from adaptive_c3.tools.diagnosis.backends.effects import calibration_sums
    return calibration_sums((c, [v]) for f in result.get("nuisance", [])
                            for c, v in zip(f.cands, f.values))


def candidate_rows(result, key: str = "fits") -> list:
    spec = result["spec"]
    rows = []
    for f in sorted(result.get(key) or [], key=lambda f: f.score):
        effects = effect_params(f, spec)
        row = dict(name=" + ".join(e["name"] for e in effects),
                   target=" + ".join(e["target"] for e in effects),
                   effects=effects,
                   held_out_error=dict(normalised_rms=float(np.sqrt(f.test_ssr / f.test_n)),
                                       ssr_reduction=float(f.reduction)),
                   penalty_score=float(f.score), num_params=int(f.num_params),
                   significant=bool(f.significant), physical=bool(f.physical),
                   z_vs_none=float(f.z_vs_none))
        if len(effects) == 1:
            row["params"] = effects[0]["params"]
        rows.append(row)
    return rows


def selected_rows(result) -> list:
    chosen = result["chosen"]
    if chosen is None:
        return [{"name": "none"}]
    out = []
    for e in effect_params(chosen, result["spec"], calibration_shift(result)):
        e["held_out_error"] = dict(normalised_rms=float(np.sqrt(chosen.test_ssr / chosen.test_n)),
                                   ssr_reduction=float(chosen.reduction))
        e["penalty_score"] = float(chosen.score)
        e["favoured"] = (result.get("judged") or {}).get("verdict", "named") == "named"
        out.append(e)
    return out


def _fmt(v):
    return f"{v:.3g}"


def _judged(result) -> dict:
    """report.json's verdict, ambiguous set, separating excitation, evidence windows, the
    sizes that matter tested directly and an effect found within its size that matters
    (engine/boundary.py)."""
    j = result.get("judged") or dict(verdict="none" if result["chosen"] is None else "named",
                                     ambiguous=[], separating_excitation=[])
    return {k: j[k] for k in ("verdict", "ambiguous", "separating_excitation", "evidence",
                              "size_tests", "confirmation", "left_out", "below_size",
                              "beyond_size", "left_out_rivals", "against_user_model",
                              "ruled_out_members", "direct_readings")
            if k in j}


def _alone(size_test) -> str:
    """' (by recording 1 alone)' where the pooled test of several recordings did not rule
    the size out and one recording's did (boundary.excluded), else ''."""
    each, bar = size_test.get("by_recording"), size_test.get("bar")
    if not each or size_test["z_vs_none"] <= -bar:
        return ""
    return f" (by recording {', '.join(str(i + 1) for i, z in enumerate(each) if z <= -bar)} alone)"


def ambiguity_summary(report) -> str:
    """Sentences on where the evidence sits and, for an ambiguous verdict, what would
    settle it."""
    ev, out = report.get("evidence"), ""
    if ev and ev["windows"]:
        w = ev["windows"][0]
        out = (f" {100 * ev['share_in_phases']:.0f}% of the held-out gain is in "
               f"{'/'.join(ev['phases']) or 'all'} windows (the largest: episode "
               f"{w['episode']}, {w['start']:.2f}-{w['end']:.2f} s, {w['phase']}).")
    ruled = [f"{t['name']} at {' and '.join(_fmt(x['value']) + _alone(x) for x in t['tested'])}"
             for t in report.get("size_tests", []) if t["excluded"]]
    if ruled:
        out += (f" Ruled out at the size that matters (the model fixed there is clearly "
                f"worse than without it on held-out windows): {', '.join(ruled)}"
                + (f"; so not kept beside `none`: {', '.join(report['ruled_out_members'])}."
                   if report.get("ruled_out_members") else "."))
    for r in report.get("direct_readings", []):
        out += (f" Read from the recording's momentum balance, no contact model: {r['name']} "
                f"= {_fmt(r['value'])} (interval {_fmt(r['interval'][0])} to "
                f"{_fmt(r['interval'][1])}, {r['windows']} windows of {r['episodes']} "
                f"episodes), " + ("within its size that matters "
                                  if r["within"] else "beyond its size that matters "
                                  if r["beyond"] else "reaching its size that matters ")
                + f"({_fmt(r['sizes'][0])} to {_fmt(r['sizes'][1])})"
                + ("; so not kept beside `none`." if r["within"] else
                   "; so `none` is not kept beside it." if r["beyond"] else "."))
    for b in report.get("below_size", []):
        lo, hi = b["ci95"]
        out += (f" Found {b['name']} = {_fmt(b['value'])} {b['unit']} (95% interval "
                f"{_fmt(lo)} to {_fmt(hi)}), within the size that matters (the model's "
                f"{_fmt(b['nominal'])} -{_fmt(b['size'][0])}/+{_fmt(b['size'][1])}): there, "
                f"but too small to change the model, so the verdict is `none`.")
    c = report.get("confirmation")
    if c and c["confirmed"]:
        out += (f" Confirmed on {c['windows']} held-out windows the fit never used: "
                f"{c['name']} beats the unmodified model there (cluster z "
                f"{c['z_vs_none']:.2f}, {100 * c['reduction']:.1f}% less error), so `none` "
                f"is not kept beside it.")
    elif c and c.get("nuisance_rivals"):         # computed only when it beat `none`
        r = min(c["nuisance_rivals"], key=lambda r: r["z_effect_vs_it"])
        out += (f" Not confirmed: {c['name']} beats the unmodified model on "
                f"{c['windows']} held-out windows (cluster z {c['z_vs_none']:.2f}), but the "
                f"nuisance {r['name']}, fitted as it was, explains that gain as well (z "
                f"{r['z_effect_vs_it']:.2f} for the effect against it), so `none` stays.")
    for b in (b for b in report.get("beyond_size", []) if b["beyond"]):
        out += (f" Beyond its size that matters on held-out windows the fit never used: "
                f"{b['name']} = {_fmt(b['value'])} beats both the unmodified model (cluster "
                f"z {b['z_vs_none']:.2f}) and the model fixed at {_fmt(b['size'])} (z "
                f"{b['z_vs_size']:.2f})"
                + (f", each with {', '.join(b['fitted_beside'])} fitted beside it"
                   if b.get("fitted_beside") else "") + ", so `none` is not kept beside it.")
    gone = [r for r in report.get("left_out_rivals", []) if r["dropped"]]
    if gone:
        out += (" Clearly worse than another effect of the set on held-out windows the "
                "fit never used, so not kept: "
                + ", ".join(f"{r['name']} (against {r['beaten_by']}: cluster z "
                            f"{r['z']:.2f} on {r['windows']} windows)" for r in gone) + ".")
    stay = [r for r in report.get("left_out_rivals", []) if r.get("kept")]
    if stay:
        out += (" Beaten there but kept: " + ", ".join(
            f"{r['name']} (by {r['beaten_by']}, cluster z {r['z']:.2f}; {r['kept']})"
            for r in stay) + ".")
    u = report.get("against_user_model")
    if u and u["joined"]:
        out += (f" Its own held-out rollouts are clearly worse than the model as given "
                f"(SSR {_fmt(u['after'])} against {_fmt(u['before'])} in noise units over "
                f"{u['episodes']} episodes, paired z {u['z']:.2f}), so `none` is kept "
                f"beside it.")
    if report.get("verdict") != "ambiguous":
        return out
    names = ", ".join(f"{a['name']}{'[' + a['target'] + ']' if a['target'] else ''} "
                      f"(held-out {_fmt(a['held_out_score'])}{_member_note(a)})"
                      for a in report["ambiguous"])
    fix = "; ".join(f"{' vs '.join(p['between'])}: {p['change']}"
                    for p in report["separating_excitation"])
    gait = any("excitation" in p for p in report["separating_excitation"])
    return out + (f" AMBIGUOUS: the held-out data do not favour one of {names} beyond "
                  f"their uncertainty; the first is only the best-scoring. To separate "
                  f"them: {fix}. Record that{GAIT_NOTE if gait else ''} and diagnose both "
                  f"recordings together (`adaptive-c3 diagnose THIS.npz --also NEW.npz "
                  f"--scenario ...`).")


def _member_note(member) -> str:
    """The 95 % interval of a member that joined because `none` cannot rule it out, or
    its `reason` (evidence.require_support: the chosen effect's interval holds the
    model's value)."""
    if "ci95" not in member:
        return f"; {member['reason']}" if "reason" in member else ""
    lo, hi = member["ci95"]
    return f"; not excluded: 95% interval {_fmt(lo)} to {_fmt(hi)}"


GAIT_NOTE = " (separating_excitation[].excitation: the push gait's fields to change)"


def backend_summary(report) -> str:
    """Which model was diagnosed and, for another backend than the LCS, what each finding
    means for the controller's LCS (an empty string for an lcs diagnosis)."""
    if report.get("model_backend", "lcs") == "lcs":
        return ""
    text = f"Model diagnosed: {report['model_backend']} ({report['model_description']}). "
    if report["lcs_counterpart"]:
        text += "For the controller's LCS: " + "; ".join(
            f"{c['effect']} -> {c['lcs']}" for c in report["lcs_counterpart"]) + ". "
    return text


def plain_summary(result, selected) -> str:
    eb, ea = result["error_before"], result["error_after"]
    rb, ra = eb["rollout"]["normalised_rms"], ea["rollout"]["normalised_rms"]
    sb, sa = eb["one_step"]["normalised_rms"], ea["one_step"]["normalised_rms"]
    units = ("(held-out: cross-validated over episodes; RMS in units of the noise floor, "
             "where 1 means as good as the sensor noise allows)")
    if selected[0]["name"] == "none":
        best = min(result["fits"], key=lambda f: f.score, default=None)
        tail = (f" The best candidate, {best.label()}, changed the held-out error by only "
                f"{100 * best.reduction:.2g}%." if best is not None else "")
        return (f"No effect in the library improves the held-out predictions beyond the noise "
                f"floor: the model and the recording agree up to sensor noise (one-step error "
                f"{_fmt(sb)}, {result['horizon']}-step rollout error {_fmt(rb)} {units})." + tail)
    parts = []
    for e in selected:
        d = EFFECTS[e["name"]].description
        vals = ", ".join(f"{_fmt(p['value'])} {p['unit']} (95% interval {_fmt(p['ci95'][0])} "
                         f"to {_fmt(p['ci95'][1])})" for p in e["params"])
        where = f" on {e['target']}" if e["target"] else ""
        parts.append(f"{e['name'].replace('_', ' ')}{where} ({d}) of about {vals}")
    ww = len(result["mismatch_windows"])
    xb, xa = eb["rollout"]["excess_over_noise"], ea["rollout"]["excess_over_noise"]
    return (f"The model leaves out {' and '.join(parts)}. Adding it cuts the held-out "
            f"{result['horizon']}-step rollout error from {_fmt(rb)} to {_fmt(ra)} and the "
            f"one-step error from {_fmt(sb)} to {_fmt(sa)} {units}; the rollout error above "
            f"the noise floor goes from {_fmt(xb)} to {_fmt(xa)}. The recording and the "
            f"model disagree beyond the noise floor in {ww} window(s) listed below.")


# ------------------------------------------------------------------ writing
def write_report(out: Path, rec, result, scenario_notes=()) -> dict:
    spec = result["spec"]
    selected = selected_rows(result)
    report = dict(
        model=spec.name, model_backend=result.get("model_backend", "lcs"),
        model_description=result.get("model_description", ""),
        lcs_counterpart=result.get("lcs_counterpart", []),
        horizon_steps=result["horizon"], dt=spec.dt, split=result["split"],
        recording=dict(samples=int(len(rec.t)), episodes=len(list(rec.episodes()))),
        scenario_effects=[dict(name=c.name, target=c.target, value=[float(v) for v in p])
                          for c, p in result["base"]
                          if all(c not in f.cands for f in result.get("nuisance", []))],
        nuisance=[dict(effect_params(f, spec)[0], ssr_reduction=float(f.reduction),
                       note=NUISANCE_NOTES.get(f.cands[0].name, NUISANCE_NOTES[""]))
                  for f in result.get("nuisance", [])],
        noise_floor={n: float(s) for n, s in zip(spec.state_names,
                                                 result.get("sigma_report", result["sigma"]))},
        noise_floor_one_step={n: float(s) for n, s in zip(spec.state_names, result["sigma"])},
        mismatch_windows=result["windows"],
        mismatch_windows_total=int(result["steps"]["total_windows"]),
        contact_agreement=result["contact"],
        candidates=candidate_rows(result),
        free_window_candidates=candidate_rows(result, "fits_free"),
        not_applicable=[dict(name=k, reason=v) for k, v in result["not_applicable"].items()],
        selected=selected, **_judged(result),
        error_before=result["errors"]["before"], error_after=result["errors"]["after"],
        patched_scenario="patched_scenario.yaml", patched_scenario_notes=list(scenario_notes),
        seconds=float(result["seconds"]))
    result["error_before"], result["error_after"] = report["error_before"], report["error_after"]
    result["mismatch_windows"] = result["windows"]
    report["summary"] = (backend_summary(report) + plain_summary(result, selected)
                         + ambiguity_summary(report))
    (out / "report.json").write_text(json.dumps(report, indent=1))
    files = report_plots(out, rec, result)
    _write_html(out / "report.html", report, files)
    return report


def embedded_figures(files) -> str:
    """HTML figures with the PNG files inlined (a report is one self-contained file)."""
    return "".join(
        f"<figure><img src='data:image/png;base64,{base64.b64encode(Path(f).read_bytes()).decode()}'"
        f" style='max-width:100%'><figcaption>{html.escape(Path(f).name)}</figcaption></figure>"
        for f in files)


def _write_html(path: Path, report: dict, files: list) -> None:
    esc = html.escape
    rows = "".join(
        f"<tr><td>{esc(c['name'])}</td><td>{esc(c['target'])}</td><td>"
        + "; ".join(f"{p['name']}={_fmt(p['value'])} {esc(p['unit'])} "
                    f"[{_fmt(p['ci95'][0])}, {_fmt(p['ci95'][1])}]"
                    for e in c["effects"] for p in e["params"])
        + f"</td><td>{_fmt(c['held_out_error']['normalised_rms'])}</td>"
        f"<td>{100 * c['held_out_error']['ssr_reduction']:.1f}%</td>"
        f"<td>{c['penalty_score']:.1f}</td><td>{'yes' if c['significant'] else ''}</td></tr>"
        for c in report["candidates"])
    wins = "".join(
        f"<tr><td>{w['episode']}</td><td>{w['start']:.2f}</td><td>{w['end']:.2f}</td>"
        f"<td>{esc(', '.join(w['coordinates']))}</td><td>{esc(', '.join(w['contact_pairs']))}</td>"
        f"<td>{esc(json.dumps(w['contact']))}</td></tr>" for w in report["mismatch_windows"])
    na = "".join(f"<li><b>{esc(n['name'])}</b>: {esc(n['reason'])}</li>"
                 for n in report["not_applicable"])
    imgs = embedded_figures(files)
    path.write_text(f"""<!doctype html><html><head><meta charset="utf-8">
<title>adaptive-c3 diagnose: {esc(report['model'])}</title>
<style>body{{font-family:sans-serif;max-width:1100px;margin:auto}}
td,th{{border:1px solid #ccc;padding:2px 6px;font-size:12px}} table{{border-collapse:collapse}}</style>
</head><body><h1>Model / recording mismatch: {esc(report['model'])}</h1>
<p><b>{esc(report['summary'])}</b></p>
<p>Noise floor estimated from the data (sensor noise std per state):
{esc(json.dumps({k: float(f'{v:.3g}') for k, v in report['noise_floor'].items()}))}.
Held-out data: {esc(report['split'])}. Patched scenario: patched_scenario.yaml
({esc('; '.join(report['patched_scenario_notes']) or 'unchanged')}).</p>
{imgs}
<h2>Candidates (values fitted on all data; errors cross-validated: each part predicted by
parameters fitted on the other parts)</h2>
<table><tr><th>effect</th><th>target</th><th>value [95% interval]</th>
<th>held-out RMS / noise</th><th>SSR reduction</th><th>penalised score</th><th>significant</th></tr>
{rows}</table>
<p>Not applicable to this model:</p><ul>{na}</ul>
<h2>Mismatch windows ({report['mismatch_windows_total']} found, the worst
{len(report['mismatch_windows'])} listed)</h2>
<table><tr><th>episode</th><th>start (s)</th><th>end (s)</th><th>coordinates</th>
<th>contact pairs</th><th>contact steps (both / model only / data only)</th></tr>{wins}</table>
</body></html>""")
