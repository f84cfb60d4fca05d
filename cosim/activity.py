"""Toggles of every flip-flop and output port of a Verilog top, per block, read from a VCD.

The check of :mod:`tespike.golden.activity` (and the place its figures come from when
the model is not trusted): :func:`flip_flops` asks Yosys which signals of the Verilog
text are flip-flops (``proc`` turns every clocked ``always`` into ``$dff`` cells; the
netnames on their Q bits are the registers' names), whatever the top looks like;
:func:`vcd_activity` counts, in an Icarus VCD of a run of that text
(:func:`tespike.cosim.icarus.run_icarus` with ``vcd_path``), the bit changes of each of
those Q bits and of each output port of the top, one settled value per time stamp
(the last one written: no glitches), from the first value after the reset edges on.
:func:`block_of` files every register under a block of :data:`tespike.golden.activity.BLOCKS`
by the module that holds it; a register of a module no block claims is refused,
so a new register in the generated Verilog cannot go uncounted.
"""

from __future__ import annotations

import dataclasses
import json
import re

import numpy as np

from tespike.golden.toggles import pixel_register_names
from tespike.golden.config import SensorConfig
from tespike.golden.errors import InputError

from .synthesis import SynthesisError, yosys_run


@dataclasses.dataclass(frozen=True)
class FlipFlops:
    """One register (a ``$dff``-type cell after ``proc``) of module ``module`` at instance path
    ``path`` ('' for the top): its Q bits as (netname, bit index) of one netname that covers
    them all, and every such netname (``names``: the register and its aliases)."""

    path: str
    module: str
    name: str
    bits: tuple[int, ...]
    names: tuple[str, ...]


def _design_json(verilog_text: str, top: str, yosys: str = "yosys") -> dict:
    with yosys_run(verilog_text, [f"hierarchy -top {top}", "proc", "write_json design.json"],
                   f"yosys could not read {top}", yosys, "tespike-activity-") as (work, _):
        return json.loads((work / "design.json").read_text())


def flip_flops(verilog_text: str, top: str, yosys: str = "yosys") -> tuple[list[FlipFlops], dict[str, int]]:
    """Every register of the design under ``top`` (one entry per instance), and the top's
    output ports with their widths."""
    modules = _design_json(verilog_text, top, yosys)["modules"]
    found: list[FlipFlops] = []

    def walk(module: str, path: str) -> None:
        data = modules[module]
        owners: dict[int, list[tuple[str, int]]] = {}
        for net, info in data["netnames"].items():
            if info.get("hide_name"):
                continue
            if info.get("offset", 0) or info.get("upto", 0):
                raise SynthesisError(f"{module}.{net}: only [n:0] vectors are read")
            for index, bit in enumerate(info["bits"]):
                owners.setdefault(bit, []).append((net, index))
        for cell_name, cell in data["cells"].items():
            kind = cell["type"]
            if kind in modules:
                walk(kind, f"{path}.{cell_name}" if path else cell_name)
                continue
            if "dff" not in kind and "dlatch" not in kind:
                continue
            q = cell["connections"]["Q"]
            full = []
            for net in sorted({n for n, _ in owners.get(q[0], [])}):
                indices = _net_bits(owners, net, q)
                if len(indices) == len(q):
                    full.append((net, tuple(indices)))
            if not full:
                raise SynthesisError(f"{module}: flip-flop {cell_name} has no named signal on its Q bits")
            full.sort(key=lambda item: (item[0].count("."), len(item[0]), item[0]))
            found.append(FlipFlops(path, module, full[0][0], full[0][1], tuple(n for n, _ in full)))

    walk(top, "")
    ports = {name: len(info["bits"]) for name, info in modules[top]["ports"].items()
             if info["direction"] == "output"}
    return found, ports


def _net_bits(owners: dict, net: str, q: list) -> list[int]:
    """The bit index in ``net`` of each Q bit, as far as ``net`` holds them in order."""
    out = []
    for bit in q:
        index = next((i for name, i in owners.get(bit, []) if name == net), None)
        if index is None:
            break
        out.append(index)
    return out


def module_blocks(config: SensorConfig, streaming: bool) -> dict[str, str]:
    """The block (:data:`tespike.golden.activity.BLOCKS`) of every module of a generated top: the
    pixel (and the streaming pixel's combinational rule) ``pixel``, the readout cell ``readout``,
    the timing module (streaming ``<mode>_readout_timing``, parallel ``<mode>_array_timing``)
    ``timing``, the top and its beat groups ``control``. One map for the registers (here), the
    gates (:mod:`tespike.cosim.gate_activity`) and the cells (:func:`tespike.cosim.energy.block_cells`)."""
    from tespike.rtl.names import module_names, stream_module_names

    if streaming:
        names = stream_module_names(config)
        return {names["pixel"]: "pixel", names["rule"]: "pixel", names["cell"]: "readout",
                names["timing"]: "timing", names["group"]: "control", names["group_end"]: "control",
                names["top"]: "control"}
    names = module_names(config)
    return {names["pixel"]: "pixel", names["array_timing"]: "timing", names["top"]: "control"}


