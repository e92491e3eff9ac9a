"""`adaptive-c3 bench`: run benchmark suites, print a table, write JSON.

Each suite module exposes `run_bench(quick: bool) -> list[row]`; a row has
`name`, `median_ms` and, where compared, `baseline` (a row name) and
`speedup` (baseline median / this median). Speed is always a ratio against a
baseline measured in the same run on the same machine. Every run also times the
machine reference (machine.py: rows machine/python and machine/drake), so absolute
times from different machines can be compared.
"""
from __future__ import annotations

import importlib
import inspect
import json
import os
import platform
import sys
from pathlib import Path


def machine_info() -> dict:
    info = {"python": platform.python_version(), "platform": platform.platform(),
            "processor": platform.processor() or platform.machine(), "cpus": os.cpu_count()}
    try:
        import pydrake
        info["drake"] = getattr(pydrake, "__version__", "unknown")
    except ImportError:
        pass
    return info


def format_table(rows) -> str:
    lines = [f"{'name':44s} {'median_ms':>10s} {'speedup':>9s}  baseline"]
    for r in rows:
        sp = r.get("speedup")
        lines.append(f"{r['name']:44s} {r['median_ms']:10.4f} "
                     f"{(f'{sp:8.1f}x' if sp is not None else ''):>9s}  {r.get('baseline', '')}"
                     + (f"value = {_value(r['value'])}" if "value" in r else ""))
    return "\n".join(lines)


def _value(v) -> str:
    return f"{v:.4g}" if isinstance(v, (int, float)) and not isinstance(v, bool) else str(v)


def run_suites(suites: dict, json_path=None, quick: bool = False, options=None) -> list:
    """options: extra keyword arguments, given to the suites whose run_bench takes them
    (e.g. overload for bridge)."""
    from adaptive_c3.tools.bench.machine import machine_rows
    options = {k: v for k, v in (options or {}).items() if v is not None}
    print("bench machine reference ...", file=sys.stderr)
    rows = machine_rows()
    print(format_table(rows))
    for name, module in suites.items():
        try:
            mod = importlib.import_module(module)
        except ModuleNotFoundError as e:
            print(f"bench {name}: skipped ({e.name} not available)", file=sys.stderr)
            continue
        print(f"bench {name} ...", file=sys.stderr)
        accepted = inspect.signature(mod.run_bench).parameters
        suite_rows = mod.run_bench(quick=quick,
                                   **{k: v for k, v in options.items() if k in accepted})
        print(format_table(suite_rows))
        rows.extend(suite_rows)
    if json_path:
        Path(json_path).parent.mkdir(parents=True, exist_ok=True)
        Path(json_path).write_text(json.dumps({"machine": machine_info(), "results": rows},
                                              indent=2, default=float))
        print(f"wrote {json_path}")
    return rows
