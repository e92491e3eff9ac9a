"""The README's commands stay honest: every `adaptive-c3 ...` line in its code blocks
parses against today's CLI, its command answers `--help`, and the quick ones run for
real (shortened, into a temporary folder); every `make X` there is a Makefile target.

Commands are read from the README each time, so a rewritten README is checked as it is;
the commands in docs/*.md are parsed and asked for --help too (not run). Blocks fenced
as ```text, ```yaml, ```json or ```python are not read.
Real runs: `run` (sim_duration_s cut to 0.3 s, not `--meshcat`) in the default suite;
`sweep` (one trial a cell, 0.3 s) and `bench` (--quick; every bench run also times the
machine reference) with `-m slow` (make test-slow). Commands that need a rig, a recording or a browser (hardware,
impedance, planner, sim-driver, record, diagnose, evaluate, --meshcat) are parsed and
asked for --help only.
"""
import json
import re
import shlex
from pathlib import Path

import pytest

from adaptive_c3.tools.cli import build_parser, main

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"
SHORT_S = 0.3


NOT_SHELL = ("text", "yaml", "json", "python")   # fenced blocks that hold no commands


def code_block_lines(text: str) -> list:
    """The lines inside ``` fences (not ```text, ```yaml, ...), with backslash
    continuations joined."""
    lines, inside, shell, pending = [], False, True, ""
    for line in text.splitlines():
        if line.lstrip().startswith("```"):
            inside, pending = not inside, ""
            shell = line.lstrip()[3:].strip().lower() not in NOT_SHELL
            continue
        if not inside or not shell:
            continue
        line = pending + line.strip()
        if line.endswith("\\"):
            pending = line[:-1] + " "
            continue
        pending = ""
        lines.append(line)
    return lines


def _tokens(line: str):
    line = line[2:] if line.startswith("$ ") else line
    try:
        return shlex.split(line, comments=True)
    except ValueError:
        return []


def readme_commands(text: str) -> list:
    """[argv after `adaptive-c3`] of every command line in the README's code blocks."""
    out = []
    for line in code_block_lines(text):
        tokens = _tokens(line)
        if tokens[:1] == ["adaptive-c3"] and len(tokens) > 1:
            out.append(tokens[1:])
    return out


def readme_make_targets(text: str) -> list:
    return [t[1] for t in map(_tokens, code_block_lines(text)) if t[:1] == ["make"] and len(t) > 1]