def block_of(config: SensorConfig, module: str, name: str, streaming: bool) -> str:
    """The block of a register ``name`` of ``module`` (:func:`module_blocks`); a module no block
    claims is refused."""
    blocks = module_blocks(config, streaming)
    if module not in blocks:
        raise InputError(f"register {name!r} of module {module!r}: no block of the generated top holds it")
    return blocks[module]


def model_name(config: SensorConfig, block: str, names: tuple[str, ...], streaming: bool) -> str:
    """The register name :mod:`tespike.golden.activity` gives a register known in the Verilog as
    ``names`` (the streaming pixel's state registers carry a ``_q`` suffix: its rule's inputs;
    the parallel pixel adds its ``word_reg``, the parallel timing its ``frame_valid_reg``, and
    the parallel top has no register of its own)."""
    state = pixel_register_names(config)
    if streaming:
        known = {"pixel": ("charge_sample",) + state, "readout": ("held",),
                 "timing": ("divider", "cycle", "primed"), "control": ("rst_sample", "sending", "beat")}
    else:
        known = {"pixel": state + ("word_reg",), "readout": (), "timing": ("divider", "cycle", "frame_valid_reg"),
                 "control": ()}
    for name in names:
        base = name.rsplit(".", 1)[-1]
        for candidate in (base, base.removesuffix("_q") if streaming else base):
            if candidate in known[block]:
                return candidate
    raise InputError(f"register {'/'.join(names)} of block {block}: not one the model counts "
                     f"({', '.join(known[block]) or 'none'})")


def settled_values(tv) -> list[int | None]:
    """One value per time stamp (the last written), as integers (None for x or z bits)."""
    final = {}
    for time, value in tv:
        final[time] = value
    return [int(v, 2) if set(v) <= {"0", "1"} else None for _, v in sorted(final.items())]


def bit_changes(values: list[int | None], mask: int) -> int:
    """Bit changes within ``mask`` between consecutive known values (the first value is the
    initial state, not a change; an unknown value breaks the chain)."""
    total, previous = 0, None
    for value in values:
        if previous is not None and value is not None:
            total += ((previous ^ value) & mask).bit_count()
        previous = value
    return total


def vcd_activity(vcd_path, config: SensorConfig, verilog_text: str, top: str, streaming: bool,
                 scope: str) -> dict[tuple[str, str], int]:
    """Toggles per (block, register or port name) in the VCD of a run of ``verilog_text``, summed
    over instances; the top is at ``scope`` (e.g. ``tespike_tb.dut``)."""
    from .vcd import vcd_reader
    VCDVCD = vcd_reader()
    registers, ports = flip_flops(verilog_text, top)
    header = VCDVCD(str(vcd_path), only_sigs=True)
    by_base = {re.sub(r"\[\d+:\d+\]$", "", ref): ref for ref in header.references_to_ids}

    def signal(path: str) -> str:
        full = f"{scope}.{path}"
        if full not in by_base:
            raise InputError(f"waveform {str(vcd_path)!r} has no signal {full!r}")
        return by_base[full]

    wanted = {}
    for reg in registers:
        wanted[reg] = signal(f"{reg.path}.{reg.name}" if reg.path else reg.name)
    outputs = {port: signal(port) for port in ports}
    vcd = VCDVCD(str(vcd_path), signals=sorted(set(wanted.values()) | set(outputs.values())), store_tvs=True)
    counts: dict[tuple[str, str], int] = {}
    for reg, ref in wanted.items():
        block = block_of(config, reg.module, reg.name, streaming)
        key = (block, model_name(config, block, reg.names, streaming))
        mask = sum(1 << i for i in reg.bits)
        counts[key] = counts.get(key, 0) + bit_changes(settled_values(vcd[ref].tv), mask)
    for port, ref in outputs.items():
        counts[("output", port)] = bit_changes(settled_values(vcd[ref].tv), (1 << ports[port]) - 1)
    return counts


def register_bits(verilog_text: str, top: str, config: SensorConfig, streaming: bool) -> dict[tuple[str, str], int]:
    """Flip-flops per (block, model name) that Yosys finds in the Verilog, summed over instances."""
    registers, _ = flip_flops(verilog_text, top)
    out: dict[tuple[str, str], int] = {}
    for reg in registers:
        block = block_of(config, reg.module, reg.name, streaming)
        key = (block, model_name(config, block, reg.names, streaming))
        out[key] = out.get(key, 0) + len(reg.bits)
    return out


def edges_after_reset(vcd_path, scope: str) -> int:
    """Rising edges of ``clk`` with ``rst`` low in the VCD of a run (the model's ``edges``)."""
    from .vcd import rising_edges, vcd_reader
    VCDVCD = vcd_reader()

    vcd = VCDVCD(str(vcd_path), signals=[f"{scope}.clk", f"{scope}.rst"], store_tvs=True)
    edges = rising_edges(vcd[f"{scope}.clk"])
    changes = vcd[f"{scope}.rst"].tv
    times = np.array([t for t, _ in changes], np.int64)
    before = np.searchsorted(times, edges, side="left") - 1   # rst as the edge samples it
    return int(sum(1 for i in before if i >= 0 and changes[i][1] == "0"))
