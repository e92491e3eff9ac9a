"""The PNG figures of `diagnose`'s report (engine/report.py writes the text around them)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from adaptive_c3.tools.diagnosis.backends.effects import rollout
from adaptive_c3.tools.diagnosis.engine.locate import LAG

PLOT_ROLLOUT_STEPS = 40


def report_plots(out: Path, rec, result) -> list:
    """The report's PNG figures in `out` (where the mismatch sits, open-loop rollouts
    from recorded states before and after, the error tables); returns their paths."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    spec, W1, steps = result["spec"], result["W1"], result["steps"]
    files = []
    # 1. timeline of the episode with the most flagged steps
    eps = np.unique(W1.episode)
    ep = max(eps, key=lambda e: steps["flag"][W1.episode == e].sum())
    sel = W1.episode == ep
    t = W1.t0[sel]
    shown = list(getattr(spec, "plot_idx", ()) or range(len(spec.state_names)))
    n = len(shown)
    fig, ax = plt.subplots(n + 2, 1, figsize=(10, 2.0 * (n + 2)), sharex=True)
    flag = steps["flag"][sel]
    for i, j in enumerate(shown):
        ax[i].plot(t, W1.X0[sel, j], "k.", ms=2, label="recording")
        ax[i].set_ylabel(spec.state_names[j])
        for a, b in _runs(flag):
            for k in range(n + 2):
                ax[k].axvspan(t[a], t[b], color="orange", alpha=0.15, lw=0)
    ax[n].semilogy(t, np.maximum(steps["score"][sel].max(1), 1e-2))
    ax[n].axhline(4.0, color="r", ls="--", lw=0.8)
    ax[n].set_ylabel("mismatch\n(noise units)")
    mc, dc = steps["model_contact"][sel], steps["data_contact"][sel]
    for i, pair in enumerate(spec.pair_names):
        y = i
        for mask, col, lab in ((mc[:, i] & dc[:, i], "tab:green", "both"),
                               (mc[:, i] & ~dc[:, i], "tab:red", "model only"),
                               (~mc[:, i] & dc[:, i], "tab:purple", "data only")):
            ax[n + 1].plot(t[mask], np.full(mask.sum(), y), "|", color=col, ms=10,
                           label=lab if i == 0 else None)
    ax[n + 1].set_yticks(range(len(spec.pair_names)), spec.pair_names)
    ax[n + 1].set_ylim(-0.8, len(spec.pair_names) - 0.2)
    ax[n + 1].legend(loc="upper right", fontsize=7, ncol=3)
    ax[n + 1].set_title("contact: model prediction vs inferred from the motion", fontsize=8)
    ep_id = int(rec.episode[W1.row[sel][0]]) if rec.episode is not None else 0
    ax[-1].set_xlabel(f"time in episode {ep_id} (s); shaded: mismatch beyond noise")
    fig.tight_layout()
    files.append(_save(fig, out / "timeline.png"))
    plt.close(fig)
    # 2. rollouts: recording vs original vs patched over longer horizons
    starts = _rollout_starts(rec, result, 3)
    if starts:
        fig, ax = plt.subplots(n, len(starts), figsize=(4 * len(starts), 2.0 * n), squeeze=False)
        for j, (row, length, fold) in enumerate(starts):
            x0, U, Xr, tt = _segment(rec, row, length)
            for tag, P, style in (("original model", result.get("P_user", result["P0"]), "r--"),
                                  ("patched model (fitted without this part)",
                                   result["P1_folds"][fold], "b-")):
                X, _ = rollout(P, x0[None], U[None], length, LAG, np.array([row]))
                for i, k in enumerate(shown):
                    ax[i, j].plot(tt[1:], X[0, :, k], style, lw=1.2, label=tag)
            for i, k in enumerate(shown):
                ax[i, j].plot(tt, Xr[:, k], "k.", ms=3, label="recording")
                ax[i, 0].set_ylabel(spec.state_names[k])
            ax[-1, j].set_xlabel("time (s)")
        ax[0, 0].legend(fontsize=7)
        fig.suptitle(f"open-loop rollouts from recorded states ({PLOT_ROLLOUT_STEPS} steps), "
                     "patched model fitted on the other folds", fontsize=9)
        fig.tight_layout()
        files.append(_save(fig, out / "rollouts.png"))
        plt.close(fig)
    # 3. errors before / after
    fig, ax = plt.subplots(1, 2, figsize=(9, 3))
    for k, scope in enumerate(("overall", "inside mismatch windows")):
        vals = []
        for tag in ("before", "after"):
            e = result["errors"][tag] if scope == "overall" else \
                result["errors"][tag]["inside_mismatch_windows"]
            vals.append([(e[m] or {}).get("normalised_rms", np.nan) for m in ("one_step", "rollout")])
        vals = np.array(vals)
        x = np.arange(2)
        ax[k].bar(x - 0.2, vals[0], 0.4, label="original model", color="tab:red")
        ax[k].bar(x + 0.2, vals[1], 0.4, label="patched model", color="tab:blue")
        ax[k].axhline(1.0, color="k", ls=":", lw=0.8)
        ax[k].set_xticks(x, ["one-step", f"{result['horizon']}-step rollout"])
        ax[k].set_title(f"cross-validated error, {scope}", fontsize=9)
        ax[k].set_ylabel("RMS / noise floor")
    ax[0].legend(fontsize=7)
    fig.tight_layout()
    files.append(_save(fig, out / "errors.png"))
    plt.close(fig)
    # 4. candidates
    fits = sorted([f for f in result["fits"] if len(f.cands) == 1], key=lambda f: -f.reduction)
    fig, ax = plt.subplots(figsize=(8, 0.3 * len(fits) + 1))
    chosen = result["chosen"]
    cols = ["tab:blue" if chosen is not None and f.label() == chosen.label() else
            ("tab:gray" if not f.significant else "tab:orange") for f in fits]
    ax.barh([f.label() for f in fits], [100 * f.reduction for f in fits], color=cols)
    ax.set_xlabel("cross-validated SSR reduction vs the original model (%)\n"
                  "blue: selected, orange: significant, grey: not significant", fontsize=8)
    ax.invert_yaxis()
    ax.tick_params(labelsize=7)
    fig.tight_layout()
    files.append(_save(fig, out / "candidates.png"))
    plt.close(fig)
    return files


