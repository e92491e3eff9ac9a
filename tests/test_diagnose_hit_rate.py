"""Proof on concealed effects (issue 6): hit rate of `diagnose` and of the SINDy baseline.

Each draw: the harness picks an effect of the library (or none) and its size from a
seed, makes a cart-pole recording with it (tools/diagnosis/harness/concealed_data.py), runs the diagnosis
and the baseline on the recording alone, and scores them against the truth:
  named        exactly one effect selected, with the concealed name and target
               (r_comp never counts as contact_offset; a pair never counts as a single)
  in_interval  named, and the true value inside the reported 95% interval
  clean_cut    cross-validated rollout error of the original / the patched model,
               measured against the noise-free truth
The slow test runs >= 30 random draws plus clean draws (`pytest -m slow`); the fast one
a few draws in the default run.
"""
import json
import os

import numpy as np
import pytest

from adaptive_c3.tools.diagnosis.harness.concealed_data import DRAWABLE, hit_rates, score_draw


def _run(seeds, **kw):
    rows = [score_draw(s, **kw) for s in seeds]
    return rows, hit_rates(rows)


def _check(summary, rows):
    eff = [r for r in rows if r["truth"]["name"] != "none"]
    assert summary["named"] >= 0.9, summary
    assert all(r["named"] for r in rows if r["truth"]["name"] == "none"), "none on clean data"
    assert np.mean([r["clean_cut"] >= 5 for r in eff if r["named"]]) >= 0.9, summary


def test_hit_rate_fast():
    """A few draws (random effects, and a clean one) in the default run."""
    rows, summary = _run([1003, 1009, 1024])
    _check(summary, rows)


@pytest.mark.slow
def test_hit_rate_slow(tmp_path):
    """45 random draws + one draw per drawable effect + 10 clean draws."""
    rows, _ = _run(range(2000, 2045))
    rows += [score_draw(3000 + i, name=n, target=t) for i, (n, t) in enumerate(DRAWABLE)]
    rows += [score_draw(4000 + i, name="none") for i in range(10)]
    summary = hit_rates(rows)
    out = os.environ.get("ADAPTIVE_C3_HIT_RATE_JSON") or str(tmp_path / "hit_rate.json")
    with open(out, "w") as f:
        json.dump(dict(summary=summary, rows=rows), f, indent=1, default=float)
    print(json.dumps(summary, indent=1))
    assert summary["draws"] >= 30
    _check(summary, rows)
    assert summary["in_interval"] >= 0.85, summary
