"""The documentation's Python examples and references follow the code.

A user copies the README's and docs' examples: every import in their Python
blocks must import (the installed names are ``tespike.golden`` ... since the
rooms got unique import names), every name they import must exist, every call of
an imported function must use keywords its signature has, and every repository
path or ``golden.x.y`` reference in backticks must still exist.
"""

from __future__ import annotations

import ast
import importlib
import inspect
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PAGES = [ROOT / "README.md"] + sorted((ROOT / "docs").rglob("*.md"))
ROOMS = ("golden", "recon", "rtl", "cosim")


def python_blocks(text: str) -> list[tuple[int, str]]:
    """(first line number, code) of each fenced ``python`` block."""
    return [(text[:m.start()].count("\n") + 2, m.group(1))
            for m in re.finditer(r"```(?:python|py)\n(.*?)```", text, re.S)]


def _resolve(dotted: str):
    """The module or attribute ``dotted`` names (importing the longest module prefix), or None.
    A bare room (``golden.x``) is None: the tests run from the checkout, where the folders
    import bare, but an installed tespike has them only as ``tespike.<room>``."""
    parts = dotted.split(".")
    if parts[0] in ROOMS:
        return None
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        for part in parts[i:]:
            if not hasattr(obj, part):
                return None
            obj = getattr(obj, part)
        return obj
    return None


def block_problems(code: str) -> list[str]:
    """What in one example would fail for a user: an import that fails, an imported name
    that does not exist, a keyword an imported callable does not take."""
    try:
        tree = ast.parse(code)
    except SyntaxError as e:
        return [f"not Python: {e.msg} (line {e.lineno})"]
    problems, names = [], {}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module:
            if _resolve(node.module) is None:
                problems.append(f"line {node.lineno}: no module {node.module}")
                continue
            for alias in node.names:
                obj = _resolve(f"{node.module}.{alias.name}")
                if obj is None:
                    problems.append(f"line {node.lineno}: {node.module} has no {alias.name}")
                else:
                    names[alias.asname or alias.name] = obj
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if _resolve(alias.name) is None:
                    problems.append(f"line {node.lineno}: no module {alias.name}")
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in names:
            try:
                params = inspect.signature(names[node.func.id]).parameters
            except (TypeError, ValueError):
                continue
            if any(p.kind is p.VAR_KEYWORD for p in params.values()):
                continue
            for kw in node.keywords:
                if kw.arg is not None and kw.arg not in params:
                    problems.append(f"line {node.lineno}: {node.func.id}() takes no keyword {kw.arg!r}")
    return problems


def test_the_block_check_finds_what_a_user_would_meet():
    """The check fails on the old import names, a missing name and a wrong keyword."""
    assert block_problems("from golden.config import load_config")
    assert block_problems("import recon.metrics")
    assert block_problems("from tespike.golden.config import no_such_thing")
    assert block_problems("from tespike.golden.config import load_config\nload_config('te', seedd=1)")
    assert not block_problems("from tespike.golden.config import load_config\nc = load_config('te')")


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_python_examples_import_and_call_what_exists(page):
    text = page.read_text()
    problems = [f"{page.name}:{line}: {p}" for line, code in python_blocks(text) for p in block_problems(code)]
    assert not problems, "\n".join(problems)


def test_shell_examples_import_with_the_installed_names():
    """``python3 -c "..."`` lines and the like import tespike's rooms as ``tespike.<room>``."""
    old = re.compile(r"(?<![\w.])(?:from|import)\s+(?:" + "|".join(ROOMS) + r")(?:\.|\s|$)")
    found = [f"{page.relative_to(ROOT)}:{n}: {line.strip()[:100]}"
             for page in PAGES for n, line in enumerate(page.read_text().splitlines(), 1) if old.search(line)]
    assert not found, "\n".join(found)


def test_backticked_paths_and_modules_exist():
    """Repository paths (``golden/x.py``) and dotted references (``golden.x.f``) in backticks."""
    path = re.compile(r"`((?:" + "|".join(ROOMS + ("tests", "benchmarks", "tespike")) + r")/[\w/.-]+\.(?:py|md|json))`")
    dotted = re.compile(r"`((?:tespike\.)?(?:" + "|".join(ROOMS) + r")\.[\w.]+?)\.?(?:\([^`]*\))?`")
    missing = []
    for page in PAGES:
        for n, line in enumerate(page.read_text().splitlines(), 1):
            missing += [f"{page.relative_to(ROOT)}:{n}: {m}" for m in path.findall(line) if not (ROOT / m).exists()]
            for m in dotted.findall(line):
                if _resolve(m if m.startswith("tespike.") else "tespike." + m) is None:
                    missing.append(f"{page.relative_to(ROOT)}:{n}: {m}")
    assert not missing, "\n".join(missing)


