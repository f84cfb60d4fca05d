"""Toggles of every gate of the synthesised netlist, per block: a measurement of the energy
model's one assumption about logic.

:mod:`tespike.cosim.energy` prices a block's gates at its register activity (gate toggles =
gates x register toggles / register bits), because nothing here simulates gates at sensor
size. This module measures what that leaves out, on small arrays: Yosys synthesises the
generated top (``synth``, hierarchy kept, the flow of :mod:`tespike.cosim.synthesis`), names
every net (``rename -enumerate``) and writes the gate netlist as Verilog (gates as
expressions, flip-flops as clocked blocks with their initial values); Icarus runs that
netlist on the stimulus with a VCD (:mod:`tespike.cosim.icarus`, whose checks hold it to the
golden model's words); every output bit of every gate is counted in the VCD, one settled
value per clock (zero-delay: no glitches), and filed under its block as
:mod:`tespike.cosim.activity` files registers.
"""

from __future__ import annotations

import json
from pathlib import Path

from tespike.golden.atomic import work_folder
from tespike.golden.activity import BLOCKS
from tespike.golden.config import SensorConfig
from tespike.golden.errors import InputError

from .activity import bit_changes, module_blocks, settled_values
from .synthesis import SynthesisError, yosys_run


def gate_netlist(verilog_text: str, top: str, yosys: str = "yosys") -> tuple[str, dict]:
    """(the synthesised gate netlist as Verilog, Yosys's JSON of the same design)."""
    steps = [f"synth -top {top}", "rename -enumerate", "write_verilog -noattr gates.v", "write_json gates.json"]
    with yosys_run(verilog_text, steps, f"yosys could not synthesise {top}", yosys, "tespike-gates-") as (work, _):
        return (work / "gates.v").read_text(), json.loads((work / "gates.json").read_text())


def gate_outputs(design: dict, top: str, config: SensorConfig, streaming: bool) -> list[tuple[str, str, str, int]]:
    """Every gate output bit under ``top``: (block, instance path, net name, bit index)."""
    modules = design["modules"]
    blocks = module_blocks(config, streaming)
    out = []

    def walk(module: str, path: str) -> None:
        data = modules[module]
        owner = {}
        for net, info in data["netnames"].items():
            if not info.get("hide_name"):
                for index, bit in enumerate(info["bits"]):
                    owner.setdefault(bit, (net, index))
        if module not in blocks:
            raise InputError(f"module {module!r}: no block of the generated top holds it")
        block = blocks[module]
        for name, cell in data["cells"].items():
            kind = cell["type"]
            if kind in modules:
                walk(kind, f"{path}.{name}" if path else name)
            elif "DFF" not in kind and "DLATCH" not in kind:
                for bit in cell["connections"]["Y"]:
                    if bit not in owner:
                        raise SynthesisError(f"{module}: gate {name} drives a net with no name")
                    out.append((block, path, *owner[bit]))

    walk(top, "")
    return out


def vcd_gate_toggles(vcd_path, design: dict, top: str, config: SensorConfig, streaming: bool,
                     scope: str) -> tuple[dict[str, int], dict[str, int]]:
    """(gate output toggles per block, gate outputs per block) in the VCD of a run of the netlist."""
    import re

    from .vcd import vcd_reader
    VCDVCD = vcd_reader()
    outputs = gate_outputs(design, top, config, streaming)
    header = VCDVCD(str(vcd_path), only_sigs=True)
    by_base = {re.sub(r"\[\d+:\d+\]$", "", ref): ref for ref in header.references_to_ids}
    refs = {}
    for block, path, net, index in outputs:
        where = f"{scope}.{path}" if path else scope
        # a name Verilog must escape (``m[0]``: a memory Yosys split into registers) keeps its backslash
        found = [by_base[name] for name in (f"{where}.{net}", f"{where}.\\{net}") if name in by_base]
        if not found:
            raise InputError(f"waveform {str(vcd_path)!r} has no signal {where}.{net!r}")
        refs.setdefault(found[0], []).append((block, index))
    vcd = VCDVCD(str(vcd_path), signals=sorted(refs), store_tvs=True)
    toggles = {block: 0 for block in BLOCKS}
    gates = {block: 0 for block in BLOCKS}
    for ref, bits in refs.items():
        values = settled_values(vcd[ref].tv)
        for block, index in bits:
            toggles[block] += bit_changes(values, 1 << index)
            gates[block] += 1
    return toggles, gates


def logic_check(config: SensorConfig, electrons, lanes: int) -> dict[str, dict[str, float]]:
    """Gate toggles per block of the streaming top on ``electrons`` (T, H, W), measured on the
    synthesised netlist (Icarus, checked against the golden model's beats) and as
    :mod:`tespike.cosim.energy` estimates them from the registers: ``gates``, ``measured``,
    ``estimated`` and their ``ratio`` (measured / estimated) per block."""
    import numpy as np

    from tespike.golden.activity import top_activity
    from tespike.golden.beats import beats
    from tespike.golden.sensor import simulate

    from tespike.golden.io import check_stimulus

    from .activity import edges_after_reset
    from .icarus import DUT_SCOPE, run_icarus_stream
    from .tops import Top

    config = SensorConfig.required(config, "logic_check")
    electrons = np.asarray(electrons)
    check_stimulus(electrons, config, what="electrons")  # (a list had been an AttributeError of .shape)
    top = Top(config, electrons.shape[1], electrons.shape[2], lanes)
    netlist, design = gate_netlist(top.verilog(), top.module)
    with work_folder("tespike-gates-") as tmp:
        vcd = Path(tmp) / "gates.vcd"
        words = run_icarus_stream(config, electrons, lanes, verilog=netlist, vcd_path=vcd)
        if not np.array_equal(words, beats(simulate(config, electrons), lanes)):
            raise SynthesisError(f"the synthesised netlist of {top.module} does not give the golden model's beats")
        activity = top_activity(config, electrons, lanes, edges=edges_after_reset(vcd, DUT_SCOPE))
        measured, gates = vcd_gate_toggles(vcd, design, top.module, config, True, DUT_SCOPE)
    toggles, bits = activity.per_block(), activity.register_bits()
    out = {}
    for block in BLOCKS:
        if not bits[block]:
            continue
        estimated = gates[block] * toggles[block] / bits[block]
        out[block] = {"gates": gates[block], "measured": measured[block], "estimated": estimated,
                      "ratio": measured[block] / estimated if estimated else float("nan")}
    return out
