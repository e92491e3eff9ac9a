"""What the ball model's held-out error is made of when nothing is concealed.

    python -m adaptive_c3.tools.diagnosis.harness.ball_floor [DRAWS] [FIRST_SEED] [--out DIR]
        [--no-open-pair-gate]

The rigid 100 Hz Anitescu LCS that `diagnose` patches is compared with the other
engine's states (SAP, compliant point contact, 1 kHz: concealed_ball_data) on clean
draws: no effect, the draw's contact stiffness, relaxation time and table height, no
sensor delay (the delay nuisance takes that part up) and sensor noise at 1e-3 of the
harness's, so that what is left is the model's own mismatch. From every sample a
10-step rollout under the recorded EE forces (diagnose.HORIZON), its error in the
harness's noise units (NOISE_STD) over the fitted states. The mean square is the
mismatch an effect fit cannot remove: with noise it adds to the noise floor's 1, so an
`excess_over_noise` after a perfect fit is about sqrt(mean). Reported per draw: that
mean, its part in each phase (push: EE on the ball; coast, rest: the ball free), and
the share the worst 5 % of windows carry, with their phases and how many of them hold
the start or the end of an EE-ball contact.

Writes DIR/ball_floor.json and DIR/ball_floor.png.
"""
from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

import numpy as np

PHASES = ("push", "coast", "rest", "other")
WORST = 0.05          # the share of windows called the worst
# m: a window whose EE-ball gap (at the 100 Hz samples) goes below the first and above
# the second starts or ends a contact (a touch-down, a lift-off, the ball rolling into
# the EE: a 10 ms sample rarely catches the compliant contact's brief penetration)
CONTACT_CHANGE = (2e-4, 5e-4)


def floor_of_draw(seed: int, episodes: int = 15, gate: bool = True) -> dict:
    """The model's mismatch on one clean draw (module doc); gate=False: without the
    open-pair gate (BallSpec.open_pair_tol = None, the model before issue 30)."""
    from adaptive_c3.scenarios.schema import SCENARIO_DIR, load_scenario
    from adaptive_c3.tools.diagnosis.harness.concealed_ball_data import (NOISE_STD, concealed_draw,
                                                                 draw_variation)
    from adaptive_c3.tools.diagnosis.diagnose import HORIZON
    from adaptive_c3.tools.diagnosis.backends.effects import patch, rollout
    from adaptive_c3.tools.diagnosis.tasks.ball_rolling.effects_ball import ModelParams, ball_spec
    from adaptive_c3.tools.diagnosis.engine.evidence import window_phases
    from adaptive_c3.tools.diagnosis.engine.locate import LAG, make_windows
    scenario, _ = load_scenario(SCENARIO_DIR / "ball_rolling.yaml")
    var = replace(draw_variation(seed), sensor_delay=0.0)
    rec, _, _ = concealed_draw(seed, name="none", variation=var, noise_scale=1e-3,
                               episodes=episodes, params=ModelParams.from_scenario(scenario))
    spec = ball_spec(scenario)
    if not gate:
        spec.open_pair_tol = None
    spec.prepare(rec)
    W = make_windows(rec, HORIZON)
    X, _ = rollout(patch(spec, []), W.X0, W.U, HORIZON, LAG, W.row)
    scored = spec.fit_weight > 0
    per_window = np.mean((((X - W.Xt) / NOISE_STD)[..., scored]) ** 2, axis=(1, 2))
    phases = window_phases(spec, W)
    total = float(np.sum(per_window))
    worst = np.argsort(per_window)[::-1][:max(1, int(WORST * len(W)))]
    rows = np.minimum(np.asarray(W.row)[:, None] + np.arange(HORIZON + 1),
                      len(rec.t) - 1)
    gap = spec.cache["phi"][rows, 0]           # EE-ball gap over each window, m
    changes = (gap.min(1) < CONTACT_CHANGE[0]) & (gap.max(1) > CONTACT_CHANGE[1])
    return dict(seed=seed, variation=var.as_dict(), windows=int(len(W)),
                mean=float(np.mean(per_window)), median=float(np.median(per_window)),
                excess_equivalent=float(np.sqrt(np.mean(per_window))),
                by_phase={p: dict(share_of_windows=float(np.mean(phases == p)),
                                  share_of_mismatch=float(np.sum(per_window[phases == p]) / total))
                          for p in PHASES},
                worst_share=float(np.sum(per_window[worst]) / total),
                worst_with_contact_change=float(np.mean(changes[worst])),
                windows_with_contact_change=float(np.mean(changes)),
                worst_phases={p: int(np.sum(phases[worst] == p)) for p in PHASES})


def plot(rows, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    x = np.arange(len(rows))
    worst = np.array([r["mean"] * r["worst_share"] for r in rows])
    rest = np.array([r["mean"] for r in rows]) - worst
    fig, ax = plt.subplots(figsize=(9, 4))
    ax.bar(x, worst, label=f"the worst {WORST:.0%} of windows")
    ax.bar(x, rest, bottom=worst, label="the other windows")
    ax.set_xticks(x, [f"{r['seed']}\n{r['variation']['stiffness'] / 1e3:.0f}k" for r in rows],
                  fontsize=7)
    ax.set_xlabel("draw (contact stiffness, N/m)")
    ax.set_ylabel("mean square rollout error\n(noise units, 10 steps)")
    ax.set_title("the rigid 100 Hz model against the compliant 1 kHz engine, nothing "
                 "concealed", fontsize=10)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    from adaptive_c3.tools.progress import Progress
    ap = argparse.ArgumentParser(description="what the ball model's error is made of on "
                                             "clean draws of the other engine")
    ap.add_argument("draws", type=int, nargs="?", default=10)
    ap.add_argument("first_seed", type=int, nargs="?", default=200)
    ap.add_argument("--out", default="runs/ball_floor")
    ap.add_argument("--no-open-pair-gate", action="store_true",
                    help="the model before issue 30 (relaxed cone on open pairs too)")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    bar = Progress(args.draws, "ball_floor", unit="draws")
    for i, seed in enumerate(range(args.first_seed, args.first_seed + args.draws)):
        rows.append(floor_of_draw(seed, gate=not args.no_open_pair_gate))
        bar.update(i + 1)
    bar.close()
    summary = dict(draws=len(rows),
                   median_mean=float(np.median([r["mean"] for r in rows])),
                   median_excess_equivalent=float(np.median([r["excess_equivalent"]
                                                             for r in rows])),
                   median_worst_share=float(np.median([r["worst_share"] for r in rows])),
                   median_worst_with_contact_change=float(np.median(
                       [r["worst_with_contact_change"] for r in rows])),
                   median_windows_with_contact_change=float(np.median(
                       [r["windows_with_contact_change"] for r in rows])),
                   push_share_of_mismatch=float(np.median(
                       [r["by_phase"]["push"]["share_of_mismatch"] for r in rows])))
    (out / "ball_floor.json").write_text(json.dumps(dict(summary=summary, rows=rows), indent=1))
    plot(rows, out / "ball_floor.png")
    for r in rows:
        print(f"seed {r['seed']}: k={r['variation']['stiffness']:.3g} N/m mean {r['mean']:.2f} "
              f"(excess ~{r['excess_equivalent']:.2f}), worst {WORST:.0%} carry "
              f"{r['worst_share']:.0%} ({r['worst_with_contact_change']:.0%} of them start or "
              f"end an EE-ball contact, {r['windows_with_contact_change']:.0%} of all "
              f"windows do), push windows carry "
              f"{r['by_phase']['push']['share_of_mismatch']:.0%}")
    print(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
