"""One TE or ML pixel in Amaranth (SPEC sections 3 and 4).

The pixel logic is written once, as the functions :func:`te_pixel_logic` and
:func:`ml_pixel_logic` that add it to a module; :class:`TEPixel` and
:class:`MLPixel` wrap them as components (one Verilog module each, the unit of
synthesis), and :class:`rtl.array.PixelArray` may inline them into one flat
module (faster in the Amaranth simulator). Both forms are the same logic.

Per pixel clock (one rising edge of ``sync``):

* integrator: ``q = acc + charge`` (one bit wider than either operand, so it
  never wraps), spike ``s = q >= theta``, ``acc <= min(q - theta*s, 2^A - 1)``
  (subtractive reset, saturating well);
* TE: the SFC of b1 bits counts spikes while the overflow flag is clear; its
  carry *is* the overflow flag, and on the carry a b2-bit register latches the
  shared CCC value;
* ML: a saturating ml_bits spike counter;
* on the last clock of a readout interval (``last``) the word register loads
  the word of SPEC section 4 computed from the state *after* this clock, and
  SFC and flag restart from zero; ``acc`` keeps its residual.

The latched CCC register is not cleared at readout: the word shows it only
while the flag is set, and a set flag means it was written in this interval,
so clearing it would be logic with no observable effect.
"""

from __future__ import annotations

from amaranth.hdl import Cat, Const, Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from golden.config import SensorConfig
from golden.errors import ConfigError


def check_pixel_config(config: SensorConfig, mode: str, what: str) -> SensorConfig:
    """Re-validate ``config`` and refuse a mode the block cannot build."""
    if not isinstance(config, SensorConfig):
        raise ConfigError(f"{what}: configuration must be a SensorConfig, not {type(config).__name__}")
    config = config.check()
    if config.mode != mode:
        raise ConfigError(f"config key 'mode' = {config.mode!r}: {what} needs mode {mode!r}")
    return config


def _integrator(m: Module, config: SensorConfig, charge, name: str):
    """Charge accumulator with threshold comparator and subtractive reset; returns the spike."""
    acc = Signal(config.acc_bits, name=f"{name}acc")
    width = max(config.acc_bits, config.input_bits) + 1        # acc + charge never wraps
    q = Signal(width, name=f"{name}q")
    spike = Signal(name=f"{name}spike")
    rest = Signal(width, name=f"{name}rest")
    m.d.comb += [
        q.eq(acc + charge),
        spike.eq(q >= Const(config.threshold, width)),
        rest.eq(q - Mux(spike, Const(config.threshold, width), Const(0, width))),
    ]
    m.d.sync += acc.eq(Mux(rest > Const(config.acc_max, width),
                           Const(config.acc_max, config.acc_bits), rest[:config.acc_bits]))
    return spike


def te_pixel_logic(m: Module, config: SensorConfig, charge, ccc, last, word, name: str = "") -> None:
    """Add one TE pixel (SPEC sections 3-4) driving the register ``word`` to ``m``."""
    b1, b2, d = config.b1, config.b2, config.d
    spike = _integrator(m, config, charge, name)
    sfc = Signal(b1, name=f"{name}sfc")
    ovf = Signal(name=f"{name}ovf")
    mreg = Signal(b2, name=f"{name}m")
    total = Signal(b1 + 1, name=f"{name}sfc_sum")     # SFC + spike; bit b1 is the carry
    ovf_next = Signal(name=f"{name}ovf_next")
    m_next = Signal(b2, name=f"{name}m_next")
    m.d.comb += [
        total.eq(sfc + (spike & ~ovf)),
        ovf_next.eq(ovf | total[b1]),
        m_next.eq(Mux(total[b1], ccc, mreg)),
    ]
    flagged = Cat(m_next, Const(0, d - b2), Const(1, 1))     # (1 << d) | m
    counted = Cat(total[:b1], Const(0, d - b1), Const(0, 1))  # sfc
    m.d.sync += mreg.eq(m_next)
    with m.If(last):
        m.d.sync += [word.eq(Mux(ovf_next, flagged, counted)), sfc.eq(0), ovf.eq(0)]
    with m.Else():
        m.d.sync += [sfc.eq(total[:b1]), ovf.eq(ovf_next)]


def ml_pixel_logic(m: Module, config: SensorConfig, charge, last, word, name: str = "") -> None:
    """Add one ML pixel (saturating ml_bits spike counter) driving ``word`` to ``m``."""
    bits = config.ml_bits
    spike = _integrator(m, config, charge, name)
    count = Signal(bits, name=f"{name}count")
    count_next = Signal(bits, name=f"{name}count_next")
    full = count == Const(config.ml_max, bits)
    m.d.comb += count_next.eq(Mux(spike & ~full, (count + 1)[:bits], count))
    with m.If(last):
        m.d.sync += [word.eq(count_next), count.eq(0)]
    with m.Else():
        m.d.sync += count.eq(count_next)


class TEPixel(wiring.Component):
    """One time-encoding pixel: integrate, fire, count, latch the CCC on overflow (SPEC §3-4).

    Ports: ``charge`` (electrons this pixel clock), ``ccc`` (shared clock cycle
    counter, 1..alpha), ``last`` (S_r: last pixel clock of the readout
    interval), ``word`` (registered readout word, loaded at the edge that
    processes the ``last`` clock).
    """

    def __init__(self, config: SensorConfig):
        self.config = check_pixel_config(config, "te", "TEPixel")
        super().__init__({
            "charge": In(self.config.input_bits),
            "ccc": In(self.config.b2),
            "last": In(1),
            "word": Out(self.config.word_bits),
        })

    def elaborate(self, platform):
        m = Module()
        te_pixel_logic(m, self.config, self.charge, self.ccc, self.last, self.word)
        return m


class MLPixel(wiring.Component):
    """One multi-level-counter pixel: integrate, fire, count spikes saturating (SPEC §3-4).

    Ports as :class:`TEPixel` without ``ccc`` (an ML pixel never sees the CCC).
    """

    def __init__(self, config: SensorConfig):
        self.config = check_pixel_config(config, "ml", "MLPixel")
        super().__init__({
            "charge": In(self.config.input_bits),
            "last": In(1),
            "word": Out(self.config.word_bits),
        })

    def elaborate(self, platform):
        m = Module()
        ml_pixel_logic(m, self.config, self.charge, self.last, self.word)
        return m


def pixel_class(config: SensorConfig):
    """:class:`TEPixel` or :class:`MLPixel`, whichever the config's mode needs."""
    return TEPixel if config.is_te else MLPixel
