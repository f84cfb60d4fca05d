"""cocotb testbench of the generated array Verilog: SPEC section 6 ports only, golden model as scoreboard.

cocotb loads this module inside the simulator (Icarus, Verilator, or any
simulator cocotb supports). The test :func:`spec_ports_equal_golden` drives
only ``clk``, ``rst`` and ``charge`` and reads only ``frame_valid`` and
``frame``, so it checks any Verilog with the ports of SPEC section 6, not only
the generated one:

1. ``rst`` high for :data:`tespike.cosim.outside.RESET_CLOCKS` rising edges;
2. for pixel clock t = 0, 1, ...: at the falling edge, ``rst`` low (or, with
   ``TESPIKE_RESETS``, the reset vector's value) and stimulus
   row t on ``charge``; one simulator step later (the logic has settled) ``frame_valid`` and,
   when it is high, ``frame`` are sampled: the values the rising edge t sees;
   then the rising edge;
3. after the stimulus, zero charge for up to L + 1 clocks until every readout
   has been seen.

The scoreboard is the literal SPEC rule, :func:`tespike.golden.reference.step_reference`,
on the same stimulus. The test fails, naming what went wrong, on an X or Z on
``frame_valid`` or on a sampled ``frame``, on a ``frame_valid`` count or latency
that breaks SPEC section 6 (:func:`tespike.cosim.outside.check_captures`: one pulse per
interval, one fixed latency in 0..L), or on the first word that differs.

Settings come from environment variables, which :mod:`tespike.cosim.cocotb_run` (and so
``tespike cocotb`` and the tests) sets, and which a designer sets by hand in a
cocotb Makefile flow (docs/outside-simulators.md):

``TESPIKE_CONFIG``
    a preset name (``te``, ``ml``, ``ml-msb``), a JSON file or JSON text (default ``te``);
``TESPIKE_HEIGHT``, ``TESPIKE_WIDTH``
    the array's size (required: the port widths are checked against them);
``TESPIKE_STIMULUS``
    an ``E.npy`` file (T, H, W) of electrons per pixel clock; without it
    :func:`default_stimulus` makes ``TESPIKE_READOUTS`` (default 3) intervals of
    it from ``TESPIKE_SEED`` (default 0);
``TESPIKE_RESETS``
    reset in the middle of the run (:mod:`tespike.cosim.resets`): ``sweep`` asserts
    ``rst`` at every phase of an interval and of its beats
    (:func:`tespike.cosim.resets.reset_sweep` from the seed; the default stimulus then
    covers the sweep and ``TESPIKE_READOUTS`` intervals after it; a stimulus file must be at
    least that long, and runs without a reset past the sweep), or an ``.npy``
    file of one 0/1 per stimulus clock; each segment between resets is checked
    against the golden model from zero state (:func:`tespike.cosim.resets.golden_segments`);
``TESPIKE_LANES``
    set: the design is the streaming top (SPEC section 6, ``--lanes N``):
    :func:`run_top_bench` samples ``out_valid``, ``out_first`` and
    ``out_words`` before every rising edge, the beats are held to SPEC section
    6 by :func:`tespike.cosim.stream_ports.check_beats` and compared with
    :func:`tespike.golden.beats.beats` of the literal SPEC rule's words.
"""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path

import numpy as np

from tespike.golden.config import SensorConfig, load_config
from tespike.golden.errors import InputError
from tespike.golden.io import check_stimulus, load_stimulus
from tespike.golden.reference import step_reference

from .compare import first_difference
from .outside import RESET_CLOCKS, pack_rows, words_per_row
from .tops import RunPlan, Top, prepare

#: Pixel clock period in simulator steps (its time precision, whatever the Verilog's timescale):
#: low for 2 steps (inputs change at the falling edge, sampled 1 step later), high for 2.
PERIOD_STEPS = 4


