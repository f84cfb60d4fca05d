"""Bit toggles of every register and output bus of the generated Verilog tops, per block.

:mod:`tespike.golden.toggles` counts the pixel's own state; a chip switches more. This
model follows the tops that ``tespike verilog`` writes, edge by edge after their reset
(the Icarus testbench's: power-up state, ``rst`` high for some clocks with no charge,
then one stimulus row per rising edge), and counts the bit changes of

* ``pixel``: each site's state (``acc``, TE ``sfc`` / ``ovf`` / ``m``, ML ``count``);
  the streaming pixel's registers are ``acc_q``, ``sfc_q``, ... behind its input
  register ``charge_sample`` (E bits, counted here); the parallel pixel's are
  ``acc``, ``sfc``, ... and its readout ``word_reg`` (Wd bits: ``frame`` is these
  registers), with no input register (its pixels take ``charge`` from the port);
* ``readout``: the streaming top's readout cells ``held`` (Wd bits each, one per
  site: the per-lane shift registers);
* ``timing``: the S_h ``divider`` (when F > 1) and the CCC register ``cycle`` (when
  alpha > 1); the streaming top's timing adds ``primed``, the parallel top's
  (``<mode>_array_timing``) the output register ``frame_valid_reg``;
* ``control``: the streaming top's ``rst_sample`` and beat counter ``sending`` /
  ``beat`` (the parallel top has no register of its own);
* ``output``: the output ports, settled once per clock (streaming ``out_valid``,
  ``out_first``, ``out_words`` per lane; parallel ``frame_valid`` and ``frame`` per
  pixel, both straight from the registers above).

The two tops see the stimulus one edge apart: the streaming top's edge u processes the
charge its input register sampled at edge u - 1 (its timing shows clock u - 1, reset to
clock -1), the parallel top's edge u the charge on the port (its timing shows clock u,
reset to clock 0), and ``rst`` clears the parallel pixels at the reset edges themselves.
Both reset to their power-up state, so a reset costs no toggles but the streaming
``rst_sample``'s two.

The registers' sequences follow SPEC sections 1, 3, 4 and 6 and the structure
of :mod:`tespike.rtl.verilog_stream` / :mod:`tespike.rtl.verilog` (input register, rule,
timing phase, word registers, shift-register readout, beat counter): the input register
and the timing are whole-run numpy expressions; the pixel state, the word registers and
the readout cells one numpy step per clock over all sites.
``tests/test_golden_activity.py`` holds every count equal, block by block and register
by register, to an Icarus VCD of the generated Verilog, and every flip-flop Yosys finds
in that Verilog to a register named here. Glitches (several changes inside one clock)
are not counted: one settled value per clock, as the VCD's last value at each time stamp.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .config import SensorConfig
from .errors import InputError, check_flag, is_count
from .io import check_stimulus
from .toggles import flips, pixel_register_bits, pixel_register_names, register_step

#: The blocks of a generated top, in report order.
BLOCKS = ("pixel", "readout", "timing", "control", "output")


@dataclasses.dataclass
class Activity:
    """Toggles of one run of a generated top.

    ``toggles[(block, name)]``: int64 array, one entry per instance of the register or
    port (per site for pixel registers, readout cells and ``frame``; per lane for
    ``out_words``; one for the rest). ``bits[(block, name)]``: its width in bits.
    ``edges``: rising clock edges counted; ``readouts``: S_r strobes (``frame_valid``)
    among them.
    """

    toggles: dict[tuple[str, str], np.ndarray]
    bits: dict[tuple[str, str], int]
    edges: int
    readouts: int

    def per_block(self) -> dict[str, int]:
        """Total toggles of each block (every instance of every register or port)."""
        out = {block: 0 for block in BLOCKS}
        for (block, _), counts in self.toggles.items():
            out[block] += int(counts.sum())
        return out

    def register_bits(self) -> dict[str, int]:
        """Flip-flops each block's registers hold (the output ports are wires, 0)."""
        out = {block: 0 for block in BLOCKS}
        for (block, name), width in self.bits.items():
            if block != "output":
                out[block] += width * self.toggles[(block, name)].size
        return out


