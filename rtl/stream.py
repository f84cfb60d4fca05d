"""The streaming readout of SPEC section 6: an H x W array whose words leave in beats of N lanes.

:class:`StreamingPixelArray` is the :class:`rtl.array.PixelArray` (pixels and
timing, unchanged) followed by a double-buffered readout: one readout cell
(a Wd-bit register) per pixel, chained into N shift registers, lane i being cells
i, i + N, i + 2N, ... At the edge where the array shows the words of interval k
(``frame_valid``) every cell loads its pixel's word (``held``) and the pixels go
on integrating interval k + 1; on each clock that carries a beat every cell
takes the word of the cell N on (0 past the last pixel), so the lanes, cells
0..N-1, carry beat j = pixels p = j N + i (raster order), 0 past the last
pixel, and every cell is 0 once the B = ceil(H W / N) beats have left. The same
structure as the Verilog top (:mod:`rtl.verilog_stream`), whose logic grows
linearly with the pixel count (no multiplexer over the whole array).

Ports (clock domain ``sync``): ``charge`` as the parallel array; ``out``, an
``amaranth.lib.stream`` source (``always_ready``: a sensor cannot stall, the
receiver takes every beat) whose payload is ``words`` (N * Wd bits, lane i at
``[i*Wd +: Wd]``) and ``first`` (beat 0 of an interval). The generated Verilog
top (:func:`rtl.verilog_stream.stream_top_verilog`) names them ``out_words``,
``out_first`` and ``out_valid``.

Timing: the parallel array's words of interval k are sampled with
``frame_valid`` one clock after its last clock (t = (k+1)L - 1), the buffer
loads at that edge and beat j is on ``out`` during the clock after it plus j:
the last beat is sampled B + 1 clocks after the interval's last clock, at most
L + 1 <= 2L because the generator refuses B > L
(:func:`golden.stream.check_lanes`). The next interval's words arrive L clocks
after the previous ones, when beat B - 1 <= L - 1 has just been sent, so the
buffer is never overwritten before all its beats left.
"""

from __future__ import annotations

from amaranth.hdl import Cat, Const, Module, Signal
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from golden.config import SensorConfig
from golden.errors import ConfigError
from golden.stream import beat_count, check_lanes

from .array import PixelArray, check_array_size


def beat_layout(config: SensorConfig, lanes: int) -> data.StructLayout:
    """The payload of one beat: ``words`` (lanes * Wd bits) and ``first``."""
    return data.StructLayout({"words": lanes * config.word_bits, "first": 1})


class StreamingPixelArray(wiring.Component):
    """H x W pixels, one timing block and a double-buffered N-lane readout (SPEC section 6)."""

    def __init__(self, config: SensorConfig, height: int, width: int, lanes: int, *, flat: bool = False):
        if not isinstance(config, SensorConfig):
            raise ConfigError(f"StreamingPixelArray: configuration must be a SensorConfig, "
                              f"not {type(config).__name__}")
        self.config = config.check()
        self.height, self.width = check_array_size(height, width)
        self.lanes = check_lanes(self.config, height, width, lanes)
        self.flat = bool(flat)
        super().__init__({
            "charge": In(height * width * self.config.input_bits),
            "out": Out(stream.Signature(beat_layout(self.config, lanes), always_ready=True)),
        })

    @property
    def beats(self) -> int:
        """B = ceil(H W / N), beats per readout interval."""
        return beat_count(self.height * self.width, self.lanes)

    def elaborate(self, platform):
        m = Module()
        cfg, n, B = self.config, self.lanes, self.beats
        wd = cfg.word_bits
        m.submodules.array = array = PixelArray(cfg, self.height, self.width, flat=self.flat)
        m.d.comb += array.charge.eq(self.charge)
        pixels = self.height * self.width
        # The readout cells, one Wd-bit register per pixel (cell p at [p*Wd +: Wd]); ``rst`` clears them.
        held = Signal(pixels * wd, name="held")
        beat = Signal(range(max(B, 2)), name="beat")              # index of the beat on ``out``
        sending = Signal(name="sending")
        step = min(n, pixels) * wd                 # one beat: every chain moves by N cells
        shifted = Cat(held[step:], Const(0, step)) if step < len(held) else Const(0, len(held))
        with m.If(array.frame_valid):
            m.d.sync += [held.eq(array.frame), beat.eq(0), sending.eq(1)]
        with m.Elif(sending):
            m.d.sync += [held.eq(shifted), beat.eq(beat + 1)]
            with m.If(beat == B - 1):
                m.d.sync += sending.eq(0)
        m.d.comb += [self.out.valid.eq(sending),
                     self.out.p.first.eq(sending & (beat == 0)),
                     self.out.p.words.eq(held[:step])]     # lanes past the last pixel: 0
        return m
