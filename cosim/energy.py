"""Energy of a readout from toggles and synthesised cells: a named first-order CV^2 model.

Model :data:`SKY130_HD` ("CV^2, sky130_fd_sc_hd, 1.8 V"): dynamic energy only, every
number below written where it is used and in docs/energy.md.

* A node of capacitance C that makes one transition (0 -> 1 or 1 -> 0) costs on average
  C V^2 / 2 from the supply (charging draws C V^2, half of it is stored and released on
  the discharge): the textbook switching energy, P = alpha C V^2 f (Weste and Harris,
  *CMOS VLSI Design*, 4th ed., section 5.1; Rabaey, *Digital Integrated Circuits*, ch. 5).
* Supply V = 1.8 V: the nominal VDD of SkyWater's open 130 nm PDK, high-density library
  ``sky130_fd_sc_hd`` (skywater-pdk.readthedocs.io, "SkyWater Foundry Provided Standard
  Cell Libraries").
* Unit capacitance C_in = 2.3 fF: one input pin of the library's smallest NAND,
  ``sky130_fd_sc_hd__nand2_1`` (liberty: pin A 0.00225 pF at ff_n40C_1v76, 0.00220 pF at
  ff_n40C_1v65; tt about the same), the load one gate input puts on a node.
* Every other capacitance is a stated multiple of C_in (assumptions, not library data):
  a logic node (a gate's output) is ``node_inputs`` = 3 C_in (a fan-out of two inputs plus
  the driver's own diffusion and a short local wire, about one input's worth);
  a flip-flop whose stored bit changes also switches ``flop_internal_inputs`` = 4 C_in of
  master and slave latch nodes; every flip-flop's clock pin, its internal clock phases and
  its share of the clock tree are ``clock_inputs`` = 4 C_in, charged and discharged on
  every clock whatever the data (no clock gating), C V^2 per flip-flop per clock.
* Combinational gates: no gate-level simulation here. A block's gates are taken to toggle,
  per gate per clock, as often as its flip-flops do per bit per clock (the block's
  register activity: toggles / register bits / clocks), so a block's gate toggles are
  gates x register toggles / register bits. Glitches are not counted.
* Output ports: one logic node per bit toggle; pads, bond wires and the long wires to
  them are left out (their toggles are reported), as are the analog front end, leakage
  (static power: excluded) and wires beyond the local-node share above.

Integer counts in, float64 joules out.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from tespike.golden.activity import BLOCKS, Activity
from tespike.golden.config import SensorConfig
from tespike.golden.errors import InputError, is_count, is_positive_number


@dataclasses.dataclass(frozen=True)
class EnergyModel:
    """Per-event energies of a CV^2 model: supply ``vdd`` (V), unit capacitance ``c_input`` (F)
    and the capacitances of a logic node, a flip-flop's internal nodes and its clock load in
    units of ``c_input`` (module docstring)."""

    name: str
    vdd: float
    c_input: float
    node_inputs: float
    flop_internal_inputs: float
    clock_inputs: float

    def __post_init__(self):
        """Refuse a model that is no physical one in one line (a negative supply had given
        negative joules, a text one a TypeError at the first figure)."""
        if not isinstance(self.name, str):
            raise InputError(f"energy model name {self.name!r}: must be text")
        for key in ("vdd", "c_input"):
            if not is_positive_number(getattr(self, key)):
                raise InputError(f"energy model {key} = {getattr(self, key)!r}: must be a finite number > 0")
        for key in ("node_inputs", "flop_internal_inputs", "clock_inputs"):
            value = getattr(self, key)
            if not (value == 0 or is_positive_number(value)):
                raise InputError(f"energy model {key} = {value!r}: must be a finite number >= 0")

    @property
    def gate_toggle(self) -> float:
        """J per toggle of one logic node (a gate output, an output port bit): C_node V^2 / 2."""
        return 0.5 * self.node_inputs * self.c_input * self.vdd ** 2

    @property
    def flop_toggle(self) -> float:
        """J per toggle of a flip-flop's stored bit: its output node and its internal latch nodes."""
        return 0.5 * (self.node_inputs + self.flop_internal_inputs) * self.c_input * self.vdd ** 2

    @property
    def clock_per_flop(self) -> float:
        """J per flip-flop per clock: its clock load charged and discharged, C_clk V^2."""
        return self.clock_inputs * self.c_input * self.vdd ** 2


#: The model of the docs: sky130_fd_sc_hd at 1.8 V, 2.3 fF unit input (module docstring).
SKY130_HD = EnergyModel(name="CV^2, sky130_fd_sc_hd, 1.8 V", vdd=1.8, c_input=2.3e-15,
                        node_inputs=3.0, flop_internal_inputs=4.0, clock_inputs=4.0)

