"""The timing shared by every pixel of an array (SPEC section 1): one block per array.

* the S_h divider counts pixel clocks 0..F-1; its wrap is the S_h tick;
* the clock cycle counter (CCC) shows ``c = j + 1`` during S_h cycle j of the
  readout interval, running 1..alpha and back to 1 after the interval;
* ``last`` (S_r) is high on the last pixel clock of every readout interval:
  divider at F - 1 and CCC at alpha;
* ``frame_valid`` is ``last`` once the first clock has been sampled
  (``primed``).

The counters describe the pixel clock whose charge the array's input register
holds, which the next rising edge processes (see :mod:`tespike.rtl.array`). A
synchronous reset puts them at clock -1, the last clock of an interval
(divider F - 1, CCC alpha) with an empty input register, and clears
``primed``: the first rising edge with ``rst`` low processes that empty clock
(no charge, nothing to count) and samples e[0], so t = 0 is that edge, and
no frame is shown for the empty clock.

Built with ``sampled_input=False`` (the parallel Verilog top, whose pixels take ``charge``
straight from the port and whose outputs are flip-flops, :func:`tespike.rtl.verilog.top_verilog`),
the counters describe the pixel clock whose charge is on the port now, which the next rising
edge processes: a reset puts them at clock 0 (divider 0, CCC 1), and ``frame_valid`` is a
register loaded with ``last`` at every edge (cleared by ``rst``), so it is high in the clock
after the edge that processes an interval's last clock: the same clocks as the sampled form.
"""

from __future__ import annotations

from amaranth.hdl import Const, Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import Out

from tespike.golden.config import SensorConfig


class ReadoutTiming(wiring.Component):
    """S_h divider, CCC and S_r strobe of SPEC section 1.

    Ports: ``ccc`` (b2 bits, TE only: an ML pixel never uses it, so the ML
    timing keeps the counter internal), ``last`` (S_r strobe, combinational
    from the counters), ``frame_valid`` (sampled form: ``last`` after the first clock out
    of reset, combinational from registers; ``sampled_input=False``: a register, ``last``
    one edge later).
    """

    def __init__(self, config: SensorConfig, *, sampled_input: bool = True):
        self.config = SensorConfig.checked(config, "ReadoutTiming")
        self.sampled_input = bool(sampled_input)
        ports = {"last": Out(1), "frame_valid": Out(1)}
        if self.config.is_te:
            ports = {"ccc": Out(self.config.b2), **ports}
        super().__init__(ports)

    def elaborate(self, platform):
        m = Module()
        cfg = self.config
        F, alpha, b2 = cfg.clocks_per_tick, cfg.alpha, cfg.b2
        sampled = self.sampled_input
        # the CCC register; reset: clock -1, the interval's last (sampled), or clock 0 (at the port)
        cycle = Signal(b2, init=alpha if sampled else 1)
        if F == 1:
            tick = Const(1, 1)
        else:
            divider = Signal(range(F), init=F - 1 if sampled else 0)
            tick = Signal()
            m.d.comb += tick.eq(divider == Const(F - 1, len(divider)))
            m.d.sync += divider.eq(Mux(tick, Const(0, len(divider)), (divider + 1)[:len(divider)]))
        at_alpha = Signal()
        m.d.comb += at_alpha.eq(cycle == Const(alpha, b2))
        if alpha > 1:
            with m.If(tick):
                m.d.sync += cycle.eq(Mux(at_alpha, Const(1, b2), (cycle + 1)[:b2]))
        m.d.comb += self.last.eq(tick & at_alpha)
        if sampled:
            primed = Signal()                   # low only for the empty clock -1 after reset
            m.d.sync += primed.eq(1)
            m.d.comb += self.frame_valid.eq(self.last & primed)
        else:
            frame_valid = Signal(name="frame_valid_reg")   # the output flip-flop; rst clears it
            m.d.sync += frame_valid.eq(self.last)
            m.d.comb += self.frame_valid.eq(frame_valid)
        if cfg.is_te:
            m.d.comb += self.ccc.eq(cycle)
        return m