def _sequence_toggles(states: np.ndarray, start: int) -> np.ndarray:
    """Toggles of a register whose value before edge u is ``states[u]`` (u = 0..U, axis 0),
    counting the edges u >= ``start``."""
    return flips(states[start:-1], states[start + 1:]).sum(axis=0)


def timing_states(config: SensorConfig, edges: int, *, sampled_input: bool = True) -> dict[str, np.ndarray]:
    """The timing block before each edge u = 0..edges, with the ``last`` and ``frame_valid`` it
    drives. Sampled input (the streaming top): it shows clock u - 1 (clock -1 after reset:
    divider F - 1, CCC alpha, ``primed`` low), so ``divider = (u - 1) mod F``,
    ``cycle = ((u - 1) mod L) div F + 1``, ``frame_valid = last & primed``.
    ``sampled_input=False`` (the parallel top's ``<mode>_array_timing``): it shows clock u
    (reset: clock 0) and ``frame_valid`` is its register ``frame_valid_reg``, ``last`` one edge
    later (low after reset)."""
    config = SensorConfig.required(config, "timing_states")
    if not is_count(edges):                              # (2.5 had made four states)
        raise InputError(f"edges = {edges!r}: must be an integer >= 0")
    F, L, alpha = config.clocks_per_tick, config.clocks_per_readout, config.alpha
    clock = np.arange(edges + 1, dtype=np.int64) - (1 if sampled_input else 0)
    divider = clock % F
    cycle = (clock % L) // F + 1
    last = ((divider == F - 1) & (cycle == alpha)).astype(np.int64)
    out = {"divider": divider, "cycle": cycle, "last": last}
    if sampled_input:
        out["primed"] = (clock >= 0).astype(np.int64)
        out["frame_valid"] = last & out["primed"]
    else:
        out["frame_valid"] = np.concatenate([np.zeros(1, np.int64), last[:-1]])
    return out


