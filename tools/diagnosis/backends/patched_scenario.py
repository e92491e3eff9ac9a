"""The scenario YAML with a diagnosis's chosen effects in it (the rules: the module
docstring of tools/diagnosis/diagnose.py, "Patched scenarios")."""
from __future__ import annotations

import numpy as np
import yaml


def patched_scenario_text(scenario_text: str, spec, base, chosen) -> tuple[str, list]:
    """The scenario YAML with the chosen effects in it; returns (text, notes)."""
    data = yaml.safe_load(scenario_text) or {}
    if hasattr(spec, "patch_scenario"):      # e.g. the drake backend: its `drake:` section
        notes = spec.patch_scenario(data, chosen.effects(spec) if chosen else [])
        return yaml.safe_dump(data, sort_keys=False), notes
    data.pop("effects", None)
    effects = [(c, np.asarray(p, float)) for c, p in base]
    notes, intervals = [], {}
    if chosen is not None:
        for (c, p), lo_hi in zip(chosen.effects(spec), _split_ci(chosen, spec)):
            model = data.setdefault("model", {})
            if c.name == "contact_offset" and spec.name == "cartpole":
                err = list(model.get("wall_offset_error", [0.0, 0.0]))
                i = spec.pair_names.index(c.target)
                err[i] = float(err[i] - p[0])      # model c = wall_distance - error
                model["wall_offset_error"] = err
                notes.append(f"contact_offset[{c.target}] -> model.wall_offset_error[{i}]")
            elif c.name == "contact_stiffness" and spec.name == "cartpole":
                model["wall_stiffness"] = float(p[0])
                notes.append("contact_stiffness[walls] -> model.wall_stiffness")
            elif c.name == "contact_offset" and c.target == "ee_ball":
                model["ee_radius"] = float(spec.params.ee_radius - p[0])   # gap + offset
                notes.append("contact_offset[ee_ball] -> model.ee_radius")
            elif c.name == "mass_scale" and spec.name == "ball_rolling":
                model["ball_mass"] = float(spec.params.ball_mass * p[0])
                notes.append("mass_scale[ball] -> model.ball_mass")
            else:
                effects.append((c, p))
                intervals[c] = lo_hi
    if effects:
        data["effects"] = [dict(name=c.name, target=c.target,
                                value=[float(v) for v in p] if len(p) > 1 else float(p[0]),
                                unit=c.units(spec)[0]) for c, p in effects]
        for entry, (c, _) in zip(data["effects"], effects):
            if c in intervals:
                entry["ci95"] = [[float(a), float(b)] for a, b in intervals[c]]
        notes.append("effects: list (read by `diagnose`, not by the scenario schema)")
    return yaml.safe_dump(data, sort_keys=False), notes


def _split_ci(fit, spec):
    out, i = [], 0
    for c in fit.cands:
        p = c.num_params(spec)
        out.append(fit.ci[i:i + p])
        i += p
    return out
