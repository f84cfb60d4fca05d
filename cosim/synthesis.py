"""Yosys synthesis of the project's Verilog: cells, flip-flops and a CMOS transistor estimate.

Two flows share one Yosys run (:func:`yosys_run`), one cost script (:func:`mapping_steps`) and
one reading of its reports: :func:`synthesize_module` costs one module as a whole (the demo's small
cost table, :mod:`tespike.cosim.demo`, and the full study, ``benchmarks/hw_cost.py``,
``docs/hardware-cost.md``); :func:`synthesize_hierarchy` (below) costs every module of a
generated top. ``synth -top <module>; stat`` counts cells of
Yosys's internal gate library and flip-flops; then every flip-flop is legalised
to a plain D flip-flop (reset and enable become gates), the logic is mapped by
ABC to each gate set of :data:`ABC_GATE_SETS` and counted with
``stat -tech cmos``. ABC is heuristic: the same logic maps a few percent larger
or smaller, so the result is the smallest estimate and the largest (their gap
is the mapping noise).

One rule for Yosys's estimate: a count it marks incomplete (``"1574+"``: some
cell type has no entry in its CMOS table) is refused, never read as a number:
it is a lower bound of unknown slack, and every gate set here maps only to cells
the table covers, so a "+" means the flow broke (except where the unknown cells are
submodule instances: :func:`parse_stat_modules`).

:func:`synthesize_hierarchy` synthesises a whole generated top with its hierarchy
kept (``tespike synthesize``): one report per module, and :func:`hierarchy_total`
multiplies them out by instance counts.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import subprocess
import time
from pathlib import Path

from tespike.golden.atomic import work_folder
from tespike.golden.errors import InputError

from . import children

#: ABC gate sets tried for the transistor estimate (all have entries in Yosys's CMOS table).
ABC_GATE_SETS = ("cmos2", "cmos3", "cmos4", "gates")


#: The name Yosys reads a design under (its messages say "design.v:12: ERROR: ...").
DESIGN_FILE = "design.v"


class SynthesisError(RuntimeError):
    """Yosys is missing, failed, or reported what cannot be read as a cost (a tool's failure, not a
    refusal of the caller's input: the command line says it in one line with its own exit status)."""


def parse_stat(json_text: str) -> dict:
    """Read one ``stat -json`` (optionally ``-tech cmos``) report of Yosys 0.23+.

    Returns cells, flops (cell types containing DFF/DLATCH), transistors
    (``None`` without ``-tech cmos``) and the cell count by type. An incomplete
    transistor estimate (``"1574+"``) is refused (ValueError).
    """
    data = json.loads(json_text)
    design = data.get("design")
    if design is None:
        modules = data.get("modules") or {}
        if len(modules) != 1:
            raise ValueError(f"Yosys stat report has no 'design' and {len(modules)} modules")
        design = next(iter(modules.values()))
    by_type = design.get("num_cells_by_type", {})
    return {"cells": int(design["num_cells"]), "flops": _flops(by_type),
            "transistors": _transistors(design.get("estimated_num_transistors"), "Yosys"),
            "by_type": dict(by_type)}


def _flops(by_type: dict) -> int:
    """Flip-flops among cells counted by type (every DFF and DLATCH kind)."""
    return sum(n for kind, n in by_type.items() if "DFF" in kind or "DLATCH" in kind)


def _transistors(estimate, what: str, submodules: bool = False) -> int | None:
    """Yosys's ``estimated_num_transistors`` as a number (None where it made none), refused
    (ValueError naming ``what``) where it is marked incomplete (``"1574+"``: a cell type has no CMOS
    cost), except, with ``submodules``, the "+" of a module whose uncosted cells are its submodules'
    instances (:func:`parse_stat_modules`)."""
    if estimate is None:
        return None
    text = str(estimate)
    number = text[:-1] if submodules and text.endswith("+") else text
    if not number.isdigit():
        raise ValueError(f"{what} transistor estimate {text!r} is incomplete (a cell type has no CMOS cost)")
    return int(number)


def _estimate_range(name: str, flops: int, mapped: dict[str, dict]) -> tuple[int, int]:
    """(smallest, largest) transistor estimate of ``name`` over its ABC mappings ``mapped``
    (gate set -> its report), refused where a mapping changed the flip-flop count ``flops``."""
    for gates, stat in mapped.items():
        if stat["flops"] != flops:
            raise SynthesisError(f"{name}: flip-flop count changed in the {gates} mapping "
                                 f"({flops} -> {stat['flops']})")
    estimates = [stat["transistors"] for stat in mapped.values()]
    return min(estimates), max(estimates)


def yosys_missing(yosys: str = "yosys") -> str | None:
    """Why Yosys cannot run here, or None when it can."""
    return None if shutil.which(yosys) else f"Yosys ({yosys!r}) is not installed"


@contextlib.contextmanager
def yosys_run(verilog_text: str, steps: list[str], failure: str, yosys: str = "yosys", prefix: str = "tespike-yosys-"):
    """Yosys on ``verilog_text`` (read as :data:`DESIGN_FILE` in a fresh folder, the script's
    working folder) running ``steps``: the one place every Yosys flow here (synthesis, the
    switching netlists, the register map) starts it. Yields (the folder, the run's wall and CPU
    seconds and peak resident MB) while the folder lives; a missing Yosys or a failed run
    raises :class:`SynthesisError` saying ``failure`` and Yosys's first error line."""
    if not (isinstance(verilog_text, str) and verilog_text.strip()):   # (None had been pathlib's TypeError)
        raise InputError(f"Verilog text: must be a non-empty string of Verilog source, not "
                         f"{'an empty one' if isinstance(verilog_text, str) else type(verilog_text).__name__}")
    missing = yosys_missing(yosys)
    if missing:
        raise SynthesisError(missing)
    with work_folder(prefix) as tmp:
        work = Path(tmp)
        children.write_work_file(work / DESIGN_FILE, verilog_text)
        code, output, run = _run_measured([yosys, "-q", "-p", "; ".join([f"read_verilog {DESIGN_FILE}", *steps])],
                                          work)
        if code != 0:
            errors = [line for line in output.splitlines() if "ERROR" in line] or output.strip().splitlines()[-1:]
            raise SynthesisError(f"{failure}: {errors[0].strip() if errors else children.ended(code)}"
                                  f"{children.room_note(work)}")
        yield work, run


def check_synthesis_request(top, gate_sets) -> None:
    """A module name Yosys can read (or None where the caller lets the design say) and gate sets of
    :data:`ABC_GATE_SETS`, refused in one line before Yosys starts."""
    if top is not None and not (isinstance(top, str) and re.fullmatch(r"[A-Za-z_][A-Za-z0-9_$]*", top)):
        raise InputError(f"top module {top!r}: must be a Verilog module name")
    if isinstance(gate_sets, str) or not gate_sets or not all(isinstance(g, str) and g in ABC_GATE_SETS
                                                                for g in gate_sets):
        raise InputError(f"gate sets {gate_sets!r}: must be a sequence of {', '.join(ABC_GATE_SETS)}")


def mapping_steps(gate_sets: tuple[str, ...]) -> list[str]:
    """The cost flow after ``synth``: the generic report (``generic.json``), then every flip-flop
    legalised to a plain D flip-flop and the logic mapped to each ABC gate set, each reported
    with Yosys's CMOS transistor table (``<gates>.json``)."""
    steps = ["tee -q -o generic.json stat -json", "dfflegalize -cell $_DFF_P_ 01", "opt_clean", "design -save legal"]
    for gates in gate_sets:
        steps += ["design -load legal", f"abc -g {gates}", "opt_clean", f"tee -q -o {gates}.json stat -json -tech cmos"]
    return steps


def synthesize_module(verilog_text: str, top: str, yosys: str = "yosys",
               gate_sets: tuple[str, ...] = ABC_GATE_SETS) -> dict:
    """Synthesize module ``top``; return cells, flops, ``transistors`` (smallest estimate
    over ``gate_sets``) and ``transistors_max`` (largest). Raises :class:`SynthesisError`."""
    if top is None:
        raise InputError("top module None: must be a Verilog module name")
    check_synthesis_request(top, gate_sets)
    with yosys_run(verilog_text, [f"synth -top {top}", *mapping_steps(gate_sets)],
                   f"yosys failed on {top}", yosys) as (work, _):
        try:
            generic = parse_stat((work / "generic.json").read_text())
            mapped = {g: parse_stat((work / f"{g}.json").read_text()) for g in gate_sets}
        except (OSError, ValueError, KeyError) as exc:
            raise SynthesisError(f"{top}: {exc}") from None
    low, high = _estimate_range(top, generic["flops"], mapped)
    return {"cells": generic["cells"], "flops": generic["flops"], "transistors": low, "transistors_max": high}


def transistor_range(stat: dict) -> str:
    """Transistor estimate as 'min' or 'min-max' over the ABC mappings."""
    lo, hi = stat["transistors"], stat["transistors_max"]
    return f"{lo}" if lo == hi else f"{lo}-{hi}"


# -- a whole generated top, hierarchy kept (``tespike synthesize``) ---------------------------

def _stat_json(text: str) -> dict:
    """Yosys 0.23's ``stat -json`` of a whole design: with no ``top`` attribute it ends its
    module list with a stray comma (``},\\n\\n}``), which is removed here; nothing else is touched."""
    return json.loads(re.sub(r",\s*\}\s*$", "\n}", text))


def parse_stat_modules(json_text: str) -> dict:
    """Per module of one ``stat -json`` report: its own gate cells (``cells``, ``by_type``,
    ``flops``), the submodule instances it holds (``instances``: name -> count) and its own
    transistor estimate (``None`` without ``-tech cmos``).

    A module with submodules is marked incomplete by Yosys (``"544+"``: a module instance has no
    CMOS cost); its own estimate is the number, accepted only because every cell type of its own
    that is not a module instance is a gate (``$_..._``) of the same mapping.
    """
    modules = _stat_json(json_text).get("modules") or {}
    names = {name.lstrip("\\") for name in modules}
    out = {}
    for raw, design in modules.items():
        by_type = dict(design.get("num_cells_by_type", {}))
        instances = {t.lstrip("\\"): n for t, n in by_type.items() if t.lstrip("\\") in names}
        gates = {t: n for t, n in by_type.items() if t.lstrip("\\") not in names}
        strange = [t for t in gates if not (t.startswith("$_") and t.endswith("_"))]
        if strange:
            raise ValueError(f"module {raw.lstrip(chr(92))}: cell types {strange} are neither gates nor modules")
        transistors = _transistors(design.get("estimated_num_transistors"), f"module {raw.lstrip(chr(92))}:",
                                   submodules=bool(instances))
        out[raw.lstrip("\\")] = {"cells": sum(gates.values()), "by_type": gates, "instances": instances,
                                 "flops": _flops(gates), "transistors": transistors}
    return out


def hierarchy_total(modules: dict, name: str) -> dict:
    """Cells (by type), flip-flops and transistor estimates of module ``name`` with everything it
    instantiates, each submodule counted once per instance."""
    own = modules[name]
    total = {"cells": own["cells"], "flops": own["flops"], "by_type": dict(own["by_type"]),
             "transistors": own.get("transistors"), "transistors_max": own.get("transistors_max")}
    for sub, count in own["instances"].items():
        part = hierarchy_total(modules, sub)
        total["cells"] += count * part["cells"]
        total["flops"] += count * part["flops"]
        for kind, n in part["by_type"].items():
            total["by_type"][kind] = total["by_type"].get(kind, 0) + count * n
        for key in ("transistors", "transistors_max"):
            if total[key] is not None and part[key] is not None:
                total[key] += count * part[key]
    return total


def instance_counts(modules: dict, top: str) -> dict[str, int]:
    """How many times each module occurs in the design under ``top`` (0 for one it never uses)."""
    counts = {name: 0 for name in modules}

    def walk(name: str, times: int) -> None:
        counts[name] += times
        for sub, n in modules[name]["instances"].items():
            walk(sub, times * n)
    walk(top, 1)
    return counts


def top_module(modules: dict) -> str:
    """The one module no other module instantiates (the design's top), or ValueError."""
    if not modules:                                  # (naming a top could not help: there is none)
        raise ValueError("the design defines no module")
    used = {sub for stat in modules.values() for sub in stat["instances"]}
    roots = sorted(set(modules) - used)
    if len(roots) != 1:
        raise ValueError(f"the design has {len(roots)} top modules ({', '.join(roots) or 'none'}); name one")
    return roots[0]


def design_top(verilog_text: str, yosys: str = "yosys") -> str:
    """The one module of ``verilog_text`` no other instantiates, read by Yosys before any synthesis
    (``synth -auto-top`` would pick one of several tops and drop the others without a word), or
    :class:`SynthesisError` naming them."""
    with yosys_run(verilog_text, ["hierarchy", "tee -q -o design.json stat -json"], "yosys failed", yosys,
                   "tespike-top-") as (work, _):
        try:
            modules = _stat_json((work / "design.json").read_text()).get("modules") or {}
            names = {raw.lstrip("\\") for raw in modules}
            return top_module({raw.lstrip("\\"): {"instances": {t.lstrip("\\") for t in stat.get("num_cells_by_type", {})
                                                                  if t.lstrip("\\") in names}}
                               for raw, stat in modules.items()})
        except (OSError, ValueError, KeyError, AttributeError) as exc:
            raise SynthesisError(str(exc)) from None


def _run_measured(command: list[str], cwd: Path) -> tuple[int, str, dict]:
    """Run ``command``; return (exit code, its output, wall seconds, CPU seconds and peak resident MB
    of that one child process, from ``os.wait4``)."""
    start = time.perf_counter()
    proc = children.popen(command, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    with proc.stdout:                  # (closed when a stop interrupts the read: no ResourceWarning line)
        output = proc.stdout.read()
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    return proc.returncode, output, {"seconds": time.perf_counter() - start,
                                     "cpu_seconds": usage.ru_utime + usage.ru_stime,
                                     "peak_mb": usage.ru_maxrss / 1024.0}


def synthesize_hierarchy(verilog_text: str, top: str | None = None, yosys: str = "yosys",
                         gate_sets: tuple[str, ...] = ABC_GATE_SETS) -> dict:
    """Yosys generic synthesis of a whole design with its hierarchy kept (``synth``, no flatten).

    Returns ``top``, ``modules`` (per module its own cells by type, flip-flops, submodule
    instances and own transistor estimates, smallest and largest over ``gate_sets``, by the
    flow of :func:`synthesize_module`) and ``run`` (wall and CPU seconds and peak memory of Yosys).
    ``top=None``: the module no other instantiates. Raises :class:`SynthesisError`.
    """
    check_synthesis_request(top, gate_sets)
    if top is None:
        top = design_top(verilog_text, yosys)
    steps = [f"synth -top {top}", "setattr -mod -unset top", *mapping_steps(gate_sets)]
    with yosys_run(verilog_text, steps, "yosys failed", yosys, "tespike-synthesize-") as (work, run):
        try:
            modules = parse_stat_modules((work / "generic.json").read_text())
            mapped = {g: parse_stat_modules((work / f"{g}.json").read_text()) for g in gate_sets}
        except (OSError, ValueError, KeyError) as exc:
            raise SynthesisError(str(exc)) from None
    for name, stat in modules.items():
        stat["transistors"], stat["transistors_max"] = _estimate_range(
            name, stat["flops"], {gates: other[name] for gates, other in mapped.items()})
    return {"top": top, "modules": modules, "run": run}