def top_activity(config: SensorConfig, electrons: np.ndarray, lanes: int | None = None, *,
                 edges: int | None = None, reset: bool = True, start: int = 0) -> Activity:
    """Toggles of the generated top of an H x W array fed ``electrons`` (T, H, W) integers.

    ``lanes``: the streaming top with N lanes (``tespike verilog --lanes N``); None: the
    parallel top. ``edges``: rising edges with ``rst`` low to run (the stimulus, then zero
    charge; default T + B + 1 streaming, T + 1 parallel: every word out and, parallel, the
    last ``frame_valid`` sampled). ``reset``: the run begins with ``rst`` high for one clock
    or more (the streaming ``rst_sample`` rises and falls: 2 toggles; the parallel top's
    reset state is its power-up state); otherwise straight from power-up. ``start``: count
    only the edges u >= start (a window in steady state for per-readout figures).
    """
    c = SensorConfig.checked(config, "top_activity")
    e = np.asarray(electrons)
    check_stimulus(e, c, whole_readouts=False, what="electrons")   # integers (T, H, W) in 0..2^E - 1
    e = e.astype(np.int64, copy=False)
    T, H, W = e.shape
    if lanes is not None and not is_count(lanes, 1):
        raise InputError(f"lanes = {lanes!r}: must be an integer >= 1 (the streaming top) or None (the parallel top)")
    P = H * W
    streaming = lanes is not None
    beats = -(-P // lanes) if streaming else 1
    if edges is not None and not is_count(edges):        # (2.5 had run 2 edges, '5' five)
        raise InputError(f"edges = {edges!r}: must be an integer >= 0 or None (the whole run)")
    if not is_count(start):
        raise InputError(f"start = {start!r}: must be an integer >= 0")
    check_flag(reset, "reset")                           # ('no' had meant a reset)
    U = (T + (beats + 1 if streaming else 1)) if edges is None else int(edges)
    if U < 0 or not 0 <= start <= U:
        raise InputError(f"edges = {U}, start = {start}: need 0 <= start <= edges")
    # the charge edge u processes: streaming, charge_sample before edge u (row u - 1);
    # parallel, the port at edge u (row u)
    charge = np.zeros((U + 1, P), np.int64)
    rows = min(T, U)
    charge[int(streaming):rows + int(streaming)] = e[:rows].reshape(rows, P)
    timing = timing_states(c, U, sampled_input=streaming)
    names, widths = pixel_register_names(c), pixel_register_bits(c)

    t, bits = {}, {}
    if streaming:
        t[("pixel", "charge_sample")] = _sequence_toggles(charge, start)
        bits[("pixel", "charge_sample")] = c.input_bits
    state = {name: np.zeros(P, np.int64) for name in names}
    counts = {name: np.zeros(P, np.int64) for name in names}
    held = np.zeros(P, np.int64)                      # streaming readout cells
    held_count = np.zeros(P, np.int64)
    frame = np.zeros((U + 1, P), np.int64) if not streaming else None   # parallel word_reg before edge u
    control = np.zeros((U + 1, 2), np.int64)          # sending, beat before edge u
    lanes_out = np.zeros((U + 1, lanes if streaming else 1), np.int64)
    beat_bits = max(1, beats.bit_length())
    sending = beat = 0
    n = lanes if streaming else 0
    for u in range(U):
        last, fv = int(timing["last"][u]), int(timing["frame_valid"][u])
        nxt, word = register_step(c, state, charge[u], int(timing["cycle"][u]), bool(last))
        if u >= start:
            for name in names:
                counts[name] += flips(state[name], nxt[name])
        state = nxt
        if not streaming:
            frame[u + 1] = word if last else frame[u]
            continue
        if fv:
            new = word
        elif sending:
            new = np.concatenate([held[n:], np.zeros(min(n, P), np.int64)])
        else:
            new = held
        if u >= start and new is not held:
            held_count += flips(held, new)
        held = new
        if fv:
            sending, beat = 1, 0
        elif sending:
            sending = int(beat != beats - 1)
            beat = (beat + 1) % (1 << beat_bits)
        control[u + 1] = (sending, beat)
        lanes_out[u + 1, :min(n, P)] = held[:n]

    for name in names:
        t[("pixel", name)] = counts[name]
        bits[("pixel", name)] = widths[name]
    if not streaming:
        t[("pixel", "word_reg")], bits[("pixel", "word_reg")] = _sequence_toggles(frame, start), c.word_bits
    if c.clocks_per_tick > 1:
        t[("timing", "divider")] = _sequence_toggles(timing["divider"][:, None], start)
        bits[("timing", "divider")] = (c.clocks_per_tick - 1).bit_length()
    if c.alpha > 1:
        t[("timing", "cycle")] = _sequence_toggles(timing["cycle"][:, None], start)
        bits[("timing", "cycle")] = c.b2
    if streaming:
        flag, values = "primed", timing["primed"]
    else:
        flag, values = "frame_valid_reg", timing["frame_valid"]     # the frame_valid port's register
    t[("timing", flag)], bits[("timing", flag)] = _sequence_toggles(values[:, None], start), 1
    if streaming:
        t[("control", "rst_sample")] = np.array([2 if reset and start == 0 else 0], np.int64)
        bits[("control", "rst_sample")] = 1
        t[("readout", "held")], bits[("readout", "held")] = held_count, c.word_bits
        t[("control", "sending")] = _sequence_toggles(control[:, :1], start)
        t[("control", "beat")] = _sequence_toggles(control[:, 1:], start)
        bits[("control", "sending")], bits[("control", "beat")] = 1, beat_bits
        first = control[:, :1] & (control[:, 1:] == 0)
        ports = {"out_valid": (control[:, :1], 1), "out_first": (first, 1), "out_words": (lanes_out, c.word_bits)}
    else:
        ports = {"frame_valid": (timing["frame_valid"][:, None], 1), "frame": (frame, c.word_bits)}
    for name, (values, width) in ports.items():
        t[("output", name)], bits[("output", name)] = _sequence_toggles(values, start), width
    readouts = int(timing["frame_valid"][start:U].sum())
    return Activity(t, bits, U - start, readouts)