def command_lines(text: str) -> list[tuple[int, str]]:
    """(line number, text) of each ``tespike <command> ...`` written in a code block or in
    backticks, continuation lines joined (``tespike x: error: ...``, a message, is not one)."""
    lines, out, fence = text.splitlines(), [], False
    i = 0
    while i < len(lines):
        line = lines[i]
        if line.lstrip().startswith("```"):
            fence = not fence
        elif fence:
            n, joined = i + 1, line
            while joined.rstrip().endswith("\\") and i + 1 < len(lines):
                i += 1
                joined = joined.rstrip()[:-1] + " " + lines[i].strip()
            for m in re.finditer(r"(?:^|[\s$;&|(])(?:python3 -m )?tespike ([a-z][\w-]*)(?=\s|$)([^#;&|]*)", joined):
                out.append((n, f"{m.group(1)}{m.group(2)}"))
        else:
            for m in re.finditer(r"`(?:python3 -m )?tespike ([a-z][\w-]*)(?=[\s`])([^`]*)`", line):
                out.append((i + 1, f"{m.group(1)}{m.group(2)}"))
        i += 1
    return out


def command_problems(text: str) -> list[str]:
    """Commands and flags in ``text``'s ``tespike COMMAND --flag`` examples that the parser lacks."""
    from tespike.cosim.cli import COMMANDS, build_parser
    parser = build_parser()
    commands = {name: sub for action in parser._subparsers._group_actions for name, sub in action.choices.items()}
    wrong = []
    for n, line in command_lines(text):
        name, _, rest = line.partition(" ")
        if name not in COMMANDS:
            if name not in ("COMMAND", "command"):
                wrong.append(f"{n}: no command {name!r}")
            continue
        known = set(commands[name]._option_string_actions)
        wrong += [f"{n}: tespike {name} has no {flag}"
                  for flag in re.findall(r"(?<![\w-])(--?[a-zA-Z][\w-]*)", rest) if flag not in known]
    return wrong


def test_the_command_check_finds_a_stale_flag():
    assert command_problems("```\ntespike simulate --config te --no-such-flag 1\n```")
    assert command_problems("run `tespike simulat --config te`")
    assert command_problems("```\ntespike reconstruct --stream S.npz \\\n    --method net --wieghts W.pt\n```")
    assert not command_problems("```\ntespike simulate --config te --scene I.npy --out S.npz\n```")
    assert not command_problems("`tespike golden: error: argument --config: expected one argument`")


def test_command_examples_use_commands_and_flags_that_exist():
    """Every ``tespike COMMAND --flag`` in the README and docs names a command and flags its
    parser has (a renamed or removed flag in an example is refused at the user's first try)."""
    wrong = [f"{page.relative_to(ROOT)}:{p}" for page in PAGES for p in command_problems(page.read_text())]
    assert not wrong, "\n".join(wrong)


def script_lines(text: str) -> list[tuple[int, str, str]]:
    """(line number, script, arguments) of each ``benchmarks/X.py ...`` run in ``text``
    (continuation lines joined; an argument list ends at a backtick, pipe or comment;
    quoted values, e.g. another tool's options, left out)."""
    joined = re.sub(r"\\\n\s*", " ", text)
    out = []
    for m in re.finditer(r"(benchmarks/[\w]+\.py)([^`|#\n;&)]*)", joined):
        args = re.sub(r"\"[^\"]*\"|'[^']*'", "", m.group(2))     # a quoted value is not a flag of the script
        out.append((joined[:m.start()].count("\n") + 1, m.group(1), args))
    return out


def test_benchmark_examples_use_flags_that_exist():
    """Every ``benchmarks/X.py --flag`` in the README and docs names a flag the script's
    ``--help`` lists (each script asked once)."""
    import subprocess
    import sys
    uses = [(page, n, script, args) for page in PAGES for n, script, args in script_lines(page.read_text())
            if re.search(r"(?<![\w-])--?[a-zA-Z]", args)]
    known = {}
    wrong = []
    for page, n, script, args in uses:
        if not (ROOT / script).exists():
            wrong.append(f"{page.relative_to(ROOT)}:{n}: no {script}")
            continue
        if script not in known:
            done = subprocess.run([sys.executable, script, "--help"], cwd=ROOT, capture_output=True, text=True,
                                  timeout=120)
            assert done.returncode == 0, f"{script} --help: {done.stderr[-300:]}"
            known[script] = set(re.findall(r"(?<![\w-])(--?[a-zA-Z][\w-]*)", done.stdout))
        wrong += [f"{page.relative_to(ROOT)}:{n}: {script} has no {flag}"
                  for flag in re.findall(r"(?<![\w-])(--?[a-zA-Z][\w-]*)", args) if flag not in known[script]]
    assert uses and not wrong, "\n".join(wrong)


def test_the_docs_figures_have_one_home_and_every_link_resolves():
    """Figures lived in three places (docs/, docs/net/ and benchmarks/); they live in docs/figures/
    (training curves in its net/), where ``--docs`` of every benchmark writes, and each link to one
    (or to any other file) from a page resolves."""
    import subprocess
    tracked = subprocess.run(["git", "ls-files", "*.png"], cwd=ROOT, capture_output=True, text=True).stdout.split()
    if tracked:                         # (a checkout without git lists none)
        assert all(name.startswith("docs/figures/") for name in tracked), tracked
    broken = []
    for page in PAGES:
        for target in re.findall(r"\]\(([^)#\s:]+)(?:#[^)]*)?\)", page.read_text()):
            if not (page.parent / target).exists():
                broken.append(f"{page.relative_to(ROOT)}: {target}")
    assert not broken, broken
