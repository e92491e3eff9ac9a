"""Per-effect hit rates of `diagnose` on concealed ball-rolling draws (issue 19's marks).

    python -m adaptive_c3.tools.diagnosis.harness.ball_hit_rate [DRAWS] [FIRST_SEED] [--out DIR]
        [--follow-up] [--no-open-pair-gate] [--model lcs|drake]
    python -m adaptive_c3.tools.diagnosis.harness.ball_hit_rate --merge A.json B.json [--out DIR]
        (one summary and per-effect table over the rows of several runs)

Each draw (tools/diagnosis/harness/concealed_ball_data.py, with the second-engine variation) is
diagnosed and scored:
  named          the concealed effect (or none) is the one selected, i.e. named first
  favoured       ... and the verdict is `named` (not ambiguous)
  confident_right / confident_wrong / ambiguous_with_truth / ambiguous_without_truth
                 counts of the separate answers (ambiguous is never counted as right; they
                 sum to the draws); truth_in_interval: count of the named effect draws
                 (the answer is the true effect) with the truth in the 95 % interval
  matters        the effective truth reaches the size that matters (BallSpec.relevant_size);
                 below it `none` is a right answer (below_size: those draws' answers)
  in_interval    named, and the effective truth inside the reported 95% interval
  ambiguous      the verdict is ambiguous; in_ambiguous_set: the truth is in the set
  excess cut     held-out rollout excess-over-noise (noisy data) before / after (in the
                 calibrated noise; after at least concealed_ball_data.EXCESS_RESOLUTION)
  clean cut      the same against the noise-free states (NOISE_STD units)
  size_excluded  effects whose size that matters the data ruled out directly
                 (engine/boundary.py), though their interval reached it or was not read
  size_tests     every such test: the effect, the sizes tried and their z against `none`
                 (with a follow-up also each recording's alone: `by_recording`)
  confirmation   the chosen effect against `none` on the windows the fit left out, where
                 `none` had joined it (engine/boundary.py confirm_on_left_out), and
                 against each nuisance the fit did not keep (`nuisance_rivals`)
  below_size     the effect(s) of an answer (named, or an ambiguous set) whose every
                 interval lay within its size that matters, answered `none` instead
                 (engine/boundary.py below_size)
  ruled_out_members  the members of a set beside `none` whose every size that matters
                 was ruled out, taken out of it (engine/boundary.py ruled_out_members)
  left_out       each single member beside `none`: its own fit against `none` there
                 (a record; no answer depends on it)
  direct_readings  each member beside `none` the task read from the recording with no
                 model (the ball's mass: momentum balance), within / beyond its size
                 (engine/direct_reading.py)
  beyond_size    each member beside `none` whose value lies beyond its size: its fit
                 against `none` and against the size there, and whether `none` left
                 (engine/beyond_size.py)
  left_out_rivals  each effect beside the chosen one: the chosen fit against it on the
                 windows the fit left out, and whether it left the set
                 (engine/left_out_rivals.py)
  ambiguous_notes  per member of the ambiguous set, why it joined (its `note`, e.g. "not
                 excluded: its fit is worse than `none` ...", or require_support's
                 `reason`: the chosen effect's interval holds the model's value)
--follow-up: on an ambiguous verdict the harness records again with the gait change
the report proposes (`separating_excitation[].excitation`, as its user would) and
diagnoses both recordings together; `after_follow_up` scores the draws with that
second answer where there is one (the first answer elsewhere).
Writes DIR/ball_hit_rate.json (summary + rows, after every draw) and DIR/ball_hit_rate.png.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from adaptive_c3.tools.diagnosis.harness.concealed_ball_data import label as _label, score_draw

TARGETS = dict(named=0.90, none_on_clean=1.0, coverage=0.85, truth_in_ambiguous=1.0,
               median_excess_cut=5.0)


def summarise(rows) -> dict:
    out = _summary(rows)
    if any("follow_up" in r for r in rows):
        out["after_follow_up"] = dict(
            _summary([r.get("follow_up", r) for r in rows]),
            follow_ups=sum("follow_up" in r for r in rows))
    return out


ANSWERS = ("confident_right", "confident_wrong", "ambiguous_with_truth",
           "ambiguous_without_truth")


def answer(r) -> str:
    """The draw's answer category (ANSWERS; an ambiguous verdict is never right). A draw
    below the size that matters is right with `none` (concealed_ball_data.apply_size_rule)."""
    if r["verdict"] == "ambiguous":
        return "ambiguous_with_truth" if r["in_ambiguous_set"] else "ambiguous_without_truth"
    return "confident_right" if r["named"] else "confident_wrong"


def _counts(rows) -> dict:
    return {k: sum(answer(r) == k for r in rows) for k in ANSWERS}


def _summary(rows) -> dict:
    def rate(rs, key):
        return float(np.mean([bool(r[key]) for r in rs])) if rs else None
    eff = [r for r in rows if r["truth"]["name"] != "none"]
    clean = [r for r in rows if r["truth"]["name"] == "none"]
    # named effect draws: the answer is the true effect (not a right `none` below size)
    named_eff = [r for r in eff if r["named"] and not r.get("answered_none", False)]
    below = [r for r in eff if not r.get("matters", True)]
    amb = [r for r in rows if r["verdict"] == "ambiguous"]
    per = {}
    for r in rows:
        per.setdefault(_label(r["truth"]["name"], r["truth"]["target"]), []).append(r)
    def count(pred):
        return sum(bool(pred(r)) for r in rows)
    return dict(
        draws=len(rows),
        # the separate answers (an ambiguous verdict is never counted as right)
        **_counts(rows),
        named_first=count(lambda r: r["named"]),
        truth_in_interval=sum(bool(r["in_interval"]) for r in named_eff),
        below_size_draws=len(below), below_size=_counts(below),
        named=rate(rows, "named"), named_effect_draws=rate(eff, "named"),
        favoured=rate(rows, "favoured"), none_on_clean=rate(clean, "named"),
        clean_draws=len(clean), coverage=rate(named_eff, "in_interval"),
        named_effect_count=len(named_eff), ambiguous_draws=len(amb),
        truth_in_ambiguous=rate(amb, "in_ambiguous_set"),
        median_excess_cut=float(np.median([r["excess_cut"] for r in named_eff]))
        if named_eff else None,
        median_clean_cut=float(np.median([r["clean_cut"] for r in named_eff]))
        if named_eff else None,
        per_effect={k: dict(draws=len(v), below_size=sum(not r.get("matters", True) for r in v),
                            **_counts(v), named=rate(v, "named"),
                            ambiguous=sum(r["verdict"] == "ambiguous" for r in v),
                            truth_in_ambiguous=rate([r for r in v if r["verdict"] ==
                                                     "ambiguous"], "in_ambiguous_set"),
                            in_interval=rate(v, "in_interval"),
                            truth_in_interval=sum(bool(r["in_interval"]) for r in v
                                                  if r in named_eff),
                            named_effect=sum(r in named_eff for r in v))
                    for k, v in sorted(per.items())},
        confirmations=_confirmations(rows),
        # members beside `none` tested beyond their sizes, and `none` taken out (beyond_size)
        beyond_size=dict(tested=count(lambda r: r.get("beyond_size")),
                         none_out=count(lambda r: any(t["beyond"] for t in
                                                      r.get("beyond_size") or []))),
        # members beside `none` read directly from the recording (engine/direct_reading.py):
        # read, ruled out within their size, `none` taken out beyond it
        direct_readings=dict(
            read=count(lambda r: r.get("direct_readings")),
            within=count(lambda r: any(x["within"] for x in r.get("direct_readings") or [])),
            beyond=count(lambda r: any(x["beyond"] for x in r.get("direct_readings") or []))),
        # rivals of the chosen effect tested on the left-out windows, dropped, and
        # dropped while they were the truth (engine/left_out_rivals.py)
        left_out_rivals=_left_out_rivals(rows),
        # answers with a size ruled out by one recording alone, not the pooled test
        # (boundary.excluded; `bar`: the one the 1 + k tests share, evidence.size_z)
        excluded_by_one_recording=count(lambda r: any(
            t["excluded"] and any(x.get("by_recording") and x["z_vs_none"] > -x["bar"]
                                  for x in t["tested"])
            for t in r.get("size_tests") or [])),
        # answers within their sizes that matter turned into `none` (boundary.below_size)
        within_size_to_none=count(lambda r: r.get("below_size")),
        # members of a set beside `none` whose sizes were all ruled out, taken out
        # (boundary.ruled_out_members), and taken out while they were the truth
        ruled_out_members=dict(
            answers=count(lambda r: r.get("ruled_out_members")),
            the_truth=count(lambda r: r.get("matters", True) and _label(
                r["truth"]["name"], r["truth"]["target"]) in (r.get("ruled_out_members")
                                                             or []))),
        targets=TARGETS)


def _confirmations(rows) -> dict:
    """How often a chosen effect was tested against `none` on the left-out windows
    (engine/boundary.py confirm_on_left_out), confirmed, and confirmed while it held the
    true effect (a pair counts when one of its members is the truth); and how often one
    that beat `none` there was stopped by a nuisance it did not beat (nuisance_rivals),
    and of those how often it held the truth."""
    def on_truth(r):
        return _label(r["truth"]["name"], r["truth"]["target"]) in \
            r["confirmation"]["name"].split(" + ")
    tested = [r for r in rows if r.get("confirmation")]
    ok = [r for r in tested if r["confirmation"]["confirmed"]]
    stopped = [r for r in tested if not r["confirmation"]["confirmed"]
               and r["confirmation"].get("nuisance_rivals")]
    return dict(tested=len(tested), confirmed=len(ok),
                confirmed_the_truth=sum(map(on_truth, ok)),
                stopped_by_nuisance=len(stopped),
                stopped_the_truth=sum(map(on_truth, stopped)))


def _left_out_rivals(rows) -> dict:
    """Draws where rivals of the chosen effect were tested on the left-out windows, the
    rivals dropped there, and of those how many were the true effect."""
    tested = [r for r in rows if r.get("left_out_rivals")]
    gone = [(r, x) for r in tested for x in r["left_out_rivals"] if x["dropped"]]
    return dict(tested=len(tested), dropped=len(gone),
                dropped_the_truth=sum(x["name"] == _label(r["truth"]["name"],
                                                          r["truth"]["target"])
                                      for r, x in gone))


def answer_line(summary) -> str:
    """One line of the separate answers, e.g. 'confident right 9/21, ...'."""
    n = summary["draws"]
    parts = [f"confident right {summary['confident_right']}/{n}",
             f"confident wrong {summary['confident_wrong']}/{n}",
             f"ambiguous with the truth {summary['ambiguous_with_truth']}/{n}",
             f"ambiguous without {summary['ambiguous_without_truth']}/{n}",
             f"named first {summary['named_first']}/{n}",
             f"truth in the 95 % interval {summary['truth_in_interval']}/"
             f"{summary['named_effect_count']} named effect draws"]
    if summary.get("below_size_draws"):
        b = summary["below_size"]
        parts.append(f"{summary['below_size_draws']} draws below the size that matters "
                     f"(confident right {b['confident_right']}, wrong {b['confident_wrong']})")
    if summary.get("median_excess_cut") is not None:
        parts.append(f"median excess-over-noise cut {summary['median_excess_cut']:.2f}x "
                     "(named effect draws)")
    return ", ".join(parts)


def plot(summary, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    per = summary["per_effect"]
    names = list(per)
    x = np.arange(len(names))
    fig, ax = plt.subplots(figsize=(10, 4))
    for i, (key, lab) in enumerate((("named", "named first"), ("in_interval", "truth in 95% CI"),
                                    ("truth_in_ambiguous", "truth in ambiguous set"))):
        vals = [per[n][key] if per[n][key] is not None else np.nan for n in names]
        ax.bar(x + (i - 1) * 0.27, vals, 0.27, label=lab)
    ax.set_xticks(x, [f"{n}\n(n={per[n]['draws']})" for n in names], rotation=30, ha="right",
                  fontsize=8)
    ax.axhline(0.9, color="k", lw=0.5, ls="--")
    ax.set_ylim(0, 1.05)
    title = (f"diagnose on {summary['draws']} concealed ball draws: named first "
             f"{summary['named']:.0%}, coverage {summary['coverage'] or 0:.0%}")
    if "after_follow_up" in summary:
        f = summary["after_follow_up"]
        title += (f"\nafter {f['follow_ups']} follow-up recordings with the proposed "
                  f"excitation: named first {f['named']:.0%}, coverage {f['coverage'] or 0:.0%}")
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run(draws: int, first_seed: int, out: Path, **kw) -> dict:
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for s in range(first_seed, first_seed + draws):
        r = score_draw(s, baseline=False, **kw)
        rows.append(r)
        print(f"seed {s}: truth {_label(r['truth']['name'], r['truth']['target'])}="
              f"{r['truth']['value']:.4g} -> {_answer(r)}", flush=True)
        if "follow_up" in r:
            print(f"  follow-up {r['follow_up']['excitation']} -> {_answer(r['follow_up'])}",
                  flush=True)
        summary = summarise(rows)
        (out / "ball_hit_rate.json").write_text(
            json.dumps(dict(summary=summary, rows=rows), indent=1, default=float))
    plot(summary, out / "ball_hit_rate.png")
    print_summary(summary)
    return summary


def print_summary(summary) -> None:
    print("one recording: " + answer_line(summary), flush=True)
    print("\n".join(effect_table(summary)), flush=True)
    if "after_follow_up" in summary:
        f = summary["after_follow_up"]
        print(f"after {f['follow_ups']} follow-up recordings: " + answer_line(f), flush=True)
        print("\n".join(effect_table(f)), flush=True)


def effect_table(summary) -> list:
    """Markdown rows per effect: draws (below the size that matters), the four answers,
    truth in the 95 % interval of the named effect draws."""
    out = ["| effect | draws (below size) | confident right | confident wrong | ambiguous "
           "with truth | ambiguous without | truth in 95 % CI / named |",
           "|---|---|---|---|---|---|---|"]
    for k, v in list(summary["per_effect"].items()) + [("all", dict(
            summary, below_size=summary["below_size_draws"],
            named_effect=summary["named_effect_count"]))]:
        out.append(f"| {k} | {v['draws']} ({v['below_size']}) | "
                   + " | ".join(str(v[a]) for a in ANSWERS)
                   + f" | {v['truth_in_interval']}/{v['named_effect']} |")
    return out


def merge(paths, out: Path) -> dict:
    """One summary over the rows of several ball_hit_rate.json files (e.g. two halves
    of an evaluation run side by side)."""
    rows = [r for p in paths for r in json.loads(Path(p).read_text())["rows"]]
    summary = summarise(rows)
    out.mkdir(parents=True, exist_ok=True)
    (out / "ball_hit_rate.json").write_text(
        json.dumps(dict(summary=summary, rows=rows, merged=[str(p) for p in paths]),
                   indent=1, default=float))
    print_summary(summary)
    return summary


def _answer(r) -> str:
    sel = "+".join(_label(x["name"], x.get("target", "")) for x in r["selected"])
    est = ""
    if r["selected"] and r["selected"][0].get("params"):
        p = r["selected"][0]["params"][0]
        est = f" {p['value']:.3g} [{p['ci95'][0]:.3g}, {p['ci95'][1]:.3g}]"
    below = "" if r.get("matters", True) else " [truth below the size that matters]"
    return (f"{sel}{est} ({r['verdict']}"
            f"{': ' + ', '.join(r['ambiguous']) if r['ambiguous'] else ''}) -> {answer(r)}"
            f"{below} named={r['named']} in_ci={r['in_interval']} "
            f"excess cut={r['excess_cut']:.3g} ({r['seconds']:.1f}s)")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description="per-effect hit rates of diagnose on concealed "
                                             "ball-rolling draws")
    ap.add_argument("draws", type=int, nargs="?", default=40)
    ap.add_argument("first_seed", type=int, nargs="?", default=7000)
    ap.add_argument("--out", default="runs/ball_hit_rate")
    ap.add_argument("--follow-up", action="store_true",
                    help="record again with the proposed excitation on ambiguous verdicts")
    ap.add_argument("--no-open-pair-gate", action="store_true",
                    help="diagnose with Anitescu's relaxed cone on open pairs too (the model "
                         "before issue 30: BallSpec.open_pair_tol = None)")
    ap.add_argument("--model", choices=("lcs", "drake"), default="lcs",
                    help="the model diagnosed: the controller's LCS (default) or Drake's "
                         "plant of the scenario's nominal world")
    ap.add_argument("--merge", nargs="+", metavar="JSON",
                    help="summarise the rows of these ball_hit_rate.json files together")
    args = ap.parse_args(argv)
    if args.merge:
        missing = [p for p in args.merge if not Path(p).is_file()]
        if missing:
            import sys
            print(f"ball_hit_rate: no such file: {missing[0]}", file=sys.stderr)
            return 2
        merge(args.merge, Path(args.out))
        return 0
    kw = dict(spec_overrides=dict(open_pair_tol=None)) if args.no_open_pair_gate else {}
    kw["model"] = args.model
    print(json.dumps(run(args.draws, args.first_seed, Path(args.out),
                         follow_up=args.follow_up, **kw), indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
