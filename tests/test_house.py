"""The house rules of issue 20, checked on the source (no import, no run).

- no import circle among the project's modules, at module level or inside functions;
- no module imports another module's private (``_name``) functions or constants;
- no command module imports :mod:`tespike.cosim.cli` back (shared pieces live below it), and no
  library module of cosim imports a command module (cli -> commands -> the rest);
- the learned wing's shared package (:mod:`tespike.recon.learning`) reaches no method (:mod:`tespike.recon.net`,
  :mod:`tespike.recon.baselines`), directly or through another module (the registry, the trainer);
- the floors: ``golden`` imports no other room, ``rtl`` only ``golden``'s configuration,
  errors and beat order, ``recon`` only ``golden``; ``cosim`` stands on all of them;
- every import of a room goes through ``tespike.`` (the bare names ``golden``, ``rtl``,
  ``cosim`` and ``recon`` belong to unrelated packages on the package index).
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("golden", "cosim", "recon", "rtl")
#: The learned wing: its shared package, and the packages of the methods built on it.
SHARED, METHODS = "tespike.recon.learning", ("tespike.recon.net", "tespike.recon.baselines")


def _modules() -> dict[str, Path]:
    modules = {}
    for package in PACKAGES:
        for path in (ROOT / package).rglob("*.py"):
            name = ".".join(("tespike",) + path.relative_to(ROOT).with_suffix("").parts)
            modules[name.removesuffix(".__init__")] = path
    return modules


MODULES = _modules()


def _imports(name: str, path: Path):
    """(imported module, names taken from it) for every import statement of the file."""
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, ()
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
                parts = parts[:len(parts) - (node.level - 1)]
                base = ".".join(parts + ([base] if base else []))
            yield base, tuple(alias.name for alias in node.names)


def _graph() -> dict[str, set[str]]:
    graph = {}
    for name, path in MODULES.items():
        targets = set()
        for module, names in _imports(name, path):
            if module in MODULES:
                targets.add(module)
            targets.update(f"{module}.{n}" for n in names if f"{module}.{n}" in MODULES)
        targets.discard(name)
        graph[name] = targets
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan, iterative)."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []
    for start in graph:
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        while work:
            node, children = work[-1]
            for child in children:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                    break
                if child in on_stack:
                    low[node] = min(low[node], index[child])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    component = []
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        component.append(member)
                        if member == node:
                            break
                    if len(component) > 1:
                        found.append(sorted(component))
    return found


def test_the_cycle_finder_finds_a_circle():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_no_import_circles():
    assert _cycles(_graph()) == []


def test_no_module_imports_private_names_of_another():
    reach_ins = []
    for name, path in MODULES.items():
        for module, names in _imports(name, path):
            private = [n for n in names if n.startswith("_") and not n.startswith("__")]
            if private and module != name:
                reach_ins.append(f"{path.relative_to(ROOT)}: from {module} import {', '.join(private)}")
    assert reach_ins == []


def test_command_modules_do_not_import_the_cli_back():
    back = [f"{path.relative_to(ROOT)}" for name, path in MODULES.items()
            if name.startswith("tespike.cosim.commands") and any(module == "tespike.cosim.cli" or (module == "tespike.cosim" and "cli" in names)
                                                         for module, names in _imports(name, path))]
    assert back == []


def test_cosim_library_modules_do_not_import_the_commands():
    graph = _graph()
    up = [f"{name} -> {target}" for name in sorted(graph)
          if _inside(name, "tespike.cosim") and not _inside(name, "tespike.cosim.commands")
          and name != "tespike.cosim.cli"
          for target in sorted(graph[name]) if _inside(target, "tespike.cosim.commands")]
    assert up == []


def _inside(name: str, package: str) -> bool:
    return name == package or name.startswith(package + ".")


def _runs_up(graph: dict[str, set[str]], shared: str, methods: tuple[str, ...]) -> list[str]:
    """``module -> ... -> method`` for every module of ``shared`` whose imports reach a module of ``methods``."""
    found = []
    for start in sorted(m for m in graph if _inside(m, shared)):
        came_from, todo = {start: None}, [start]
        while todo:
            node = todo.pop()
            if any(_inside(node, package) for package in methods):
                path = [node]
                while came_from[path[-1]] is not None:
                    path.append(came_from[path[-1]])
                found.append(" -> ".join(reversed(path)))
                break
            for child in sorted(graph.get(node, ())):
                if child not in came_from:
                    came_from[child] = node
                    todo.append(child)
    return found


def test_the_wing_check_finds_an_import_up_into_a_method():
    graph = {"w.shared.head": {"w.registry"}, "w.registry": {"w.net.model"}, "w.net.model": {"w.shared.head"},
             "w.shared.mulaw": set()}
    assert _runs_up(graph, "w.shared", ("w.net",)) == ["w.shared.head -> w.registry -> w.net.model"]
    assert _runs_up({"w.shared.a": {"w.shared.b"}, "w.shared.b": set()}, "w.shared", ("w.net",)) == []


def test_the_shared_learning_package_reaches_no_method():
    assert any(_inside(m, SHARED) for m in MODULES) and all(any(_inside(m, p) for m in MODULES) for p in METHODS)
    assert _runs_up(_graph(), SHARED, METHODS) == []


#: What each room may import from the others (a module name prefix, or the room itself).
FLOORS = {
    "golden": (),
    "rtl": ("tespike.golden.config", "tespike.golden.errors", "tespike.golden.beats"),
    # recon reads golden's configuration, decoder, file formats and checks (errors, io, paths, resources,
    # atomic), and, where it must simulate, golden's own simulator rather than a second one: the training
    # data engine and the validation clips (fastsim), the sensor's noise (noise) and the calibration's
    # saturated words (the cycle-exact model, sensor). Nothing else of golden: a new floor is a decision.
    "recon": tuple(f"tespike.golden.{m}" for m in ("config", "errors", "decode", "io", "paths", "resources",
                                                    "atomic", "noise", "fastsim", "sensor")),
    "cosim": ("tespike.golden", "tespike.rtl", "tespike.recon"),
}


def _room(module: str) -> str | None:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[0] == "tespike" and parts[1] in PACKAGES else None


def test_rooms_import_only_their_floors():
    up = []
    for name, path in MODULES.items():
        room = _room(name)
        for module, names in _imports(name, path):
            target = _room(module)
            if target is None and module == "tespike":
                targets = [f"tespike.{n}" for n in names if n in PACKAGES]
            else:
                targets = [module] if target else []
            for full in targets:
                if _room(full) != room and not any(full == f or full.startswith(f + ".") for f in FLOORS[room]):
                    up.append(f"{path.relative_to(ROOT)}: {full}")
    assert up == []


def test_golden_stands_on_numpy_and_the_standard_library_alone():
    """The bit-exact model runs wherever numpy does: any other outside import (a progress bar
    included, which the commands pass in as a hook) is a house fault."""
    import sys
    outside = []
    for name, path in MODULES.items():
        if _room(name) != "golden":
            continue
        for module, _ in _imports(name, path):
            top = module.split(".")[0]
            if top not in ("tespike", "numpy", "__future__") and top not in sys.stdlib_module_names:
                outside.append(f"{path.relative_to(ROOT)}: {module}")
    assert outside == []


def test_vcdvcd_is_imported_in_one_place():
    """Importing vcdvcd changes SIGPIPE for the whole process: only :func:`tespike.cosim.vcd.vcd_reader`
    imports it, and puts that back."""
    direct = [f"{path.relative_to(ROOT)}: {module}" for name, path in MODULES.items()
              for module, _ in _imports(name, path) if module.split(".")[0] == "vcdvcd"
              and name != "tespike.cosim.vcd"]
    assert direct == []


def test_rooms_are_imported_as_tespike_modules():
    bare = []
    for folder in PACKAGES + ("tests", "benchmarks"):
        for path in (ROOT / folder).rglob("*.py"):
            for module, _ in _imports("tests.x" if folder in ("tests", "benchmarks") else "tespike.x.y", path):
                if module.split(".")[0] in PACKAGES:
                    bare.append(f"{path.relative_to(ROOT)}: {module}")
    assert bare == []
