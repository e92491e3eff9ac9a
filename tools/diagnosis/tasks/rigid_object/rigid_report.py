"""The report of a rigid-object diagnosis: report.json, report.html (with plots), the
patched scenario, and the plain-words summary (tools/diagnosis/tasks/rigid_object/rigid_diagnose.py)."""
from __future__ import annotations

import html
import json
from pathlib import Path

import numpy as np
import yaml

from adaptive_c3.tools.diagnosis.engine.report import embedded_figures


def _sure(gain: dict) -> str:
    """'clearly' when even the low end of the gain's interval is 5 % of the error."""
    return "clearly" if gain["relative_ci95"][0] >= 0.05 else "probably"


MODEL_WORDS = {"lcs": "the controller's rigid LCS", "drake": "Drake's SAP simulation"}


def _refitted(s: dict) -> str:
    """', with KEY re-fitted to VALUE' for a two-parameter effect, else ''."""
    return "".join(f", with {k} re-fitted to {v:.4g}" for k, v in (s.get("refitted") or {}).items())


def _effect_words(s: dict) -> str:
    g = s["validation_gain"]
    return (f"{s['physics']} ({s['name']} = {s['value']:.4g} {s['unit']}{_refitted(s)}, 95 % "
            f"interval [{s['ci95'][0]:.4g}, {s['ci95'][1]:.4g}]; {_sure(g)}: validation "
            f"error down {100 * g['relative']:.0f} %, 95 % interval of the gain "
            f"[{g['ci95'][0]:.2f}, {g['ci95'][1]:.2f}] % of size)")


def lcs_meaning(selected: list) -> list[str]:
    """For a drake diagnosis: what each selected effect means for the controller's LCS."""
    out = []
    for s in selected:
        if s.get("lcs", "").startswith(("contact.", "patch.")):
            out.append(f"{s['name']}: LCS patch {s['lcs']} = {s['value']:.4g}")
        else:
            out.append(f"{s['name']}: {s.get('lcs') or 'no LCS counterpart'}")
        if "drake.friction" in (s.get("refitted") or {}):
            out.append(f"{s['name']}'s re-fitted friction: LCS patch contact.friction = "
                       f"{s['refitted']['drake.friction']:.4g}")
    return out


def plain_summary(result: dict) -> str:
    held = result["held_out"]
    model = result.get("model", "lcs")
    words = MODEL_WORDS.get(model, model)
    before = held["nominal"]["summary"]["position_pct_mean_median"]
    after = held["diagnosed"]["summary"]["position_pct_mean_median"]
    n = held["nominal"]["summary"]["episodes"]
    head = f"Model diagnosed: {model} ({words}); starts: {result.get('initial_state', 'first-row')}. "
    if not result["selected"]:
        first = result["rounds"][0] if result["rounds"] else None
        names = ", ".join(t["name"] for t in (first or {}).get("tries") or []) or (
            first["candidates"][0]["name"] if first else "")
        tail = (f" The best candidates on the fit episodes ({names}) did not improve the "
                "validation episodes enough to be kept." if first else "")
        return (head + f"No effect in the library explains the mismatch better than the plain "
                f"model on episodes it was not fitted on.{tail} Held-out median position error "
                f"{before:.1f} % of the object's size ({n} episodes).")
    physics = [s for s in result["selected"] if s.get("kind", "physics") == "physics"]
    nuisance = [s for s in result["selected"] if s.get("kind") == "nuisance"]
    text = head
    if physics:
        text += f"{words[0].upper() + words[1:]} leaves out: " + "; then ".join(
            _effect_words(s) for s in physics) + ". "
    if nuisance:
        text += "Nuisances fitted (not missing physics): " + "; ".join(
            _effect_words(s) for s in nuisance) + ". "
    g = result.get("held_out_gain")
    gain = (f" (paired per-episode drop {g['drop']:.2f}, 95 % interval [{g['ci95'][0]:.2f}, "
            f"{g['ci95'][1]:.2f}] % of size)" if g else "")
    text += (f"On {n} held-out episodes the median mean-over-time position error goes "
             f"{before:.1f} % -> {after:.1f} % of the object's size{gain}.")
    if model == "drake":
        text += " For the controller's LCS: " + "; ".join(lcs_meaning(result["selected"])) + "."
    return text