#: The parts of a block's energy.
PARTS = ("data", "logic", "clock")


def check_model(model) -> "EnergyModel":
    if not isinstance(model, EnergyModel):
        raise InputError(f"energy model {model!r}: must be an EnergyModel (e.g. SKY130_HD), "
                         f"not {type(model).__name__}")
    return model


def block_energy(toggles, register_bits: int, flops: int, gates: int, clocks: int,
                 model: EnergyModel = SKY130_HD) -> dict[str, np.ndarray]:
    """Energy (J, float64) of one block over ``clocks`` clocks: ``data`` (its register bit
    toggles), ``logic`` (its gates, toggling at the register activity: gates x toggles /
    register bits), ``clock`` (its synthesised flip-flops, every clock). ``toggles`` may be an
    array (one entry per instance or per case; counts, or their means); the other counts are
    per instance."""
    check_model(model)
    for name, value in (("register_bits", register_bits), ("flops", flops), ("gates", gates), ("clocks", clocks)):
        if not is_count(value):                          # (-4 bits or 2.5 flops had been figures)
            raise InputError(f"block_energy {name} = {value!r}: must be an integer >= 0")
    toggles = np.asarray(toggles)
    if toggles.dtype.kind not in "fiu" or (toggles.size and not (np.isfinite(toggles).all() and toggles.min() >= 0)):
        raise InputError("block_energy toggles: must be finite counts >= 0")
    toggles = toggles.astype(np.float64, copy=False)
    data = toggles * model.flop_toggle
    logic = gates * toggles / register_bits * model.gate_toggle if register_bits else 0.0 * toggles
    clock = np.full_like(toggles, float(flops) * clocks * model.clock_per_flop)
    return {"data": data, "logic": logic, "clock": clock}


def block_cells(modules: dict, top: str, config, streaming: bool) -> dict[str, dict[str, int]]:
    """Flip-flops and gates (other cells) per block of a synthesised generated top
    (:func:`tespike.cosim.synthesis.synthesize_hierarchy`'s ``modules``), every instance counted,
    each module under its block of :func:`tespike.cosim.activity.module_blocks` (the parallel top
    holds no flip-flop: its ``frame`` is the pixels' word registers, its ``frame_valid`` the
    timing module's)."""
    from .activity import module_blocks
    from .synthesis import instance_counts

    config = SensorConfig.required(config, "block_cells")
    if not isinstance(modules, dict) or top not in modules:
        raise InputError(f"block_cells: the synthesised modules hold no top {top!r} "
                         "(synthesize_hierarchy's modules of that top)")
    blocks = module_blocks(config, streaming)
    out = {block: {"flops": 0, "gates": 0} for block in BLOCKS}
    for name, times in instance_counts(modules, top).items():
        if not times:
            continue
        if name not in blocks:
            raise ValueError(f"module {name} of {top}: no block claims it")
        stat = modules[name]
        out[blocks[name]]["flops"] += times * stat["flops"]
        out[blocks[name]]["gates"] += times * (stat["cells"] - stat["flops"])
    return out


def run_energy(activity: Activity, cells: dict[str, dict[str, int]],
               model: EnergyModel = SKY130_HD) -> dict[str, dict[str, float]]:
    """Energy (J) of each block over the run's counted edges: ``data``, ``logic``, ``clock`` and
    ``total``; the output block is its port bit toggles at one logic node each."""
    check_model(model)
    if not isinstance(activity, Activity):
        raise InputError(f"run_energy activity: must be an Activity (tespike.golden.activity.top_activity), "
                         f"not {type(activity).__name__}")
    missing = [block for block in BLOCKS if block != "output" and not (
        isinstance(cells, dict) and isinstance(cells.get(block), dict) and {"flops", "gates"} <= set(cells[block]))]
    if missing:                                          # (a KeyError of the first block)
        raise InputError(f"run_energy cells: no flops and gates of block {missing[0]!r} (block_cells' result)")
    totals = activity.per_block()
    bits = activity.register_bits()
    out = {}
    for block in BLOCKS:
        if block == "output":
            data = totals[block] * model.gate_toggle
            out[block] = {"data": data, "logic": 0.0, "clock": 0.0, "total": data}
            continue
        parts = block_energy(totals[block], bits[block], cells[block]["flops"], cells[block]["gates"],
                             activity.edges, model)
        out[block] = {part: float(parts[part]) for part in PARTS}
        out[block]["total"] = sum(out[block][part] for part in PARTS)
    return out
