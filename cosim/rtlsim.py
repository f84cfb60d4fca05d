"""Co-simulation: run the Amaranth RTL, either top, on a per-clock stimulus (SPEC sections 3, 4, 6).

:func:`rtl_words` is the pure function behind ``tespike rtl-sim`` and the conformance
tests: stimulus ``(T, H, W)`` in, readout words ``(T / L, H, W)`` out, exactly what
:func:`tespike.golden.sensor.simulate` returns for a correct RTL. :func:`rtl_stream_beats`
is the same for the streaming array (:class:`tespike.rtl.stream.StreamingPixelArray`): beats
``(K, B, N)`` out, equal to :func:`tespike.golden.beats.beats` of the golden words. Both
run the one testbench (:func:`_simulate`) and take a reset vector (``resets=``,
:mod:`tespike.cosim.resets`).

The testbench is one async Amaranth testbench around a small wrapper
(:class:`Bench`) that owns the ``sync`` clock domain. Per pixel clock it makes
one ``ctx.set`` of the whole packed ``charge`` bus and waits for the rising edge,
sampling ``frame_valid`` and ``frame`` *at* that edge (the values the circuit
shows just before the edge, as a synchronous receiver would latch them).

Timing (SPEC section 6): reset is held high for :data:`RESET_CLOCKS` edges; the
first rising edge with reset low is pixel clock t = 0 and registers ``e[0]``.
Readout k ends at clock ``k L + L - 1``; the RTL must show it with
``frame_valid`` at edge ``k L + L - 1 + latency`` with one fixed latency in
``0..L``. The testbench drives zero charge for up to L clocks after the
stimulus so the last readout comes out, and refuses (:class:`RTLProtocolError`)
any ``frame_valid`` that breaks this rule: early, missing, doubled or drifting.
"""

from __future__ import annotations

import contextlib
import dataclasses
import time

import numpy as np

from tespike.golden.config import SensorConfig
from tespike.golden.errors import ConfigError, InputError, check_flag, is_count
from tespike.golden.io import atomic_output
from tespike.golden.beats import check_lanes

from .benchbus import ARRAY_SCOPE, CLOCK_PERIOD_S, frame_rows, iter_packed_charge, unpack_frames
from .outside import RESET_CLOCKS
from .stream_ports import check_beats
from .tops import RunPlan, prepare
from .vcd import dump_path, write_gtkw_to


class RTLProtocolError(RuntimeError):
    """The RTL broke the output protocol of SPEC section 6 (a bug in rtl/, not bad input)."""


# -- the design under test ---------------------------------------------------

def build_array(config: SensorConfig, height: int, width: int, *, flat: bool = False):
    """``tespike.rtl.array.PixelArray(config, height, width, flat=flat)``, the design under test."""
    from tespike.rtl.array import PixelArray
    return build_or_refuse(lambda: PixelArray(config, height, width, flat=flat), config, height, width)


def build_or_refuse(make, config, height, width):
    """Call ``make()``; turn the RTL's refusal of a configuration into a one-line :class:`ConfigError`."""
    from tespike.golden.errors import TespikeError
    try:
        return make()
    except TespikeError:
        raise
    except Exception as exc:            # the RTL's own refusal, whatever its type
        raise ConfigError(f"the RTL cannot build a {height} x {width} array for config {config.describe()}: "
                          f"{type(exc).__name__}: {exc}") from exc


def _bench(array):
    """Wrapper owning the ``sync`` domain, with named copies of the array's ports.

    The copies ``tb_clk``, ``tb_rst``, ``tb_charge``, ``tb_frame_valid`` and
    ``tb_frame`` live in the wrapper's own VCD scope (``bench.top``), so
    :mod:`tespike.cosim.vcd` reads the stream back from names that do not depend on
    how the RTL names its signals.
    """
    from amaranth.hdl import ClockDomain, ClockSignal, Elaboratable, Module, ResetSignal, Signal

    class Bench(Elaboratable):
        def __init__(self):
            self.array = array
            self.domain = ClockDomain("sync")
            self.tb_clk = Signal(name="tb_clk")
            self.tb_rst = Signal(name="tb_rst")
            self.tb_charge = Signal(len(array.charge), name="tb_charge")
            self.tb_frame_valid = Signal(name="tb_frame_valid")
            self.tb_frame = Signal(len(array.frame), name="tb_frame")

        def elaborate(self, platform):
            m = Module()
            m.domains.sync = self.domain
            m.submodules[ARRAY_SCOPE] = self.array
            m.d.comb += [
                self.tb_clk.eq(ClockSignal("sync")),
                self.tb_rst.eq(ResetSignal("sync")),
                self.array.charge.eq(self.tb_charge),
                self.tb_frame_valid.eq(self.array.frame_valid),
                self.tb_frame.eq(self.array.frame),
            ]
            return m

    return Bench()


