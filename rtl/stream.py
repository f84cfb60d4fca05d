"""The streaming readout of SPEC section 6: an H x W array whose words leave in beats of N lanes.

:class:`StreamingPixelArray` is the :class:`tespike.rtl.array.PixelArray` (pixels and
timing, unchanged) followed by a double-buffered readout, as a column-parallel
sensor reads out: at the edge where the array shows the words of interval k
(``frame_valid``), all H x W words are copied into the readout buffer
(``held``) and the pixels go on integrating interval k + 1 while the buffer
sends its B = ceil(H W / N) beats, one per clock, beat j carrying pixels
p = j N + i (raster order) in lane i and 0 past the last pixel.

Ports (clock domain ``sync``): ``charge`` as the parallel array; ``out``, an
``amaranth.lib.stream`` source (``always_ready``: a sensor cannot stall, the
receiver takes every beat) whose payload is ``words`` (N * Wd bits, lane i at
``[i*Wd +: Wd]``) and ``first`` (beat 0 of an interval). The generated Verilog
top (:func:`tespike.rtl.verilog_stream.stream_top_verilog`) names them ``out_words``,
``out_first`` and ``out_valid``.

Timing: the parallel array's words of interval k are sampled with
``frame_valid`` one clock after its last clock (t = (k+1)L - 1), the buffer
loads at that edge and beat j is on ``out`` during the clock after it plus j:
the last beat is sampled B + 1 clocks after the interval's last clock, at most
L + 1 <= 2L because the generator refuses B > L
(:func:`tespike.golden.beats.check_lanes`). The next interval's words arrive L clocks
after the previous ones, when beat B - 1 <= L - 1 has just been sent, so the
buffer is never overwritten before all its beats left.

Structure: ``held.word_select(beat, N*Wd)`` is one B-to-1 multiplexer per lane (N B words
in all, linear in the pixel count). The Verilog top (:mod:`tespike.rtl.verilog_stream`) draws the
same readout as per-lane shift registers (no multiplexer at all); the outputs are equal
at every clock. The proof of this component (``tespike prove``, property ``stream``) reads
``held`` as the interval's words, so it stays a static buffer here.
"""

from __future__ import annotations

from amaranth.hdl import Cat, Const, Module, Signal
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from tespike.golden.config import SensorConfig
from tespike.golden.beats import beat_count, check_lanes
from tespike.golden.errors import ConfigError, is_count

from .array import PixelArray, check_array_size
from .pixel import check_flag


def beat_layout(config: SensorConfig, lanes: int) -> data.StructLayout:
    """The payload of one beat: ``words`` (lanes * Wd bits) and ``first``."""
    config = SensorConfig.required(config, "beat_layout")
    if not is_count(lanes, 1):                           # (-1 or 2.5 had been Amaranth's TypeError, 0 taken)
        raise ConfigError(f"lanes = {lanes!r}: must be an integer >= 1")
    return data.StructLayout({"words": lanes * config.word_bits, "first": 1})


class StreamingPixelArray(wiring.Component):
    """H x W pixels, one timing block and a double-buffered N-lane readout (SPEC section 6)."""

    def __init__(self, config: SensorConfig, height: int, width: int, lanes: int, *, flat: bool = False):
        self.config = SensorConfig.checked(config, "StreamingPixelArray")
        self.height, self.width = check_array_size(height, width)
        self.lanes = check_lanes(self.config, height, width, lanes)
        self.flat = check_flag(flat, "StreamingPixelArray flat")
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
        pad = B * n * wd - len(array.frame)                     # lanes past the last pixel: 0
        held = Signal(B * n * wd, name="held", reset_less=True)  # the second buffer of the words
        beat = Signal(range(max(B, 2)), name="beat")              # index of the beat on ``out``
        sending = Signal(name="sending")
        with m.If(array.frame_valid):
            m.d.sync += [held.eq(Cat(array.frame, Const(0, pad)) if pad else array.frame),
                         beat.eq(0), sending.eq(1)]
        with m.Elif(sending):
            m.d.sync += beat.eq(beat + 1)
            with m.If(beat == B - 1):
                m.d.sync += sending.eq(0)
        m.d.comb += [self.out.valid.eq(sending),
                     self.out.p.first.eq(sending & (beat == 0))]
        with m.If(sending):
            m.d.comb += self.out.p.words.eq(held.word_select(beat, n * wd))
        return m
