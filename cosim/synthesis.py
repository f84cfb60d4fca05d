"""Yosys synthesis of the project's Verilog: cells, flip-flops and a CMOS transistor estimate.

One function, :func:`synthesize`, for both the demo's small cost table
(:mod:`cosim.demo`) and the full study (``benchmarks/hw_cost.py``,
``docs/hardware-cost.md``). ``synth -top <module>; stat`` counts cells of
Yosys's internal gate library and flip-flops; then every flip-flop is legalised
to a plain D flip-flop (reset and enable become gates), the logic is mapped by
ABC to each gate set of :data:`ABC_GATE_SETS` and counted with
``stat -tech cmos``. ABC is heuristic: the same logic maps a few percent larger
or smaller, so the result is the smallest estimate and the largest (their gap
is the mapping noise).

One rule for Yosys's estimate: a count it marks incomplete (``"1574+"``: some
cell type has no entry in its CMOS table) is refused, never read as a number:
it is a lower bound of unknown slack, and every gate set here maps only to cells
the table covers, so a "+" means the flow broke.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import tempfile
from pathlib import Path

#: ABC gate sets tried for the transistor estimate (all have entries in Yosys's CMOS table).
ABC_GATE_SETS = ("cmos2", "cmos3", "cmos4", "gates")


class SynthesisError(RuntimeError):
    """Yosys is missing, failed, or reported what cannot be read as a cost."""


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
    flops = sum(n for kind, n in by_type.items() if "DFF" in kind or "DLATCH" in kind)
    transistors = design.get("estimated_num_transistors")
    if transistors is not None:
        text = str(transistors)
        if not text.isdigit():
            raise ValueError(f"Yosys transistor estimate {text!r} is incomplete (a cell type has no CMOS cost)")
        transistors = int(text)
    return {"cells": int(design["num_cells"]), "flops": flops, "transistors": transistors,
            "by_type": dict(by_type)}


def yosys_missing(yosys: str = "yosys") -> str | None:
    """Why Yosys cannot run here, or None when it can."""
    return None if shutil.which(yosys) else f"Yosys ({yosys!r}) is not installed"


def synthesize(verilog_text: str, top: str, yosys: str = "yosys",
               gate_sets: tuple[str, ...] = ABC_GATE_SETS) -> dict:
    """Synthesize module ``top``; return cells, flops, ``transistors`` (smallest estimate
    over ``gate_sets``) and ``transistors_max`` (largest). Raises :class:`SynthesisError`."""
    missing = yosys_missing(yosys)
    if missing:
        raise SynthesisError(missing)
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / "design.v"
        src.write_text(verilog_text)
        steps = [f"read_verilog {src}", f"synth -top {top}", f"tee -q -o {tmp}/generic.json stat -json",
                 "dfflegalize -cell $_DFF_P_ 01", "opt_clean", "design -save legal"]
        for gates in gate_sets:
            steps += ["design -load legal", f"abc -g {gates}", "opt_clean",
                      f"tee -q -o {tmp}/{gates}.json stat -json -tech cmos"]
        result = subprocess.run([yosys, "-q", "-p", "; ".join(steps)], capture_output=True, text=True)
        if result.returncode != 0:
            lines = (result.stderr or result.stdout).strip().splitlines()
            raise SynthesisError(f"yosys failed on {top}: {lines[-1] if lines else 'no message'}")
        try:
            generic = parse_stat((Path(tmp) / "generic.json").read_text())
            mapped = {g: parse_stat((Path(tmp) / f"{g}.json").read_text()) for g in gate_sets}
        except (OSError, ValueError, KeyError) as exc:
            raise SynthesisError(f"{top}: {exc}") from None
    for gates, stat in mapped.items():
        if stat["flops"] != generic["flops"]:
            raise SynthesisError(f"{top}: flip-flop count changed in the {gates} mapping "
                                 f"({generic['flops']} -> {stat['flops']})")
    estimates = [stat["transistors"] for stat in mapped.values()]
    return {"cells": generic["cells"], "flops": generic["flops"],
            "transistors": min(estimates), "transistors_max": max(estimates)}


def span(stat: dict) -> str:
    """Transistor estimate as 'min' or 'min-max' over the ABC mappings."""
    lo, hi = stat["transistors"], stat["transistors_max"]
    return f"{lo}" if lo == hi else f"{lo}-{hi}"