# -- the testbench -----------------------------------------------------------

@dataclasses.dataclass
class RtlRun:
    """A co-simulation's result: the words and when ``frame_valid`` showed them."""

    words: np.ndarray       # (K, H, W) int64 readout words
    clocks: np.ndarray      # (K,) pixel clock t of the edge at which readout k was sampled
    latency: int | None     # clocks from the last clock of a readout to its frame_valid (None if K = 0)
    cycles: int = 0         # rising edges simulated after reset (T plus the latency of the last readout)
    seconds: float = 0.0    # wall time of those edges (no elaboration, no reset): cycles / seconds = speed


def rtl_words(config: SensorConfig, stimulus: np.ndarray, *, vcd_path=None, gtkw_path=None,
              progress: bool | None = False, flat: bool = False, resets=None):
    """Run the RTL on ``stimulus`` (T, H, W); return the ``(T / L, H, W)`` int64 readout words.

    ``vcd_path`` writes the whole waveform (all signals of the design) and
    ``gtkw_path`` a GTKWave save file showing the useful ones (see
    :func:`tespike.cosim.vcd.write_gtkw`); both appear only if the run succeeds.
    ``progress`` shows a tqdm bar (``None``: only on a terminal). ``flat``
    simulates the array with its pixels inlined into one module (same logic).
    ``resets`` (T booleans): ``rst`` of every stimulus clock (:mod:`tespike.cosim.resets`);
    the result is then a list of each segment's words ``(n, H, W)``.
    """
    config = SensorConfig.required(config, "rtl_words")
    return rtl_run(config, stimulus, vcd_path=vcd_path, gtkw_path=gtkw_path,
                   progress=progress, flat=flat, resets=resets).words


def rtl_run(config: SensorConfig, stimulus: np.ndarray, *, vcd_path=None, gtkw_path=None,
            progress: bool | None = False, flat: bool = False, reset_charge: int = 0,
            resets=None) -> RtlRun:
    """:func:`rtl_words`, also returning the clock of every ``frame_valid``.

    ``reset_charge`` is the value of the whole ``charge`` bus while the initial
    reset is held (the tests drive all ones: a synchronous reset must ignore it).
    With ``resets``, ``words`` is the list of each segment's words, checked by
    :func:`tespike.cosim.resets.frame_segments` (``latency`` is then None).
    """
    config = SensorConfig.required(config, "rtl_run")
    run = prepare(config, stimulus, None, resets)
    T, H, W = stimulus.shape
    L = config.clocks_per_readout
    if gtkw_path is not None and vcd_path is None:
        raise InputError("a GTKWave save file (gtkw_path) needs a waveform (vcd_path)")
    check_run_flags(progress, flat)
    bus = H * W * config.input_bits
    if not (is_count(reset_charge) and reset_charge < 1 << bus):     # (2.5 had been Amaranth's TypeError)
        raise InputError(f"reset_charge {reset_charge!r}: must be an integer in 0 .. 2^{bus} - 1 (the charge bus)")
    bench = _bench(build_array(config, H, W, flat=flat))
    frames: list[int] = []
    edges: list[int] = []

    def record(t: int, values) -> None:
        if run.resets is None:
            _check_edge(t, len(frames), edges, L)
        frames.append(values[1])
        edges.append(t)

    ports = (bench.tb_frame_valid, bench.tb_frame)
    clock = _simulate(bench, bench.tb_charge, ports, run, record, limit=L, reset_charge=reset_charge,
                      progress=progress, waveform=None if vcd_path is None else
                      lambda sim: _run_with_vcd(sim, config, vcd_path, gtkw_path))
    what = f"Amaranth simulation of the {H} x {W} array"
    if run.resets is not None:
        segment_words = run.top.result(run, edges, [], frame_rows(frames, H * W, config.word_bits), what)
        return RtlRun(segment_words, np.asarray(edges, np.int64), None, *clock)
    K = run.readouts
    if len(frames) != K:
        raise RTLProtocolError(f"RTL gave {len(frames)} frame_valid pulses for {K} readout intervals "
                               f"within {T + L} clocks (latency must be at most L = {L})")
    words = unpack_frames(frames, H * W, config.word_bits).reshape(K, H, W)
    latency = edges[0] - (L - 1) if edges else None
    return RtlRun(words, np.asarray(edges, np.int64), latency, *clock)