def patched_scenario_text(scenario_text: str, chosen: dict) -> str:
    data = yaml.safe_load(scenario_text) or {}
    from adaptive_c3.tools.diagnosis.tasks.rigid_object.rigid_effects import set_key
    for key, value in chosen.items():
        set_key(data, key, value, as_dict=True)
    notes = ", ".join(f"{k} = {v:.4g}" for k, v in chosen.items()) or "no effect selected"
    return ("# written by adaptive-c3 diagnose: " + notes + "\n"
            + yaml.safe_dump(data, sort_keys=False))


def report_dict(result: dict) -> dict:
    split = result["split"]
    return dict(
        task="rigid_object", model=result.get("model", "lcs"),
        initial_state=result.get("initial_state"), dt=result["dt"], object_size_m=result["size"],
        split=dict(fit=split["fit"], validation=split["validation"], held_out=split["held_out"],
                   fit_episodes_used=result["fit_episodes"],
                   twins=[list(p) for p in split["twins"]],
                   note="episodes split held-out / validation / fit, twin episodes (copies "
                        "up to a yaw and a shift) kept on one side"),
        mismatch=result["located"],
        rounds=[dict(tried=r["tried"], accepted=r["accepted"], validation_gain=r["validation_gain"],
                     tries=r.get("tries"),
                     candidates=[{k: c.get(k) for k in ("name", "key", "value", "ci95", "unit",
                                                        "refitted", "fit_mean",
                                                        "fit_gain_relative", "physics")}
                                 for c in r["candidates"]]) for r in result["rounds"]],
        selected=[{k: s.get(k) for k in ("name", "key", "value", "ci95", "unit", "refitted",
                                         "physics", "kind", "lcs", "validation_gain")}
                  for s in result["selected"]],
        lcs_meaning=(lcs_meaning(result["selected"]) if result.get("model") == "drake" else None),
        held_out_gain=result.get("held_out_gain"),
        not_identifiable=[dict(name=k, reason=v) for k, v in result["not_identifiable"].items()],
        held_out={k: v["summary"] for k, v in result["held_out"].items()},
        held_out_per_episode={k: v["per_episode"] for k, v in result["held_out"].items()},
        drake_tuned_values=result.get("drake_tuned"),
        patched_scenario="patched_scenario.yaml",
        summary=plain_summary(result), seconds=float(result["seconds"]))


def _plots(out: Path, result: dict, rollouts: dict) -> list:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    files = []
    loc = result["located"]
    if loc.get("phases"):
        fig, ax = plt.subplots(figsize=(6, 3.5))
        names = list(loc["phases"])
        med = [loc["phases"][n]["one_step_velocity_error_mps_median"] for n in names]
        p90 = [loc["phases"][n]["one_step_velocity_error_mps_p90"] for n in names]
        xs = np.arange(len(names))
        ax.bar(xs - 0.2, med, 0.4, label="median")
        ax.bar(xs + 0.2, p90, 0.4, label="90th percentile")
        ax.axhline(3 * loc["noise_floor_mps"], color="k", ls="--", label="3 x flight level")
        ax.set_xticks(xs, names)
        ax.set_ylabel("one-step velocity error [m/s]")
        ax.set_title("where the model disagrees (fit episodes)")
        ax.legend(fontsize=8)
        fig.tight_layout()
        files.append(_save(fig, out / "mismatch_by_phase.png"))
    if result["rounds"]:
        fig, axes = plt.subplots(1, len(result["rounds"]), figsize=(4.5 * len(result["rounds"]), 3.5),
                                 squeeze=False)
        for ax, r in zip(axes[0], result["rounds"]):
            c = r["candidates"]
            ax.barh([x["name"] for x in c], [100 * x["fit_gain_relative"] for x in c])
            ax.set_xlabel("fit-episode error reduction [%]")
            ax.set_title(f"tried {r['tried']}: {'kept' if r['accepted'] else 'rejected'}", fontsize=9)
        fig.tight_layout()
        files.append(_save(fig, out / "candidates.png"))
    held = result["held_out"]
    fig, ax = plt.subplots(figsize=(6, 3.5))
    ax.boxplot([[e["position_pct_mean"] for e in held[k]["per_episode"]] for k in held],
               tick_labels=list(held))
    ax.set_ylabel("mean position error [% of size]")
    ax.set_title("held-out episodes")
    fig.tight_layout()
    files.append(_save(fig, out / "held_out_errors.png"))
    if rollouts:
        fig, axes = plt.subplots(1, len(rollouts), figsize=(4 * len(rollouts), 3.5), squeeze=False)
        for ax, (e, r) in zip(axes[0], rollouts.items()):
            ax.plot(r["t"], r["data"][:, 2], "k.", ms=3, label="data")
            for k in held:
                ax.plot(r["t"], r[k][:, 2], label=k)
            ax.set_title(f"held-out episode {e}")
            ax.set_xlabel("t [s]")
            ax.set_ylabel("centre height [m]")
            ax.legend(fontsize=7)
        fig.tight_layout()
        files.append(_save(fig, out / "held_out_rollouts.png"))
    return files


