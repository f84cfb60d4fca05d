"""One TE or ML pixel in Amaranth (SPEC sections 3 and 4).

The pixel logic is written once, as the functions :func:`te_pixel_logic` and
:func:`ml_pixel_logic` that add it to a module; :class:`TEPixel` and
:class:`MLPixel` wrap them as components (one Verilog module each, the unit of
synthesis), and :class:`tespike.rtl.array.PixelArray` may inline them into one flat
module (faster in the Amaranth simulator). Both forms are the same logic.

Shared intermediate values (``q``, the remainder after the spike, the SFC sum,
next flag and next latch value) are named signals in the components, so the
generated Verilog computes each once (Amaranth repeats an unnamed expression at
every use: six copies of ``acc + charge``, twice the Icarus memory per pixel).
The flat array passes ``named=False``: there every extra comb signal costs the
Amaranth simulator time per pixel (about 2x for an 8 x 8 array).

Per pixel clock (one rising edge of ``sync``):

* integrator: ``q = acc + charge`` (one bit wider than either operand, so it
  never wraps), spike ``s = q >= theta``, ``acc <= min(q - theta*s, 2^A - 1)``
  (subtractive reset, saturating well);
* TE: the SFC of b1 bits counts spikes while the overflow flag is clear; its
  carry *is* the overflow flag, and on the carry a b2-bit register latches the
  shared CCC value;
* ML: a saturating ml_bits spike counter;
* on the last clock of a readout interval (``last``) the word register loads
  the word of SPEC section 4 computed from the state *after* this clock (or,
  built with ``word_register=False`` as the array does, ``word`` shows it
  combinationally during that clock), and SFC and flag restart from zero;
  ``acc`` keeps its residual. With the ML msb
  readout the word is the index of the count's most significant bit (a priority
  encoder) and the counter keeps the count minus that power of two.

Reset: every state register is ``reset_less`` and cleared by the pixel's own
``clear`` input (synchronous), not by the clock domain's reset. The array drives
``clear`` from a register (``rst`` sampled one edge earlier, see
:mod:`tespike.rtl.array`), so no pixel logic depends combinationally on an input port and
a cycle-based simulator evaluates each pixel once per clock.

The latched CCC register is not cleared at readout: the word shows it only
while the flag is set, and a set flag means it was written in this interval,
so clearing it would be logic with no observable effect.
"""

from __future__ import annotations

from amaranth.hdl import Cat, Const, Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from tespike.golden.config import SensorConfig
from tespike.golden.errors import ConfigError, check_flag as check_errors_flag


def check_pixel_config(config: SensorConfig, mode: str, what: str) -> SensorConfig:
    """Re-validate ``config`` and refuse a mode the block cannot build."""
    config = SensorConfig.checked(config, what)
    if config.mode != mode:
        raise ConfigError(f"config key 'mode' = {config.mode!r}: {what} needs mode {mode!r}")
    return config


def check_flag(value, what: str) -> bool:
    """``value``, True or False, refused in one line (a :class:`ConfigError`) otherwise ('False' had
    been True)."""
    return check_errors_flag(value, what, ConfigError)


def _value(m: Module, expr, width: int, name: str, named: bool):
    """``expr`` as a named comb signal of ``width`` bits, or as the bare expression."""
    if not named:
        return expr[:width]
    signal = Signal(width, name=name)
    m.d.comb += signal.eq(expr)
    return signal


def _state(width: int, name: str) -> Signal:
    """A pixel state register: reset only through the pixel's ``clear`` input (module docstring)."""
    return Signal(width, name=name, reset_less=True)