def command_path(argv: list) -> list:
    """The (sub)command words of argv: `run`, or `record convert`."""
    parser, path = build_parser(), []
    for word in argv:
        subs = [a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction"]
        if not subs or word not in subs[0].choices:
            break
        path.append(word)
        parser = subs[0].choices[word]
    return path


TEXT = README.read_text()
COMMANDS = readme_commands(TEXT)
IDS = [" ".join(c)[:60] for c in COMMANDS]
DOCS = sorted((REPO / "docs").glob("*.md"))
DOC_COMMANDS = [(p.name, argv) for p in DOCS for argv in readme_commands(p.read_text())]


def test_the_readme_shows_commands():
    assert len(COMMANDS) >= 3, "no `adaptive-c3 ...` lines found in the README's code blocks"
    assert readme_make_targets(TEXT), "no `make ...` lines found in the README's code blocks"


@pytest.mark.parametrize("argv", COMMANDS, ids=IDS)
def test_readme_command_parses_and_has_help(argv, capsys):
    _parses_and_has_help(argv, capsys)


@pytest.mark.parametrize("page,argv", DOC_COMMANDS or [pytest.param(None, None, marks=pytest.mark.skip("no docs"))],
                         ids=[f"{p}: {' '.join(a)[:50]}" for p, a in DOC_COMMANDS] or None)
def test_docs_command_parses_and_has_help(page, argv, capsys):
    """The commands in docs/*.md: parsed and --help only (none is run)."""
    _parses_and_has_help(argv, capsys)


def _parses_and_has_help(argv, capsys):
    if "--help" not in argv and "-h" not in argv:
        try:
            build_parser().parse_args(argv)   # every flag and argument shown exists
        except SystemExit as e:
            pytest.fail(f"`adaptive-c3 {' '.join(argv)}` does not parse (exit {e.code}): "
                        + capsys.readouterr().err.strip())
    path = command_path(argv)
    assert path, f"`adaptive-c3 {' '.join(argv)}`: no such command"
    with pytest.raises(SystemExit) as e:
        main(path + ["--help"])
    assert e.value.code == 0
    assert "usage: adaptive-c3 " + " ".join(path) in capsys.readouterr().out


def test_readme_make_targets_exist():
    makefile = (REPO / "Makefile").read_text()
    targets = set(re.findall(r"^([A-Za-z0-9_.-]+)\s*:", makefile, flags=re.M))
    for target in readme_make_targets(TEXT):
        assert target in targets, f"`make {target}` in the README, no such Makefile target"


# ------------------------------------------------------------------ real runs
def _replace_flag(argv: list, flag: str, value: str) -> list:
    """argv with `flag value` set to value (added when absent)."""
    out, i = [], 0
    while i < len(argv):
        if argv[i] == flag:
            i += 2
            continue
        if argv[i].startswith(flag + "="):
            i += 1
            continue
        out.append(argv[i])
        i += 1
    return out + [flag, value]


def quick_variant(argv: list, tmp: Path):
    """(argv shortened and sent into tmp, slow?) for the commands run for real, else None."""
    path = command_path(argv)
    if "--help" in argv or "-h" in argv:
        return None
    if path == ["run"] and "--meshcat" not in argv and "--meshcat-port" not in argv:
        return _replace_flag(argv, "--out", str(tmp / "run")) + [
            "--set", f"sim_duration_s={SHORT_S}"], False
    if path == ["sweep"]:
        return _replace_flag(argv, "--out", str(tmp / "sweep")) + [
            "--set", "trials=1", "--set", f"set.sim_duration_s={SHORT_S}"], True
    if path == ["bench"]:
        suite = next((a for a in argv[1:] if not a.startswith("-")), "all")
        variant = _replace_flag(argv, "--json", str(tmp / "bench.json"))
        return variant + ([] if "--quick" in argv else ["--quick"]), True
    return None


def _real(slow: bool):
    cases = []
    for argv, cid in zip(COMMANDS, IDS):
        q = quick_variant(argv, Path("TMP"))
        if q is not None and q[1] == slow:
            cases.append(pytest.param(argv, id=cid))
    return cases or [pytest.param(None, marks=pytest.mark.skip("none in the README"))]


def _run_for_real(argv, tmp_path, monkeypatch):
    monkeypatch.chdir(REPO)   # the README's paths are relative to the repository
    variant, _ = quick_variant(argv, tmp_path)
    assert main(variant) == 0, f"`adaptive-c3 {' '.join(variant)}` failed"
    path = command_path(argv)
    if path == ["run"]:
        summary = json.loads((tmp_path / "run" / "summary.json").read_text())
        assert summary["sim_duration_s"] == pytest.approx(SHORT_S)
        assert (tmp_path / "run" / "log.npz").is_file()
    elif path == ["sweep"]:
        assert (tmp_path / "sweep" / "results.csv").is_file()
    elif path == ["bench"]:
        assert json.loads((tmp_path / "bench.json").read_text())["results"]


@pytest.mark.parametrize("argv", _real(slow=False))
def test_readme_quick_command_runs(argv, tmp_path, monkeypatch):
    _run_for_real(argv, tmp_path, monkeypatch)


@pytest.mark.slow
@pytest.mark.parametrize("argv", _real(slow=True))
def test_readme_longer_command_runs_shortened(argv, tmp_path, monkeypatch):
    _run_for_real(argv, tmp_path, monkeypatch)


def test_the_checker_reads_blocks_and_catches_a_stale_flag():
    text = ("text `adaptive-c3 inline` is not a block\n```bash\n$ adaptive-c3 run x.yaml \\\n"
            "    --out o  # a comment\nmake test\n```\n```\nadaptive-c3 run x.yaml --old-flag\n```\n")
    assert readme_commands(text) == [["run", "x.yaml", "--out", "o"],
                                     ["run", "x.yaml", "--old-flag"]]
    assert readme_make_targets(text) == ["test"]
    build_parser().parse_args(readme_commands(text)[0])
    with pytest.raises(SystemExit):
        build_parser().parse_args(readme_commands(text)[1])
    assert command_path(["record", "convert", "a.log", "b.npz"]) == ["record", "convert"]