def check_run_flags(progress, flat) -> None:
    """``progress`` None, True or False and ``flat`` True or False, refused in one line otherwise
    ('no' had shown a bar, and built the flat array)."""
    if not (progress is None or isinstance(progress, bool)):
        raise InputError(f"progress = {progress!r}: must be None (a bar on a terminal), True or False")
    check_flag(flat, "flat")


def build_stream_array(config: SensorConfig, height: int, width: int, lanes: int, *, flat: bool = False):
    """``tespike.rtl.stream.StreamingPixelArray(config, height, width, lanes, flat=flat)``, the design under test."""
    from tespike.rtl.stream import StreamingPixelArray
    check_lanes(config, height, width, lanes)
    return build_or_refuse(lambda: StreamingPixelArray(config, height, width, lanes, flat=flat),
                           config, height, width)


def rtl_stream_beats(config: SensorConfig, stimulus: np.ndarray, lanes: int, *, flat: bool = True,
                     resets=None):
    """Run the streaming RTL on ``stimulus`` (T, H, W); return its beats (K, B, N) as int64.

    The Amaranth counterpart of :func:`tespike.cosim.icarus.run_icarus_stream` and
    :func:`tespike.cosim.verilator.run_verilator_stream`, held to SPEC section 6 by the same
    check (:func:`tespike.cosim.stream_ports.check_beats`). ``resets`` (T booleans): ``rst``
    of every stimulus clock (:mod:`tespike.cosim.resets`); the result is then a list of each
    segment's beats ``(n, N)`` (:func:`tespike.cosim.resets.beat_segments`).
    """
    if resets is not None:
        return rtl_stream_run(config, stimulus, lanes, flat=flat, resets=resets)
    return rtl_stream_run(config, stimulus, lanes, flat=flat)[0]


def rtl_stream_run(config: SensorConfig, stimulus: np.ndarray, lanes: int, *, flat: bool = True,
                   resets=None):
    """:func:`rtl_stream_beats` and the largest latency of a last beat (clocks after its interval);
    with ``resets``, the list of each segment's beats only."""
    config = SensorConfig.required(config, "rtl_stream_run")
    from amaranth.hdl import ClockDomain, Elaboratable, Module

    run = prepare(config, stimulus, lanes, resets)
    T, H, W = stimulus.shape
    dut = build_stream_array(config, H, W, lanes, flat=flat)

    class Bench(Elaboratable):
        def __init__(self):
            self.domain = ClockDomain("sync")

        def elaborate(self, platform):
            m = Module()
            m.domains.sync = self.domain
            m.submodules.stream = dut
            return m

    clocks, firsts, lane_values = [], [], []

    def record(t: int, values) -> None:
        clocks.append(t)
        firsts.append(bool(values[1]))
        lane_values.append(int(values[2]))

    _simulate(Bench(), dut.charge, (dut.out.valid, dut.out.p.first, dut.out.p.words), run, record,
              limit=run.top.flush)
    rows = frame_rows(lane_values, lanes, config.word_bits)
    what = f"Amaranth simulation of the {H} x {W} streaming array ({lanes} lanes)"
    if run.resets is not None:
        return run.top.result(run, clocks, firsts, rows, what)
    return check_beats(clocks, firsts, rows, config, H, W, lanes, run.readouts, what)