def _integrator(m: Module, config: SensorConfig, charge, clear, name: str, named: bool):
    """Charge accumulator with threshold comparator and subtractive reset; returns the spike."""
    acc = _state(config.acc_bits, f"{name}acc")
    width = max(config.acc_bits, config.input_bits) + 1        # acc + charge never wraps
    q = _value(m, acc + charge, width, f"{name}q", named)
    spike = Signal(name=f"{name}spike")
    m.d.comb += spike.eq(q >= Const(config.threshold, width))
    rest = _value(m, q - Mux(spike, Const(config.threshold, width), Const(0, width)), width,
                  f"{name}rest", named)
    with m.If(clear):
        m.d.sync += acc.eq(0)
    with m.Else():
        m.d.sync += acc.eq(Mux(rest > Const(config.acc_max, width),
                               Const(config.acc_max, config.acc_bits), rest[:config.acc_bits]))
    return spike


def _drive_word(m: Module, word, value, last, clear, registered: bool, name: str) -> None:
    """Registered: ``word`` shows a register that loads ``value`` at the edge of the ``last``
    clock and holds it. Not registered: ``word`` shows ``value`` combinationally (meaningful
    only while ``last``)."""
    if registered:
        register = _state(len(word), f"{name}word_reg")
        with m.If(clear):
            m.d.sync += register.eq(0)
        with m.Elif(last):
            m.d.sync += register.eq(value)
        m.d.comb += word.eq(register)
    else:
        m.d.comb += word.eq(value)


def te_pixel_logic(m: Module, config: SensorConfig, charge, ccc, last, word, name: str = "",
                   word_register: bool = True, named: bool = True, clear=Const(0, 1)) -> None:
    """Add one TE pixel (SPEC sections 3-4) driving ``word`` to ``m``; ``clear`` zeroes its state."""
    b1, b2, d = config.b1, config.b2, config.d
    spike = _integrator(m, config, charge, clear, name, named)
    sfc = _state(b1, f"{name}sfc")
    ovf = _state(1, f"{name}ovf")
    mreg = _state(b2, f"{name}m")
    total = _value(m, sfc + (spike & ~ovf), b1 + 1, f"{name}sfc_sum", named)   # bit b1: the carry
    ovf_next = _value(m, ovf | total[b1], 1, f"{name}ovf_next", named)
    m_next = _value(m, Mux(total[b1], ccc, mreg), b2, f"{name}m_next", named)
    flagged = Cat(m_next, Const(0, d - b2), Const(1, 1))     # (1 << d) | m
    counted = Cat(total[:b1], Const(0, d - b1), Const(0, 1))  # sfc
    _drive_word(m, word, Mux(ovf_next, flagged, counted), last, clear, word_register, name)
    with m.If(clear):
        m.d.sync += [sfc.eq(0), ovf.eq(0), mreg.eq(0)]
    with m.Elif(last):
        m.d.sync += [sfc.eq(0), ovf.eq(0), mreg.eq(m_next)]
    with m.Else():
        m.d.sync += [sfc.eq(total[:b1]), ovf.eq(ovf_next), mreg.eq(m_next)]


def _msb_readout(m: Module, count, bits: int, name: str, named: bool):
    """The msb readout of SPEC sections 3-4: ``(index, remainder)`` of a ``bits``-bit count.

    ``index`` is bit_length(count) (a priority encoder: the highest set bit wins);
    ``remainder`` is the count minus 2^(index - 1), built as the subtraction it is
    here: bit j survives iff some higher bit is set (``count[j] & |count[j+1:]``), which
    clears exactly the most significant set bit (nothing when the count is 0). That is
    bits - 1 AND gates on an OR suffix chain, cheaper than a decoder and a subtractor.
    """
    index = Const(0, bits.bit_length())
    for j in range(bits):                       # later (higher) bits take priority
        index = Mux(count[j], Const(j + 1, bits.bit_length()), index)
    index = _value(m, index, bits.bit_length(), f"{name}msb", named)
    kept = [count[j] & count[j + 1:].any() for j in range(bits - 1)]
    remainder = _value(m, Cat(*kept, Const(0, 1)), bits, f"{name}remainder", named)
    return index, remainder