def _runs(flag):
    out, k = [], 0
    while k < len(flag):
        if flag[k]:
            j = k
            while j + 1 < len(flag) and flag[j + 1]:
                j += 1
            out.append((k, j))
            k = j + 1
        else:
            k += 1
    return out


def _rollout_starts(rec, result, count):
    """Starts in mismatch windows first, with PLOT_ROLLOUT_STEPS samples after, and fold."""
    W1, fold1 = result["W1"], result["fold1"]
    score = result["steps"]["score"].max(1)
    ep_len = {e: len(idx) for e, (_, idx) in enumerate(rec.episodes())}
    first = {e: idx[0] for e, (_, idx) in enumerate(rec.episodes())}
    ok = [i for i in np.flatnonzero(fold1 >= 0)
          if W1.row[i] - first[W1.episode[i]] + PLOT_ROLLOUT_STEPS < ep_len[W1.episode[i]]]
    if not ok:
        return []
    ok = sorted(ok, key=lambda i: -score[i])
    picked = []
    for i in ok:
        if all(abs(W1.row[i] - W1.row[j]) > 2 * PLOT_ROLLOUT_STEPS for j in picked):
            picked.append(i)
        if len(picked) == count:
            break
    return [(int(W1.row[i]), PLOT_ROLLOUT_STEPS, int(fold1[i])) for i in picked]


def _segment(rec, row, length):
    u = rec.u
    hist = np.array([u[max(row - LAG + k, 0)] for k in range(LAG)])
    ep = rec.episode
    if ep is not None:  # do not take history from the previous episode
        for k in range(LAG):
            if row - LAG + k < 0 or ep[row - LAG + k] != ep[row]:
                hist[k] = u[row]
    U = np.concatenate([hist, u[row:row + length]], 0)
    return rec.x[row], U, rec.x[row:row + length + 1], rec.t[row:row + length + 1]


def _save(fig, path: Path) -> Path:
    fig.savefig(path, dpi=90)
    return path
