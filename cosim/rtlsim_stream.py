"""Co-simulation of the Amaranth streaming array (:class:`rtl.stream.StreamingPixelArray`).

:func:`rtl_stream_beats` is the Amaranth counterpart of
:func:`cosim.icarus.run_icarus_stream` and
:func:`cosim.verilator_stream.run_verilator_stream`: stimulus ``(T, H, W)`` in,
beats ``(K, B, N)`` out, equal to :func:`golden.stream.beats` of the golden
words for a correct RTL, with the beat timing held to SPEC section 6 by the
same check (:func:`cosim.stream_ports.check_beats`). The testbench is the one
of :mod:`cosim.rtlsim`: reset for :data:`cosim.rtlsim.RESET_CLOCKS` edges, then
one ``charge`` per pixel clock, the stream sampled at each rising edge.
"""

from __future__ import annotations

import numpy as np

from golden.config import SensorConfig
from golden.io import check_stimulus
from golden.stream import beat_count, check_lanes

from .benchbus import frame_rows
from .resets import beat_segments, check_resets, segments
from .rtlsim import CLOCK_PERIOD_S, RESET_CLOCKS, build_or_refuse, iter_packed_charge
from .stream_ports import check_beats, flush_clocks


def build_stream_array(config: SensorConfig, height: int, width: int, lanes: int, *, flat: bool = False):
    """``rtl.stream.StreamingPixelArray(config, height, width, lanes, flat=flat)``, the design under test."""
    from rtl.stream import StreamingPixelArray
    check_lanes(config, height, width, lanes)
    return build_or_refuse(lambda: StreamingPixelArray(config, height, width, lanes, flat=flat),
                     config, height, width)


def rtl_stream_beats(config: SensorConfig, stimulus: np.ndarray, lanes: int, *, flat: bool = True,
                     resets=None):
    """Run the streaming RTL on ``stimulus`` (T, H, W); return its beats (K, B, N) as int64.

    ``resets`` (T booleans): ``rst`` of every stimulus clock (:mod:`cosim.resets`); the
    result is then a list of each segment's beats ``(n, N)``
    (:func:`cosim.resets.beat_segments`).
    """
    if resets is not None:
        return rtl_stream_run(config, stimulus, lanes, flat=flat, resets=resets)
    return rtl_stream_run(config, stimulus, lanes, flat=flat)[0]


def rtl_stream_run(config: SensorConfig, stimulus: np.ndarray, lanes: int, *, flat: bool = True,
                   resets=None):
    """:func:`rtl_stream_beats` and the largest latency of a last beat (clocks after its interval);
    with ``resets``, the list of each segment's beats only."""
    from amaranth.hdl import ClockDomain, Elaboratable, Module
    from amaranth.sim import Simulator

    check_stimulus(stimulus, config)
    T, H, W = stimulus.shape
    L, B = config.clocks_per_readout, beat_count(H * W, lanes)
    resets = check_resets(resets, T)
    K = T // L if resets is None else segments(resets, T)[-1].readouts(T, L)
    dut = build_stream_array(config, H, W, lanes, flat=flat)

    class Bench(Elaboratable):
        def __init__(self):
            self.domain = ClockDomain("sync")

        def elaborate(self, platform):
            m = Module()
            m.domains.sync = self.domain
            m.submodules.stream = dut
            return m

    bench = Bench()
    clocks, firsts, lane_values = [], [], []

    async def testbench(ctx):
        ctx.set(bench.domain.rst, 1)
        for _ in range(RESET_CLOCKS):
            await ctx.tick()
        ctx.set(bench.domain.rst, 0)
        if T == 0 or (K == 0 and resets is None):
            return
        charge = iter_packed_charge(stimulus, config.input_bits)
        ctx.set(dut.charge, next(charge))
        if resets is not None:
            ctx.set(bench.domain.rst, int(resets[0]))
        t = captured = 0
        async for _, _, valid, first, words in ctx.tick().sample(dut.out.valid, dut.out.p.first,
                                                                 dut.out.p.words):
            if valid:
                clocks.append(t)
                firsts.append(bool(first))
                lane_values.append(int(words))
                captured += 1
            if resets is not None and t < T and resets[t]:
                captured = 0                      # a reset edge: count the beats after it
            t += 1
            if (t >= T and captured >= K * B) or t >= T + flush_clocks(config):
                break
            ctx.set(dut.charge, next(charge) if t < T else 0)
            if resets is not None:
                ctx.set(bench.domain.rst, int(t < T and resets[t]))

    sim = build_or_refuse(lambda: Simulator(bench), config, H, W)
    sim.add_clock(CLOCK_PERIOD_S)
    sim.add_testbench(testbench)
    sim.run()
    rows = frame_rows(lane_values, lanes, config.word_bits)
    what = f"Amaranth simulation of the {H} x {W} streaming array ({lanes} lanes)"
    if resets is not None:
        return beat_segments(clocks, firsts, rows, config, H, W, lanes, resets, T, what)
    return check_beats(clocks, firsts, rows, config, H, W, lanes, K, what)



