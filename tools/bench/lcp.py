"""Benchmark: our Lemke LCP solver against Drake's MobyLcpSolver.

Rows (docs/performance.md): `lcp/m{m}/lemke` with `baseline`, `speedup`,
`solved_fraction`, `max_abs_diff_z`; and `lcp/m{m}/moby`. The Moby timing is a
whole call as a user with a new (M, q) each step makes it: build a
MathematicalProgram, add the complementarity constraint, Solve. The Moby row
also reports `solve_only_median_ms` (Solve on a prebuilt program).
"""

from __future__ import annotations

import time

import numpy as np
from pydrake.solvers import MathematicalProgram, MobyLcpSolver

from adaptive_c3.systems.contact.lcp import solve_lcp

SIZES = (2, 4, 8, 16)


def make_problems(m: int, n: int, seed: int = 0) -> list[tuple[np.ndarray, np.ndarray]]:
    """n random P-matrix LCPs (M = A A'/m + diag(U[0.1, 1]), q ~ N(0, 1)) of size m."""
    rng = np.random.default_rng(seed + 7919 * m)
    problems = []
    for _ in range(n):
        A = rng.standard_normal((m, m))
        M = A @ A.T / m + np.diag(rng.uniform(0.1, 1.0, m))
        q = rng.standard_normal(m)
        problems.append((M, q))
    return problems


def _moby_solve(solver: MobyLcpSolver, M: np.ndarray, q: np.ndarray):
    """Build the program and solve it; returns (z, success)."""
    prog = MathematicalProgram()
    z = prog.NewContinuousVariables(M.shape[0], "z")
    prog.AddLinearComplementarityConstraint(M, q, z)
    result = solver.Solve(prog)
    return result.GetSolution(z), result.is_success()


def run_bench(quick: bool = False) -> list[dict]:
    """Time solve_lcp and MobyLcpSolver on the same seeded problems for m in SIZES.

    quick=True uses fewer problems and repeats (a few seconds in total).
    Returns the list of result rows (times in milliseconds, medians over all solves).
    """
    n_problems, repeats = (40, 2) if quick else (200, 5)
    solver = MobyLcpSolver()
    rows: list[dict] = []
    for m in SIZES:
        problems = make_problems(m, n_problems)
        progs = []
        for M, q in problems:  # prebuilt programs, for the solve-only timing
            prog = MathematicalProgram()
            z = prog.NewContinuousVariables(m, "z")
            prog.AddLinearComplementarityConstraint(M, q, z)
            progs.append(prog)
        # warm up both paths
        for M, q in problems[:5]:
            solve_lcp(M, q)
            _moby_solve(solver, M, q)

        t_lemke, t_moby, t_moby_solve = [], [], []
        solved, moby_solved, diffs = 0, 0, []
        for rep in range(repeats):
            for (M, q), prog in zip(problems, progs):
                t0 = time.perf_counter()
                res = solve_lcp(M, q)
                t1 = time.perf_counter()
                z_moby, ok = _moby_solve(solver, M, q)
                t2 = time.perf_counter()
                solver.Solve(prog)
                t3 = time.perf_counter()
                t_lemke.append(t1 - t0)
                t_moby.append(t2 - t1)
                t_moby_solve.append(t3 - t2)
                if rep == 0:
                    solved += bool(res.solved)
                    moby_solved += bool(ok)
                    diffs.append(float(np.abs(res.z - z_moby).max()))
        lemke_ms = 1e3 * float(np.median(t_lemke))
        moby_ms = 1e3 * float(np.median(t_moby))
        rows.append(
            {
                "name": f"lcp/m{m}/lemke",
                "median_ms": lemke_ms,
                "baseline": f"lcp/m{m}/moby",
                "speedup": moby_ms / lemke_ms,
                "solved_fraction": solved / n_problems,
                "max_abs_diff_z": max(diffs),
                "n_problems": n_problems,
                "n_solves": len(t_lemke),
            }
        )
        rows.append(
            {
                "name": f"lcp/m{m}/moby",
                "median_ms": moby_ms,
                "solve_only_median_ms": 1e3 * float(np.median(t_moby_solve)),
                "solved_fraction": moby_solved / n_problems,
                "n_problems": n_problems,
                "n_solves": len(t_moby),
            }
        )
    return rows


def format_table(rows: list[dict]) -> str:
    """Rows as a fixed-width text table."""
    header = f"{'name':<18}{'median_ms':>11}{'speedup':>9}{'solved':>8}{'max|dz|':>10}{'solve_only_ms':>15}"
    lines = [header, "-" * len(header)]
    for r in rows:
        speedup = f"{r['speedup']:.2f}" if "speedup" in r else ""
        diff = f"{r['max_abs_diff_z']:.1e}" if "max_abs_diff_z" in r else ""
        solve_only = f"{r['solve_only_median_ms']:.4f}" if "solve_only_median_ms" in r else ""
        lines.append(
            f"{r['name']:<18}{r['median_ms']:>11.4f}{speedup:>9}"
            f"{r['solved_fraction']:>8.2f}{diff:>10}{solve_only:>15}"
        )
    return "\n".join(lines)


if __name__ == "__main__":
    import sys

    print(format_table(run_bench(quick="--quick" in sys.argv)))