@dataclasses.dataclass(frozen=True)
class Settings:
    """What the test runs: configuration, array size, stimulus source."""

    config: SensorConfig
    height: int
    width: int
    readouts: int = 3
    seed: int = 0
    stimulus_path: str | None = None
    lanes: int | None = None            # the streaming top's N; None: the parallel top
    resets: str | None = None           # "sweep", an .npy of per-clock rst, or None (module docstring)

    @classmethod
    def from_env(cls, env=os.environ) -> "Settings":
        text = env.get("TESPIKE_CONFIG", "te").strip()
        config = SensorConfig.from_json(text) if text.startswith("{") else load_config(text)

        def integer(name, default=None):
            raw = env.get(name)
            if raw is None:
                if default is None:
                    raise InputError(f"environment variable {name} is not set (the array's size)")
                return default
            try:
                value = int(raw)
            except ValueError:
                raise InputError(f"environment variable {name} = {raw!r}: not an integer") from None
            if value < 1:
                raise InputError(f"environment variable {name} = {value}: must be >= 1")
            return value

        return cls(config, integer("TESPIKE_HEIGHT"), integer("TESPIKE_WIDTH"),
                   integer("TESPIKE_READOUTS", 3), int(env.get("TESPIKE_SEED", "0")),
                   env.get("TESPIKE_STIMULUS") or None,
                   integer("TESPIKE_LANES") if env.get("TESPIKE_LANES") else None,
                   env.get("TESPIKE_RESETS") or None)

    def to_env(self) -> dict[str, str]:
        env = {"TESPIKE_CONFIG": self.config.to_json(), "TESPIKE_HEIGHT": str(self.height),
               "TESPIKE_WIDTH": str(self.width), "TESPIKE_READOUTS": str(self.readouts),
               "TESPIKE_SEED": str(self.seed)}
        if self.stimulus_path is not None:
            env["TESPIKE_STIMULUS"] = str(Path(self.stimulus_path).resolve())
        if self.lanes is not None:
            env["TESPIKE_LANES"] = str(self.lanes)
        if self.resets is not None:
            env["TESPIKE_RESETS"] = self.resets if self.resets == "sweep" else str(Path(self.resets).resolve())
        return env

    def inputs(self) -> tuple[np.ndarray, np.ndarray | None]:
        """The stimulus and the reset vector (None without ``resets``); one line if they disagree."""
        from tespike.golden.beats import beat_count

        from .resets import check_resets, reset_sweep
        if self.resets is None:
            return self.stimulus(), None
        if self.resets == "sweep":
            beats = beat_count(self.height * self.width, self.lanes) if self.lanes else 1
            resets = reset_sweep(self.config, np.random.default_rng(self.seed + 1), beats=beats,
                                 tail_readouts=self.readouts)
            if self.stimulus_path is None:
                stim = default_stimulus(self.config, np.random.default_rng(self.seed),
                                        len(resets) // self.config.clocks_per_readout, self.height, self.width)
                return stim, resets
            stim = self.stimulus()                  # the sweep, then no reset to the stimulus's end
            if stim.shape[0] < len(resets):
                raise InputError(f"--resets sweep resets the array at every phase over {len(resets)} pixel "
                                 f"clocks (with {self.readouts} intervals after): stimulus "
                                 f"{self.stimulus_path!r} has {stim.shape[0]}; give one of at least "
                                 f"{len(resets)} clocks, or a --resets file")
            return stim, np.concatenate([resets, np.zeros(stim.shape[0] - len(resets), bool)])
        else:
            from tespike.golden.io import load_npy
            resets = load_npy(self.resets, "--resets")          # (one line naming the file for any fault)
        stim = self.stimulus()
        return stim, check_resets(resets, stim.shape[0], self.resets)

    def stimulus(self) -> np.ndarray:
        if self.stimulus_path is None:
            return default_stimulus(self.config, np.random.default_rng(self.seed), self.readouts,
                                    self.height, self.width)
        stim = load_stimulus(self.stimulus_path, self.config)
        if stim.shape[1:] != (self.height, self.width):
            raise InputError(f"stimulus {self.stimulus_path!r} has pixels {stim.shape[1:]}, "
                             f"the array is {self.height} x {self.width}")
        return stim


def default_stimulus(config: SensorConfig, rng: np.random.Generator, readouts: int,
                     height: int, width: int) -> np.ndarray:
    """Poisson electrons with each pixel at its own level, from dark to 50x the top code, plus bursts.

    Levels are in spikes per readout relative to the top code (TE: 2^b1 alpha; ML: 2^B - 1),
    so every configuration sees pixels below, near and far above overflow or saturation;
    about 2% of the clocks carry the largest input 2^E - 1 (saturated accumulator, every
    bit of ``charge``).
    """
    L = config.clocks_per_readout
    top = config.p_max * config.alpha if config.is_te else config.ml_max
    levels = np.array([0.0, 0.05, 0.4, 0.9, 1.0, 1.3, 4.0, 50.0]) * top
    level = np.resize(rng.permutation(levels), height * width).reshape(height, width)
    mean = level * config.threshold / L
    stim = rng.poisson(np.broadcast_to(mean, (readouts * L, height, width)))
    stim = np.where(rng.random(stim.shape) < 0.02, config.input_max, stim)
    stim = np.minimum(stim, config.input_max).astype(np.int64)
    return check_stimulus(stim, config)


def _as_int(value, what: str) -> int:
    """A sampled port value as an integer; an X or Z is an error naming the port and clock."""
    if not value.is_resolvable:
        raise AssertionError(f"{what} is {value.binstr!r}: X or Z on a SPEC port")
    return int(value)


async def _drive(dut, top: Top, run: RunPlan) -> tuple[list, list, np.ndarray]:
    """Reset, then per clock ``rst``/``charge`` at the falling edge and the outputs sampled a step later.

    Either top: the valid flag, ``out_first`` (streaming top only) and the word port of
    :class:`tespike.cosim.tops.Top`. Returns the sampled clocks, the ``out_first`` values and
    the word port's values as uint32 rows.
    """
    from cocotb.clock import Clock
    from cocotb.triggers import FallingEdge, RisingEdge, Timer

    stim, resets = run.stimulus, run.resets
    T = stim.shape[0]
    packed = pack_rows(stim.reshape(T, -1), top.config.input_bits)
    rows = [int.from_bytes(row.tobytes(), "little") for row in packed]
    clock_task = __import__("cocotb").start_soon(Clock(dut.clk, PERIOD_STEPS, units="step").start(start_high=False))
    dut.rst.value = 1
    dut.charge.value = 0
    for _ in range(RESET_CLOCKS):
        await RisingEdge(dut.clk)
    clocks, firsts, values = [], [], []
    captured = 0
    for t in range(T + top.flush):
        if t >= T and captured >= run.expected:
            break
        await FallingEdge(dut.clk)
        rst = int(resets[t]) if resets is not None and t < T else 0
        dut.rst.value = rst
        dut.charge.value = rows[t] if t < T else 0
        await Timer(1, units="step")                # inputs of clock t settled; rising edge t next
        if _as_int(getattr(dut, top.valid_port).value, f"{top.valid_port} before rising edge {t}"):
            clocks.append(t)
            if top.streaming:
                firsts.append(bool(_as_int(dut.out_first.value, f"out_first before rising edge {t}")))
            values.append(_as_int(getattr(dut, top.word_port).value, f"{top.word_port} before rising edge {t}"))
            captured += 1
        if rst:
            captured = 0                            # a reset edge: count the captures after it
    clock_task.kill()
    nbytes = 4 * words_per_row(top.word_values, top.config.word_bits)
    raw = np.frombuffer(b"".join(v.to_bytes(nbytes, "little") for v in values), "<u4")
    return clocks, firsts, raw.reshape(len(values), nbytes // 4)


async def run_top_bench(dut, settings: Settings) -> dict:
    """Drive ``dut`` (either top: ``settings.lanes``) through ``settings``'s stimulus and resets.

    Returns the stimulus, the reset vector (or None) and ``outputs``: words
    ``(K, H, W)`` of the parallel top or beats ``(K, B, N)`` of the streaming top,
    held to SPEC section 6 (:meth:`tespike.cosim.tops.Top.result`); with resets, each
    segment's. Raises ``AssertionError`` (the test fails) on X/Z and on wrong port
    widths, :class:`tespike.cosim.outside.SimulatorRunError` on outputs that break SPEC section 6.
    """
    top = Top(settings.config, settings.height, settings.width, settings.lanes)
    lanes = f" and {top.lanes} lanes" if top.streaming else ""
    for port, bits in (("charge", top.charge_bits), (top.word_port, top.output_bits)):
        width = len(getattr(dut, port))
        assert width == bits, (f"port {port} is {width} bits, SPEC section 6 wants {bits} for "
                               f"{top.height} x {top.width} pixels{lanes} of {top.config}")
    stim, resets = settings.inputs()
    run = prepare(settings.config, stim, settings.lanes, resets)
    clocks, firsts, rows = await _drive(dut, top, run)
    return {"stimulus": stim, "resets": run.resets, "clocks": clocks,
            "outputs": top.result(run, clocks, firsts, rows, f"cocotb run of {top.module}")}


try:
    import cocotb as _cocotb
except ImportError:          # importable without cocotb (settings and stimulus for the runner)
    _cocotb = None

if _cocotb is not None:
    @_cocotb.test()
    async def spec_ports_equal_golden(dut):
        """The top's words (or beats) equal the golden model's on the stimulus of TESPIKE_* (module docstring)."""
        settings = Settings.from_env()
        if settings.resets is not None:
            await _segments_equal_golden(dut, settings)
        elif settings.lanes is not None:
            await _stream_equal_golden(dut, settings)
        else:
            await _frames_equal_golden(dut, settings)

    async def _frames_equal_golden(dut, settings: Settings) -> None:
        """The parallel top's words equal the literal SPEC rule's."""
        run = await run_top_bench(dut, settings)
        words, expected = run["outputs"], step_reference(settings.config, run["stimulus"])[0]
        L = settings.config.clocks_per_readout
        latency = run["clocks"][0] - (L - 1) if run["clocks"] else None
        dut._log.info(f"{settings.config}: {settings.height} x {settings.width}, "
                      f"{expected.shape[0]} readouts, latency {latency} clock(s)")
        if not np.array_equal(words, expected):
            raise AssertionError("RTL != golden model: " + first_difference(words, expected).text())
        summary = {"readouts": int(expected.shape[0]), "latency": latency,
                   "distinct_words": int(len(np.unique(expected)))}
        dut._log.info("RTL == golden model " + json.dumps(summary))

    async def _stream_equal_golden(dut, settings: Settings) -> None:
        """The streaming top's beats equal golden.beats.beats of the literal SPEC rule's words."""
        from tespike.golden.beats import beats

        from .stream_ports import last_beat_latency

        run = await run_top_bench(dut, settings)
        got = run["outputs"]
        expected = beats(step_reference(settings.config, run["stimulus"])[0], settings.lanes)
        latency = last_beat_latency(run["clocks"], settings.config, expected.shape[1])
        dut._log.info(f"{settings.config}: {settings.height} x {settings.width}, {settings.lanes} lanes, "
                      f"{expected.shape[0]} readouts of {expected.shape[1]} beats, last beat at most "
                      f"{latency} clock(s) after its interval")
        if not np.array_equal(got, expected):
            k, j, i = (int(v) for v in np.argwhere(expected != got)[0])
            raise AssertionError(f"RTL != golden model: {int((expected != got).sum())} lane words "
                                 f"differ; first at readout {k}, beat {j}, lane {i}: RTL "
                                 f"{int(got[k, j, i])}, golden {int(expected[k, j, i])}")
        summary = {"readouts": int(expected.shape[0]), "beats": int(expected.shape[1]),
                   "lanes": settings.lanes, "latency": latency}
        dut._log.info("RTL == golden model " + json.dumps(summary))

    async def _segments_equal_golden(dut, settings: Settings) -> None:
        """With resets: each segment's words (or beats) equal the golden model's from zero state."""
        from .resets import first_segment_difference, golden_segments

        run = await run_top_bench(dut, settings)
        got = run["outputs"]
        expected = golden_segments(settings.config, run["stimulus"], run["resets"], settings.lanes)
        difference = first_segment_difference(got, expected)
        if difference is not None:
            raise AssertionError("RTL != golden model after a reset: " + difference)
        summary = {"segments": len(got), "resets": len(got) - 1,
                   "outputs": int(sum(len(g) for g in got)), "golden_outputs": int(sum(len(e) for e in expected))}
        dut._log.info("RTL == golden model " + json.dumps(summary))
