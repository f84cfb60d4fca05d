"""An H x W pixel array with one shared timing block (SPEC section 6 top-level ports).

Ports (clock domain ``sync``: ``clk``, synchronous active-high ``rst``):

* ``charge``: In(H*W*E), e[t] of pixel (r, c) at bits ``[(r*W + c)*E +: E]``;
* ``frame_valid``: Out(1), high for exactly one clock per readout interval;
* ``frame``: Out(H*W*Wd), word[k] of pixel (r, c) at ``[(r*W + c)*Wd +: Wd]``.

Structure: every rising edge samples ``charge`` into an input register
(``charge_sample``, E bits per pixel: the sampled charge of a modelled
photodiode) and ``rst`` into ``rst_sample``, which drives every pixel's
``clear``. Each pixel computes its next state from these registers, the timing
block's registers and its own state: registers only. The edge that samples e[t]
processes clock t - 1, so pixel clock t is fully processed one edge later (the
timing block counts in step, see :mod:`tespike.rtl.timing`), and a reset clears the
pixels at the edge after it (that edge would otherwise process the clock the
reset edge sampled). The pixels' words are combinational from the same registers
(pixels built with ``word_register=False``) and are on ``frame`` in the clock
after the edge that sampled the interval's last charge. Why: nothing in a pixel
depends combinationally on a top-level input, so a cycle-based simulator
(Verilator) evaluates each pixel once per clock instead of once per input change
and once more after the edge (docs/outside-simulators.md).

Latency: the words of interval k are on ``frame`` with ``frame_valid`` high
after the edge that samples its last charge, t = (k+1)L - 1, so they are sampled
valid at the next rising edge (1 clock), as SPEC section 6 counts it. With L = 1,
``frame_valid`` is high on every clock after the first edge out of reset.

The generated parallel Verilog top (:func:`tespike.rtl.verilog.top_verilog`) has the same
ports, latency and words, drawn with its outputs straight from flip-flops and without the
input register (see there for why).

By default every pixel is a :class:`tespike.rtl.pixel.TEPixel` / :class:`MLPixel`
submodule (the structure a sensor has);
``flat=True`` inlines the same pixel logic into one module, which the
Amaranth simulator runs faster (measured on 2 loaded cores: 16 x 16 TE array,
113 cycles/s with submodules, 184 flat).
"""

from __future__ import annotations

from amaranth.hdl import Module, ResetSignal, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from tespike.golden.config import SensorConfig
from tespike.golden.errors import ConfigError

from .pixel import check_flag, ml_pixel_logic, pixel_class, te_pixel_logic
from .timing import ReadoutTiming


def check_array_size(height, width) -> tuple[int, int]:
    """Refuse an array height or width that is not an integer >= 1."""
    for name, value in (("height", height), ("width", width)):
        if type(value) is not int or value < 1:
            raise ConfigError(f"array {name} = {value!r}: must be an integer >= 1")
    return height, width


class PixelArray(wiring.Component):
    """H x W TE or ML pixels wired to one :class:`ReadoutTiming` (SPEC section 6 ports)."""

    def __init__(self, config: SensorConfig, height: int, width: int, *, flat: bool = False):
        self.config = SensorConfig.checked(config, "PixelArray")
        self.height, self.width = check_array_size(height, width)
        self.flat = check_flag(flat, "PixelArray flat")
        n = height * width
        super().__init__({
            "charge": In(n * self.config.input_bits),
            "frame_valid": Out(1),
            "frame": Out(n * self.config.word_bits),
        })

    @property
    def pixels(self) -> int:
        return self.height * self.width

    def word_slice(self, row: int, col: int):
        """The bits of ``frame`` that carry the word of pixel (row, col)."""
        wd = self.config.word_bits
        i = row * self.width + col
        return self.frame[i * wd:(i + 1) * wd]

    def elaborate(self, platform):
        m = Module()
        cfg = self.config
        m.submodules.timing = timing = ReadoutTiming(cfg)
        m.d.comb += self.frame_valid.eq(timing.frame_valid)
        e = cfg.input_bits
        # the input registers: charge, and the reset that clears the pixels one edge later
        sample = Signal(len(self.charge), name="charge_sample", reset_less=True)
        clear = Signal(name="rst_sample", reset_less=True)
        m.d.sync += [sample.eq(self.charge), clear.eq(ResetSignal("sync"))]
        for r in range(self.height):
            for c in range(self.width):
                i = r * self.width + c
                charge, word = sample[i * e:(i + 1) * e], self.word_slice(r, c)
                if self.flat:
                    name = f"px_{r}_{c}_"
                    shown = Signal(cfg.word_bits, name=f"{name}word")   # named for the waveform
                    if cfg.is_te:
                        te_pixel_logic(m, cfg, charge, timing.ccc, timing.last, shown, name,
                                       word_register=False, named=False, clear=clear)
                    else:
                        ml_pixel_logic(m, cfg, charge, timing.last, shown, name,
                                       word_register=False, named=False, clear=clear)
                    m.d.comb += word.eq(shown)
                else:
                    pixel = pixel_class(cfg)(cfg, word_register=False)
                    m.submodules[f"px_{r}_{c}"] = pixel
                    m.d.comb += [pixel.charge.eq(charge), pixel.last.eq(timing.last), pixel.clear.eq(clear),
                                 word.eq(pixel.word)]
                    if cfg.is_te:
                        m.d.comb += pixel.ccc.eq(timing.ccc)
        return m