def _save(fig, path: Path) -> Path:
    import matplotlib.pyplot as plt
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def write_report(out: Path, result: dict, scenario_text: str, rollouts: dict) -> dict:
    out = Path(out)
    report = report_dict(result)
    (out / "report.json").write_text(json.dumps(report, indent=1))
    (out / "patched_scenario.yaml").write_text(patched_scenario_text(scenario_text, result["chosen"]))
    files = _plots(out, result, rollouts)
    esc = html.escape
    rows = "".join(
        f"<tr><td>{i + 1}</td><td>{esc(c['name'])}</td><td>{c['value']:.4g} {esc(c['unit'])} "
        f"[{c['ci95'][0]:.4g}, {c['ci95'][1]:.4g}]</td><td>{c['fit_mean']:.2f}</td>"
        f"<td>{100 * c['fit_gain_relative']:.1f} %</td><td>{esc(c['physics'])}</td></tr>"
        for i, r in enumerate(report["rounds"]) for c in r["candidates"])
    wins = "".join(
        f"<tr><td>{w['episode']}</td><td>{w['start']:.3f}</td><td>{w['end']:.3f}</td>"
        f"<td>{esc(w['phase'])}</td><td>{w['mean_error_mps']:.3f}</td>"
        f"<td>{w['model_contact_steps']} / {w['data_contact_steps']}</td></tr>"
        for w in report["mismatch"].get("windows", []))
    held = "".join(
        f"<tr><td>{esc(k)}</td><td>{v['position_pct_mean_median']:.2f}</td>"
        f"<td>{v['position_pct_mean_mean']:.2f}</td><td>{v['position_pct_final_median']:.2f}</td>"
        f"<td>{v['orientation_deg_mean_median']:.2f}</td></tr>" for k, v in report["held_out"].items())
    na = "".join(f"<li><b>{esc(n['name'])}</b>: {esc(n['reason'])}</li>"
                 for n in report["not_identifiable"])
    imgs = embedded_figures(files)
    s = report["split"]
    (out / "report.html").write_text(f"""<!doctype html><html><head><meta charset="utf-8">
<title>adaptive-c3 diagnose: rigid object ({esc(report['model'])})</title>
<style>body{{font-family:sans-serif;max-width:1100px;margin:auto}}
td,th{{border:1px solid #ccc;padding:2px 6px;font-size:12px}} table{{border-collapse:collapse}}</style>
</head><body><h1>Model / recording mismatch: rigid object, model {esc(report['model'])}</h1>
<p><b>{esc(report['summary'])}</b></p>
<p>Episodes: {len(s['fit'])} fit ({len(s['fit_episodes_used'])} used), {len(s['validation'])}
validation, {len(s['held_out'])} held out; {len(s['twins'])} twin pairs kept together.</p>
<h2>Held-out episodes</h2><table><tr><th>model</th><th>position % (median)</th>
<th>position % (mean)</th><th>final position % (median)</th><th>orientation deg (median)</th></tr>
{held}</table>{imgs}
<h2>Candidates, round by round (values fitted on the fit episodes)</h2>
<table><tr><th>round</th><th>effect</th><th>value [95 % interval]</th><th>fit error %</th>
<th>reduction</th><th>physics</th></tr>{rows}</table>
<p>Not tried:</p><ul>{na}</ul>
<h2>Mismatch windows ({report['mismatch'].get('windows_total', 0)} found, the largest listed)</h2>
<table><tr><th>episode</th><th>start (s)</th><th>end (s)</th><th>phase</th><th>mean error (m/s)</th>
<th>contact steps model / data</th></tr>{wins}</table>
</body></html>""")
    return report
