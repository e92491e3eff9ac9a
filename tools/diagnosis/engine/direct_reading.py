"""Sizes read directly from the recording, where a task can measure an effect without the
model: a member beside `none` is ruled out when its reading lies within its size that
matters, and `none` leaves the set when the reading lies beyond it.

The rollout size tests (boundary.excluded, beyond_size) score the model fixed at a size
against `none`. For the ball's mass they trade against the contact's stiffness and
damping fitted beside it (profiled_size): scaling the mass and the stiffness together
keeps the contact's frequency, so on the free ball's motion the two are nearly one
parameter, and the tests left the mass beside `none` on 10 of the 13 undecided draws of
the forty-sixth and forty-seventh sets (all with `none` the right answer). A task that can
read the effect from a balance that holds whatever the contact model (the ball task: the
EE's impulses against the ball's angular momentum about its table contact,
tasks/ball_rolling/momentum_audit.py) offers it as spec.direct_reading(cand, rec) -> a
reading with `.scale`, `.sd`, `.interval(z)` and `.details()` (a dict the record adds),
or None.

The tests: the reading's interval at evidence.size_z (one-sided 5 % on each side, as
the rollout size tests; widened by the reading's own model-form error) lies within the
size that matters on both sides -> the member is ruled out (ruled_out_members takes it
out, as for a size the rollouts ruled out); it lies beyond the size -> `none` leaves the
set (as beyond_size). Recorded as judged["direct_readings"].
"""
from __future__ import annotations

from adaptive_c3.tools.diagnosis.backends.effects import Candidate
from adaptive_c3.tools.diagnosis.engine.beyond_size import take_none_out
from adaptive_c3.tools.diagnosis.engine.boundary import holds_none, size_that_matters


def read_directly(judged, spec, rec, z: float) -> list[dict]:
    """Read each member of an ambiguous set holding `none` that the task can read
    directly (spec.direct_reading); records judged["direct_readings"] (name, value, sd,
    interval, the sizes, within / beyond) and returns it ([] when nothing was read)."""
    read = getattr(spec, "direct_reading", None)
    if read is None or not holds_none(judged):
        return []
    out = []
    for a in judged["ambiguous"]:
        if a["name"] == "none":
            continue
        c = Candidate(a["name"], a["target"])
        size = size_that_matters(spec, c)
        r = read(c, rec) if size is not None else None
        if r is None:
            continue
        nominal = float(c.nominal(spec)[0])
        below, above = nominal - size[0], nominal + size[1]
        lo, hi = r.interval(z)
        out.append(dict(name=c.label(), value=float(r.scale), sd=float(r.sd),
                        interval=[float(lo), float(hi)], sizes=[float(below), float(above)],
                        within=bool(below < lo and hi < above),
                        beyond=bool(hi < below or lo > above), **r.details()))
    if out:
        judged["direct_readings"] = out
    return out


def shown_directly(judged, fits):
    """Take `none` out of an ambiguous set when a member's direct reading lies beyond its
    size that matters; returns that member's fit (the answer when it is then alone, else
    the lead of the set), or None."""
    if not holds_none(judged):
        return None
    beyond = {r["name"] for r in judged.get("direct_readings", []) if r["beyond"]}
    by_label = {f.label(): f for f in fits if len(f.cands) == 1}
    for a in judged["ambiguous"]:
        label = Candidate(a["name"], a["target"]).label() if a["name"] != "none" else None
        if label in beyond and label in by_label:
            return take_none_out(judged, a, by_label[label])
    return None