def ml_pixel_logic(m: Module, config: SensorConfig, charge, last, word, name: str = "",
                   word_register: bool = True, named: bool = True, clear=Const(0, 1)) -> None:
    """Add one ML pixel (saturating ml_bits spike counter) driving ``word`` to ``m``.

    Readout ``"count"``: the word is the count and the counter restarts from 0.
    Readout ``"msb"``: the word is bit_length of the count (:func:`_msb_readout`) and
    the counter keeps the remainder, counting on (saturating) in the next interval.
    ``clear`` zeroes the pixel's state.
    """
    bits = config.ml_bits
    spike = _integrator(m, config, charge, clear, name, named)
    count = _state(bits, f"{name}count")
    full = count == Const(config.ml_max, bits)
    count_next = _value(m, Mux(spike & ~full, (count + 1)[:bits], count), bits, f"{name}count_next", named)
    if config.is_msb:
        value, after_readout = _msb_readout(m, count_next, bits, name, named)
    else:
        value, after_readout = count_next, Const(0, bits)
    _drive_word(m, word, value, last, clear, word_register, name)
    with m.If(clear):
        m.d.sync += count.eq(0)
    with m.Elif(last):
        m.d.sync += count.eq(after_readout)
    with m.Else():
        m.d.sync += count.eq(count_next)


class TEPixel(wiring.Component):
    """One time-encoding pixel: integrate, fire, count, latch the CCC on overflow (SPEC §3-4).

    Ports: ``charge`` (electrons this pixel clock), ``ccc`` (shared clock cycle
    counter, 1..alpha), ``last`` (S_r: last pixel clock of the readout
    interval), ``clear`` (synchronous clear of all pixel state, see the module
    docstring), ``word`` (registered readout word, loaded at the edge that
    processes the ``last`` clock).

    ``word_register=False`` builds the pixel without its readout word register
    (``word`` is then the combinational word of the ``last`` clock, to be sampled
    at that edge). :class:`tespike.rtl.array.PixelArray` uses this form behind its input
    register (the word is then valid for the clock after the edge that sampled the
    interval's last charge, see there); the hardware-cost table shows both forms.
    """

    def __init__(self, config: SensorConfig, *, word_register: bool = True):
        self.config = check_pixel_config(config, "te", "TEPixel")
        self.word_register = check_flag(word_register, "TEPixel word_register")
        super().__init__({
            "charge": In(self.config.input_bits),
            "ccc": In(self.config.b2),
            "last": In(1),
            "clear": In(1),
            "word": Out(self.config.word_bits),
        })

    def elaborate(self, platform):
        m = Module()
        te_pixel_logic(m, self.config, self.charge, self.ccc, self.last, self.word,
                       word_register=self.word_register, clear=self.clear)
        return m


class MLPixel(wiring.Component):
    """One multi-level-counter pixel: integrate, fire, count spikes saturating (SPEC §3-4).

    Ports as :class:`TEPixel` without ``ccc`` (an ML pixel never sees the CCC);
    ``word_register`` as there. ``word`` is ml_bits wide with the count readout and
    bit_length(ml_bits) wide with the msb readout (``config.word_bits``).
    """

    def __init__(self, config: SensorConfig, *, word_register: bool = True):
        self.config = check_pixel_config(config, "ml", "MLPixel")
        self.word_register = check_flag(word_register, "MLPixel word_register")
        super().__init__({
            "charge": In(self.config.input_bits),
            "last": In(1),
            "clear": In(1),
            "word": Out(self.config.word_bits),
        })

    def elaborate(self, platform):
        m = Module()
        ml_pixel_logic(m, self.config, self.charge, self.last, self.word,
                       word_register=self.word_register, clear=self.clear)
        return m


def pixel_class(config: SensorConfig):
    """:class:`TEPixel` or :class:`MLPixel`, whichever the config's mode needs."""
    config = SensorConfig.required(config, "pixel_class")
    return TEPixel if config.is_te else MLPixel