def _simulate(bench, charge, ports, run: RunPlan, record, *, limit: int, reset_charge: int = 0,
              progress: bool | None = False, waveform=None) -> tuple[int, float]:
    """The one testbench of both tops: reset, then per pixel clock one ``charge`` (and ``rst``).

    ``bench`` owns the ``sync`` domain (``bench.domain``); ``ports`` are sampled at
    every rising edge, the first being the valid flag: ``record(t, values)`` gets each
    edge t at which it is high. The run stops once the stimulus is over and the
    captures expected after the last reset are in, or ``limit`` clocks past the
    stimulus. ``waveform(sim)`` runs the simulation instead of ``sim.run()`` (the VCD).
    Returns the edges simulated after reset and their wall time.
    """
    from amaranth.sim import Simulator

    config, stimulus, resets = run.top.config, run.stimulus, run.resets
    T = stimulus.shape[0]
    clock = {"cycles": 0, "start": 0.0, "stop": 0.0}

    async def testbench(ctx):
        ctx.set(bench.domain.rst, 1)
        ctx.set(charge, reset_charge)
        for _ in range(RESET_CLOCKS):
            await ctx.tick()
        ctx.set(bench.domain.rst, 0)
        if T == 0 or run.idle:
            ctx.set(charge, 0)
            return
        rows = iter_packed_charge(stimulus, config.input_bits)
        bar = _progress_bar(T, progress)
        t = captured = 0
        clock["start"] = time.perf_counter()
        ctx.set(charge, next(rows))
        if resets is not None:
            ctx.set(bench.domain.rst, int(resets[0]))
        # Multi-shot wait: cheaper than a fresh one-shot trigger per clock.
        async for _, _, *values in ctx.tick().sample(*ports):
            if values[0]:
                record(t, values)
                captured += 1
            if resets is not None and t < T and resets[t]:
                captured = 0                      # a reset edge: count the captures after it
            t += 1
            if (t >= T and captured >= run.expected) or t >= T + limit:
                break
            ctx.set(charge, next(rows) if t < T else 0)
            if resets is not None:
                ctx.set(bench.domain.rst, int(t < T and resets[t]))
            if bar is not None and (t & 15) == 0:   # (a large array takes seconds a clock: show it early)
                bar.update(min(t, T) - bar.n)
        clock["stop"], clock["cycles"] = time.perf_counter(), t
        if bar is not None:
            bar.update(min(t, T) - bar.n)
            bar.close()

    sim = build_or_refuse(lambda: Simulator(bench), config, run.top.height, run.top.width)   # elaborates
    sim.add_clock(CLOCK_PERIOD_S)
    sim.add_testbench(testbench)
    if waveform is None:
        sim.run()
    else:
        waveform(sim)
    return clock["cycles"], clock["stop"] - clock["start"]


def _check_edge(t: int, k: int, edges: list[int], L: int) -> None:
    """Refuse a frame_valid at clock ``t`` that is not readout ``k`` at one fixed latency <= L."""
    latency = t - (k * L + L - 1)
    if latency < 0 or latency > L:
        raise RTLProtocolError(f"frame_valid for readout {k} at clock {t}: latency {latency} "
                               f"outside 0..L = {L} (readout {k} ends at clock {k * L + L - 1})")
    if edges and latency != edges[0] - (L - 1):
        raise RTLProtocolError(f"frame_valid for readout {k} at clock {t}: latency {latency} differs "
                               f"from readout 0's {edges[0] - (L - 1)}")


def _progress_bar(total: int, progress: bool | None):
    if progress is False:
        return None
    from tqdm import tqdm
    return tqdm(total=total, unit="clk", unit_scale=True, desc="rtl-sim",
                disable=None if progress is None else False, leave=False)


def _run_with_vcd(sim, config, vcd_path, gtkw_path) -> None:
    """Run with a waveform; write VCD and GTKWave files atomically (nothing on failure). The VCD is
    entered last so that it is committed first: one that fails there (a full disk, ``/dev/full``)
    takes the save file with it (the stack commits in reverse order)."""
    with contextlib.ExitStack() as stack:
        gtkw_tmp = stack.enter_context(atomic_output(gtkw_path)) if gtkw_path is not None else None
        vcd_tmp = stack.enter_context(atomic_output(vcd_path))
        try:
            with sim.write_vcd(vcd_tmp):
                sim.run()
        except OSError as exc:
            if exc.filename is None:     # the waveform's write (a full disk): its file, never the .gtkw
                exc.filename = vcd_tmp
            raise
        if gtkw_tmp is not None:
            with open(gtkw_tmp, "w") as handle:
                write_gtkw_to(handle, vcd_tmp, config, dumpfile=dump_path(vcd_path, gtkw_path))
