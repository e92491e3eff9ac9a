"""Test recordings with a concealed effect: the proof harness of `diagnose`.

A recording is made by the *nominal* cart-pole LCS of a scenario plus ONE effect of
the library (or none), drawn with its size from a seed. The true system is written
here independently of the diagnosis code (`effects`), though with the same
physical laws (a nominal LCS plus the effect, as the issue asks): stick-slip Coulomb
friction, a contact damper acting only while touching, delays on the zero-order-held
input, masses that change the whole linearisation. The differences to the diagnosis
are the sensor noise, the closed loop on noisy states, and what the excitation reveals. Excitation: several episodes from random initial states, an LQR
(designed on the nominal model) tracking random cart targets, some of which put the
pole tip into the walls, plus band-limited input noise and random pushes. The
controller sees noisy states; the recording holds noisy states (sensor noise of
encoder / differentiated-velocity size, scaled by a random factor) and the commanded
inputs. The truth is returned beside the recording and never written into it.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from adaptive_c3.models.cartpole import (CartpoleParams, INPUT_NAMES, STATE_NAMES,
                                         cartpole_lcs)
from adaptive_c3.scenarios.schema import SCENARIO_DIR
from adaptive_c3.tools.recording import Recording

DEFAULT_SCENARIO = SCENARIO_DIR / "cartpole_softwalls.yaml"
NOISE_STD = np.array([5e-4, 1e-3, 1e-2, 2e-2])   # m, rad, m/s, rad/s

# (name, target) pairs that can be concealed, and how their size is drawn.
DRAWABLE = [
    ("none", ""),
    ("contact_offset", "right_wall"), ("contact_offset", "left_wall"),
    ("contact_stiffness", "walls"), ("contact_damping", "walls"),
    ("viscous_damping", "cart_x"), ("viscous_damping", "pole_theta"),
    ("coulomb_friction", "cart_x"), ("coulomb_friction", "pole_theta"),
    ("mass_scale", "cart"), ("mass_scale", "pole"),
    ("actuator_gain", ""), ("actuator_delay", ""),
    ("external_force", "cart_x"), ("external_force", "pole_theta"),
]
UNITS = {"contact_offset": "m", "contact_stiffness": "N/m", "contact_damping": "N*s/m",
         "mass_scale": "1", "actuator_gain": "1", "actuator_delay": "s"}


@dataclass
class Truth:
    name: str
    target: str
    value: float
    unit: str

    def as_dict(self):
        return dict(name=self.name, target=self.target, value=self.value, unit=self.unit)


def _either(rng, lo, hi, lo2, hi2):
    return rng.uniform(lo, hi) if rng.random() < 0.5 else rng.uniform(lo2, hi2)


def draw_effect(rng, name: str | None = None, target: str | None = None,
                ks: float = 50.0) -> Truth:
    """Draw (or take) an effect and draw its size."""
    if name is None:
        name, target = DRAWABLE[rng.integers(len(DRAWABLE))]
    sign = 1.0 if rng.random() < 0.5 else -1.0
    rot = target == "pole_theta"
    if name == "none":
        return Truth("none", "", 0.0, "")
    value = {
        "contact_offset": lambda: sign * rng.uniform(0.03, 0.12),
        "contact_stiffness": lambda: ks * _either(rng, 0.3, 0.6, 1.8, 4.0),
        "contact_damping": lambda: rng.uniform(3.0, 15.0),
        "viscous_damping": lambda: rng.uniform(0.02, 0.1) if rot else rng.uniform(0.5, 3.0),
        "coulomb_friction": lambda: rng.uniform(0.01, 0.06) if rot else rng.uniform(0.3, 2.0),
        "mass_scale": lambda: _either(rng, 0.6, 0.8, 1.25, 1.6),
        "actuator_gain": lambda: _either(rng, 0.6, 0.85, 1.15, 1.4),
        "actuator_delay": lambda: rng.uniform(0.01, 0.05),
        "external_force": lambda: sign * (rng.uniform(0.02, 0.15) if rot else rng.uniform(0.3, 2.0)),
    }[name]()
    unit = UNITS.get(name) or ("N*m" if rot else "N")
    if name == "viscous_damping":
        unit += "*s/rad" if rot else "*s/m"
    return Truth(name, target or "", float(value), unit)


class TrueCartpole:
    """The system that makes the data: nominal cart-pole LCS + the concealed effect."""

    def __init__(self, params: CartpoleParams, truth: Truth):
        self.truth = truth
        p = params
        if truth.name == "mass_scale":
            key = "mc" if truth.target == "cart" else "mp"
            p = replace(p, **{key: getattr(p, key) * truth.value})
        if truth.name == "contact_stiffness":
            p = replace(p, wall_stiffness=truth.value)
        self.p = p
        self.lcs = cartpole_lcs(p)
        self.c = self.lcs.c.copy()
        if truth.name == "contact_offset":
            self.c[0 if truth.target == "right_wall" else 1] += truth.value
        mc, mp, lc = p.mc, p.mp, p.lc
        self.minv = np.array([[1 / mc, 1 / (mc * lc)], [1 / (mc * lc), (mc + mp) / (mc * mp * lc * lc)]])
        self.coord = {"cart_x": 0, "pole_theta": 1}.get(truth.target, 0)
        self.u_hist: list = []

    def applied_input(self, u: float) -> float:
        """The input the plant feels this step (gain, zero-order-held delay)."""
        t = self.truth
        self.u_hist.append(u)
        if t.name == "actuator_gain":
            return t.value * u
        if t.name == "actuator_delay":
            s = t.value / self.p.dt
            n, a = int(np.floor(s)), s - np.floor(s)
            h = self.u_hist
            u0 = h[max(len(h) - 1 - n, 0)]
            u1 = h[max(len(h) - 2 - n, 0)]
            return (1 - a) * u0 + a * u1    # the held input over this step, averaged
        return u

    def step(self, x: np.ndarray, u: float) -> np.ndarray:
        L, t, dt = self.lcs, self.truth, self.p.dt
        ua = np.array([self.applied_input(u)])
        gap = L.E @ x + self.c
        lam = np.maximum(0.0, -gap / np.diag(L.F))
        if t.name == "contact_damping":          # spring || damper while touching, no pull
            pen_rate = -(L.E[:, :2] @ x[2:])
            lam = np.where(gap < 0, np.maximum(0.0, lam + t.value * pen_rate), 0.0)
        x_next = L.A @ x + L.B @ ua + L.D @ lam
        tau = np.zeros(2)
        if t.name == "viscous_damping":
            tau[self.coord] = -t.value * x[2 + self.coord]
        elif t.name == "external_force":
            tau[self.coord] = t.value
        elif t.name == "coulomb_friction":
            j = self.coord            # exact stick-slip: friction cannot reverse the motion
            v_free = x_next[2 + j]
            cap = abs(v_free) / (dt * self.minv[j, j])
            tau[j] = -np.sign(v_free) * min(t.value, cap)
        return x_next + np.concatenate([[0.0, 0.0], dt * self.minv @ tau])


def _lqr_gain(lcs):
    from scipy.linalg import solve_discrete_are
    A, B = lcs.A, lcs.B
    Q, R = np.diag([10.0, 3.0, 1.0, 1.0]), np.eye(1)
    P = solve_discrete_are(A, B, Q, R)
    return np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A)[0]


def make_recording(truth: Truth, seed: int, episodes: int = 8, duration_s: float = 4.0,
                   params: CartpoleParams | None = None, noise_scale: float | None = None,
                   scenario_text: str | None = None):
    """(Recording, clean states [T, 4]) of the true system under exciting LQR episodes."""
    rng = np.random.default_rng(seed)
    params = params or CartpoleParams()
    K = _lqr_gain(cartpole_lcs(params))
    if noise_scale is None:
        noise_scale = rng.uniform(0.5, 1.5)
    sigma = NOISE_STD * noise_scale
    dt, steps = params.dt, int(round(duration_s / params.dt))
    ts, xs, us, eps, clean = [], [], [], [], []
    for e in range(episodes):
        plant = TrueCartpole(params, truth)
        x = np.array([rng.uniform(-0.2, 0.2), rng.uniform(-0.15, 0.15),
                      rng.uniform(-0.3, 0.3), rng.uniform(-0.5, 0.5)])
        knots = rng.normal(0.0, 2.0, steps // 10 + 2)          # band-limited input noise
        ref, push_left, push, next_switch = rng.choice([-0.1, 0.1]), 0, 0.0, 0
        for k in range(steps):
            if k == next_switch:              # a new cart target, on the other side
                ref = -np.sign(ref) * rng.uniform(0.2, 0.9)
                next_switch = k + int(rng.integers(100, 200))
            y = x + sigma * rng.standard_normal(4)
            if push_left == 0 and rng.random() < 0.01:
                push_left, push = 5, rng.choice([-1, 1]) * rng.uniform(5, 15)
            excite = np.interp(k / 10, np.arange(len(knots)), knots)
            u = float(-K @ (y - np.array([ref, 0, 0, 0]))) + excite + (push if push_left else 0.0)
            push_left = max(push_left - 1, 0)
            u = float(np.clip(u, -40.0, 40.0))
            ts.append(k * dt)
            xs.append(y)
            us.append(u)
            eps.append(e)
            clean.append(x)
            x = plant.step(x, u)
            if abs(x[1]) > 1.0 or abs(x[0]) > 2.0:
                break
    if scenario_text is None:
        scenario_text = DEFAULT_SCENARIO.read_text()
    rec = Recording(t=np.array(ts), x=np.array(xs), u=np.array(us)[:, None],
                    state_names=list(STATE_NAMES), input_names=list(INPUT_NAMES),
                    scenario=scenario_text, episode=np.array(eps, dtype=np.int64))
    return rec, np.array(clean)


def concealed_draw(seed: int, name: str | None = None, target: str | None = None, **kw):
    """(Recording, Truth, clean states) for a seed; the truth stays with the harness."""
    rng = np.random.default_rng([seed, 7])
    truth = draw_effect(rng, name, target)
    rec, clean = make_recording(truth, seed=int(rng.integers(2**31)), **kw)
    return rec, truth, clean


def write_draw(path, seed: int, **kw) -> Truth:
    from adaptive_c3.tools.recording import save_recording
    rec, truth, _ = concealed_draw(seed, **kw)
    save_recording(Path(path), rec)
    return truth


# ------------------------------------------------------------------ the harness
def _named(selected, truth: Truth) -> bool:
    """The matching rule: exactly one effect selected with the concealed name and target
    (r_comp does NOT count for contact_offset, a pair does not count for a single)."""
    if truth.name == "none":
        return selected[0]["name"] == "none"
    return (len(selected) == 1 and selected[0]["name"] == truth.name
            and (selected[0].get("target") or "") == truth.target)


def _in_interval(selected, truth: Truth) -> bool:
    if truth.name == "none":
        return selected[0]["name"] == "none"
    if not _named(selected, truth):
        return False
    lo, hi = selected[0]["params"][0]["ci95"]
    return lo <= truth.value <= hi


def clean_error_cut(rec, clean, result) -> tuple[float, float]:
    """Cross-validated rollout error of the original and the patched model against the
    noise-free truth (start states and targets without sensor noise), in NOISE_STD units."""
    from adaptive_c3.tools.diagnosis.backends.effects import rollout
    from adaptive_c3.tools.diagnosis.engine.locate import LAG, make_windows
    clean_rec = Recording(t=rec.t, x=clean, u=rec.u, state_names=rec.state_names,
                          input_names=rec.input_names, episode=rec.episode)
    W = make_windows(clean_rec, result["horizon"])
    fold = result["foldH"]
    out = []
    P_user = result.get("P_user", result["P0"])
    for models in ({k: P_user for k in result["P1_folds"]}, result["P1_folds"]):
        err = []
        for k, P in models.items():          # out-of-fold: each part by the others' fit
            Wk = W.take(fold == k)
            X, _ = rollout(P, Wk.X0, Wk.U, result["horizon"], LAG)
            err.append((X - Wk.Xt) / NOISE_STD)
        out.append(float(np.sqrt(np.mean(np.concatenate(err) ** 2))))
    return out[0], out[1]


def score_draw(seed: int, baseline: bool = True, **kw) -> dict:
    """Draw, diagnose (and run the baseline), and score against the concealed truth."""
    from adaptive_c3.scenarios.schema import load_scenario
    from adaptive_c3.tools.diagnosis.diagnose import diagnose
    from adaptive_c3.tools.diagnosis.backends.effects import cartpole_spec
    rec, truth, clean = concealed_draw(seed, **kw)
    scenario, _ = load_scenario(DEFAULT_SCENARIO)
    spec = cartpole_spec(scenario)
    result = diagnose(rec, spec, progress=False)
    return score_diagnosis(seed, rec, truth, clean, spec, result, baseline)


def hit_rates(rows) -> dict:
    eff = [r for r in rows if r["truth"]["name"] != "none"]
    clean = [r for r in rows if r["truth"]["name"] == "none"]
    rate = lambda rs, k: float(np.mean([r[k] for r in rs])) if rs else float("nan")  # noqa: E731
    out = dict(draws=len(rows), named=rate(rows, "named"), in_interval=rate(rows, "in_interval"),
               none_on_clean=rate(clean, "named"), clean_draws=len(clean),
               cut_at_least_5x=rate([dict(c=r["clean_cut"] >= 5) for r in eff], "c"),
               median_clean_cut=float(np.median([r["clean_cut"] for r in eff])) if eff else None)
    if rows and "baseline_named" in rows[0]:
        out.update(baseline_named=rate(rows, "baseline_named"),
                   baseline_in_interval=rate(rows, "baseline_in_interval"),
                   baseline_none_on_clean=rate(clean, "baseline_named"))
    return out


def score_diagnosis(seed, rec, truth, clean, spec, result, baseline: bool = True,
                    error_cut=None) -> dict:
    """One draw's row: what diagnose selected against the hidden truth, the error cut
    against the noise-free data (error_cut(rec, clean, result) -> (before, after);
    default: this module's clean_error_cut), and (baseline) the SINDy baseline on the
    same draw."""
    from adaptive_c3.tools.diagnosis.engine.report import selected_rows
    selected = selected_rows(result)
    before, after = (error_cut or clean_error_cut)(rec, clean, result)
    errs = result["errors"]
    row = dict(seed=seed, truth=truth.as_dict(), selected=selected,
               named=_named(selected, truth), in_interval=_in_interval(selected, truth),
               clean_rollout_before=before, clean_rollout_after=after,
               clean_cut=before / max(after, 1e-12),
               noisy_rollout_before=errs["before"]["rollout"]["normalised_rms"],
               noisy_rollout_after=errs["after"]["rollout"]["normalised_rms"],
               seconds=result["seconds"], nuisance_seconds=result.get("nuisance_seconds"))
    if baseline:
        from adaptive_c3.tools.diagnosis.harness.sindy_baseline import sindy_diagnose
        b = sindy_diagnose(rec, spec)
        row.update(baseline_selected=b["selected"], baseline_named=_named(b["selected"], truth),
                   baseline_in_interval=_in_interval(b["selected"], truth))
    return row


def hit_rate_main(argv, score, first_seed: int, description: str) -> int:
    """The command line of a concealed-draw harness: [DRAWS] [FIRST_SEED] [--json FILE];
    score(seed) -> row (see score_draw). Prints one line per draw and the hit rates."""
    import argparse
    import json
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("draws", type=int, nargs="?", default=30)
    ap.add_argument("first_seed", type=int, nargs="?", default=first_seed)
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    rows = []
    for s in range(args.first_seed, args.first_seed + args.draws):
        r = score(s)
        rows.append(r)
        sel = "+".join(x["name"] + (f"[{x['target']}]" if x.get("target") else "")
                       for x in r["selected"])
        bsel = r["baseline_selected"][0]
        noisy = (f"noisy {r['noisy_rollout_before']:.3g}->{r['noisy_rollout_after']:.3g} "
                 if "noisy_rollout_before" in r else "")
        print(f"seed {s}: truth {r['truth']['name']}[{r['truth']['target']}]="
              f"{r['truth']['value']:.4g} -> {sel} "
              f"{[round(p['value'], 5) for x in r['selected'] for p in x.get('params', [])]} "
              f"named={r['named']} in_ci={r['in_interval']} cut={r['clean_cut']:.3g} {noisy}| "
              f"sindy {bsel['name']}[{bsel.get('target', '')}] named={r['baseline_named']} "
              f"({r['seconds']:.1f}s)", flush=True)
        if args.json:   # written after every draw: an interrupted run loses nothing
            Path(args.json).write_text(json.dumps(dict(summary=hit_rates(rows), rows=rows),
                                                  indent=1, default=float))
    print(json.dumps(hit_rates(rows), indent=1))
    return 0


def main(argv=None) -> int:
    """python -m adaptive_c3.tools.diagnosis.harness.concealed_data [DRAWS] [FIRST_SEED] [--json FILE]"""
    return hit_rate_main(argv, score_draw, 1000, "hit rate of diagnose on concealed draws")


if __name__ == "__main__":
    raise SystemExit(main())
