"""Harnesses of the pixel proofs against SPEC sections 3-4, and of the Amaranth streaming top.

Each property is an Amaranth *harness*: the pixel under proof (the component of
:mod:`tespike.rtl.pixel`, elaborated as it is built for Verilog) beside logic written here from
SPEC's text, with ``Assert``/``Assume`` statements relating the two, proved by
:func:`tespike.cosim.formal.smtbmc.prove`. The assertions state the pixel's registers equal the
reference's (or the invariants of the bound), so every property is 1-inductive; ``depth``
only adds margin.

The harness reads the pixel's state registers by name (``acc``, ``sfc``, ``ovf``, ``m``,
``count``) from its elaborated fragment: the proof is about that state, and a pixel whose
registers are renamed is refused in one line.
"""

from __future__ import annotations

from tespike.golden.config import SensorConfig

from .smtbmc import ProofToolError

# -- the corners of SPEC section 2 ------------------------------------------------------------
def corners(mode: str, ml_readout: str = "count") -> dict[str, SensorConfig]:
    """Extreme configurations of SPEC section 2 for one mode, each named.

    ``min``: every width 1 (b1 = b2 = 1, alpha = F = 1, theta = 1, A = 1, E = 1,
    ml_bits = 1), the smallest pixel. ``max``: every width at its largest
    (b1 = b2 = 16, alpha = 2^16 - 1, F = 256 so L = 16,776,960 <= 2^24, ml_bits = 16,
    E = 32, A = 62, theta = 2^61 + 1). ``sat``: a 1-bit well under a 32-bit input
    (theta = 1, A = 1, E = 32), where the accumulator saturates every clock it can.
    """
    base = {"mode": mode} if mode == "te" else {"mode": mode, "ml_readout": ml_readout}
    small = dict(b1=1, b2=1, alpha=1, clocks_per_tick=1, threshold=1, acc_bits=1, input_bits=1)
    large = dict(b1=16, b2=16, alpha=2 ** 16 - 1, clocks_per_tick=256, threshold=2 ** 61 + 1,
                 acc_bits=62, input_bits=32)
    sat = dict(b1=4, b2=4, threshold=1, acc_bits=1, input_bits=32)
    if mode == "ml":
        # msb readout: ml_bits = 16 did not finish in 28 minutes (z3 4.8, the priority encoder
        # against the reference's bit_length); its max corner keeps every other width at its top
        # and ml_bits at the paper's 8.
        small["ml_bits"], large["ml_bits"], sat["ml_bits"] = 1, 8 if ml_readout == "msb" else 16, 8
    return {name: SensorConfig(**base, **values).check()
            for name, values in (("min", small), ("max", large), ("sat", sat))}


# -- the harnesses -------------------------------------------------------------------------
def _pixel_state(fragment) -> dict[str, object]:
    """The pixel's registers (signals assigned in its ``sync`` domain), by name."""
    state = {}
    for statement in fragment.statements.get("sync", []):
        for signal in statement._lhs_signals():
            state[signal.name] = signal
    return state


def _need(state: dict, names: tuple[str, ...], what: str) -> list:
    missing = [name for name in names if name not in state]
    if missing:
        raise ProofToolError(f"{what}: no register named {', '.join(missing)} in the pixel "
                             f"(found {', '.join(sorted(state)) or 'none'}); the proof reads them by name")
    return [state[name] for name in names]


class _Harness:
    """A module, its free inputs and the pixel it holds (with its registers by name)."""

    def __init__(self, config: SensorConfig, pixel_factory, word_register: bool):
        from amaranth.hdl import Fragment, Module

        config = SensorConfig.checked(config, "pixel harness")
        if pixel_factory is None:                        # (None had been "not callable")
            from tespike.rtl.pixel import pixel_class
            pixel_factory = pixel_class(config)
        self.config = config
        self.m = Module()
        self.pixel = pixel_factory(config, word_register=word_register)
        body = Fragment.get(self.pixel, None)      # elaborated once: the registers read below
        self.state = _pixel_state(body)
        self.m.submodules.pixel = body
        self.inputs = [self.pixel.charge, self.pixel.last, self.pixel.clear]
        if config.is_te:
            self.inputs.append(self.pixel.ccc)


def _power(word, bits: int):
    """2^(word - 1) for word in 1..bits, 0 for word 0 (a table, which solvers handle
    better than a variable shift)."""
    from amaranth.hdl import Const, Mux

    value = Const(0, bits + 1)
    for j in range(bits):
        value = Mux(word == j + 1, Const(2 ** j, bits + 1), value)
    return value


def _reference_step(m, config: SensorConfig, charge, ccc, last, clear):
    """SPEC section 3-4 written from its text (not from :mod:`tespike.rtl.pixel`): registers,
    next values and the word of this clock. Returns ``(regs, word)``; the registers
    update at the clock edge (``clear`` zeroes them, ``last`` restarts the interval)."""
    from amaranth.hdl import Const, Mux, Signal

    theta, A = config.threshold, config.acc_bits
    acc = Signal(A, name="ref_acc", reset_less=True)
    q = acc + charge                                   # Amaranth widens: never wraps
    s = Signal(name="ref_s")
    m.d.comb += s.eq(q >= theta)
    after = q - Mux(s, theta, 0)
    acc_next = Mux(after > config.acc_max, config.acc_max, after)
    with m.If(clear):
        m.d.sync += acc.eq(0)
    with m.Else():
        m.d.sync += acc.eq(acc_next)
    regs = {"acc": acc, "s": s}
    if config.is_te:
        p_max = 2 ** config.b1
        sfc = Signal(range(p_max + 1), name="ref_sfc", reset_less=True)   # reaches 2^b1
        ovf = Signal(name="ref_ovf", reset_less=True)
        mm = Signal(config.b2, name="ref_m", reset_less=True)
        counting = (ovf == 0) & s
        sfc1 = Mux(counting, sfc + 1, sfc)
        hit = counting & (sfc1 == p_max)
        ovf1 = ovf | hit
        m1 = Mux(hit, ccc, mm)
        word = Signal(config.word_bits, name="ref_word")
        m.d.comb += word.eq(Mux(ovf1, (1 << config.d) | m1, sfc1))
        with m.If(clear | last):
            m.d.sync += [sfc.eq(0), ovf.eq(0), mm.eq(0)]
        with m.Else():
            m.d.sync += [sfc.eq(sfc1), ovf.eq(ovf1), mm.eq(m1)]
        regs.update(sfc=sfc, ovf=ovf, m=mm)
        return regs, word
    top = config.ml_max
    sfc = Signal(config.ml_bits, name="ref_count", reset_less=True)
    sfc1 = Mux(s & (sfc < top), sfc + 1, sfc)           # min(sfc + s, 2^ml_bits - 1)
    word = Signal(config.word_bits, name="ref_word")
    if config.is_msb:
        # bit_length(sfc1): how many of 1, 2, 4, ... 2^(ml_bits-1) are <= sfc1
        length = sum((sfc1 >= 2 ** j for j in range(config.ml_bits)), Const(0, config.word_bits))
        m.d.comb += word.eq(length)
        taken = _power(word, config.ml_bits)
        after_readout = sfc1 - taken
    else:
        m.d.comb += word.eq(sfc1)
        after_readout = Const(0, config.ml_bits)
    with m.If(clear):
        m.d.sync += sfc.eq(0)
    with m.Elif(last):
        m.d.sync += sfc.eq(after_readout)
    with m.Else():
        m.d.sync += sfc.eq(sfc1)
    regs.update(count=sfc)
    return regs, word


def rule_harness(config: SensorConfig, pixel_factory, word_register: bool):
    """Pixel == SPEC section 3's rule for every input: state equal every clock, word
    equal whenever it is meaningful (combinational: during ``last``; registered: always)."""
    from amaranth.hdl import Assert, Signal

    h = _Harness(config, pixel_factory, word_register)
    m, p = h.m, h.pixel
    regs, word = _reference_step(m, config, p.charge, getattr(p, "ccc", None), p.last, p.clear)
    if config.is_te:
        acc, sfc, ovf, mm = _need(h.state, ("acc", "sfc", "ovf", "m"), "TE pixel")
        m.d.comb += [Assert(acc == regs["acc"], "acc"),
                     Assert(ovf == regs["ovf"], "ovf"),
                     Assert(ovf | (sfc == regs["sfc"]), "sfc while counting"),
                     Assert(~ovf | (mm == regs["m"]), "m while flagged")]
    else:
        acc, count = _need(h.state, ("acc", "count"), "ML pixel")
        m.d.comb += [Assert(acc == regs["acc"], "acc"), Assert(count == regs["count"], "count")]
    if word_register:
        held = Signal(config.word_bits, name="ref_word_reg", reset_less=True)
        with m.If(p.clear):
            m.d.sync += held.eq(0)
        with m.Elif(p.last):
            m.d.sync += held.eq(word)
        m.d.comb += Assert(p.word == held, "registered word")
    else:
        m.d.comb += Assert(~p.last | (p.word == word), "word at readout")
    return h


def bounds_harness(config: SensorConfig, pixel_factory):
    """No counter wraps silently, every overflow is recorded, every word is legal (SPEC
    section 4), under the readout timing of SPEC section 1 (``ccc = j + 1``, ``last`` on
    the interval's last clock), modelled here by a tick divider and an S_h counter."""
    from amaranth.hdl import Assert, Assume, Mux, Signal

    h = _Harness(config, pixel_factory, word_register=False)
    m, p = h.m, h.pixel
    F, alpha = config.clocks_per_tick, config.alpha
    phase = Signal(range(max(F, 2)), name="phase", reset_less=True)   # pixel clock inside S_h
    j = Signal(range(max(alpha, 2)), name="j", reset_less=True)        # S_h cycle inside S_r
    tick_end = phase == F - 1
    last = Signal(name="timing_last")
    m.d.comb += [last.eq(tick_end & (j == alpha - 1)),
                 Assert(phase < F, "timing phase"), Assert(j < alpha, "timing S_h index"),
                 Assume(p.last == last)]
    m.d.sync += phase.eq(Mux(tick_end, 0, phase + 1))
    with m.If(tick_end):
        m.d.sync += j.eq(Mux(j == alpha - 1, 0, j + 1))
    acc = _need(h.state, ("acc",), "pixel")[0]
    spike = (acc + p.charge) >= config.threshold        # the pixel's spike, from its own charge
    if config.is_te:
        m.d.comb += Assume(p.ccc == j + 1)
        sfc, ovf, mm = _need(h.state, ("sfc", "ovf", "m"), "TE pixel")
        cap = 2 ** config.b1
        spikes = Signal(range(cap + 1), name="spikes", reset_less=True)   # saturates at 2^b1
        with m.If(p.clear | p.last):
            m.d.sync += spikes.eq(0)
        with m.Elif(spike & (spikes < cap)):
            m.d.sync += spikes.eq(spikes + 1)
        flag, low = p.word[config.d], p.word[:config.d]
        m.d.comb += [
            Assert(ovf == (spikes == cap), "overflow recorded: flag set iff 2^b1 spikes"),
            Assert(ovf | (sfc == spikes), "SFC counts every spike until the flag, never wraps"),
            Assert(~ovf | ((mm >= 1) & (mm <= j + 1)), "latched m in 1..ccc"),
            Assert(~p.last | ~flag | ((low >= 1) & (low <= alpha)), "flagged word: m in 1..alpha"),
            Assert(~p.last | flag | (low < cap), "counted word: sfc < 2^b1"),
        ]
        return h
    (count,) = _need(h.state, ("count",), "ML pixel")
    prev = Signal(config.ml_bits, name="prev_count", reset_less=True)
    prev_spike = Signal(name="prev_spike", reset_less=True)
    fresh = Signal(name="fresh", init=1, reset_less=True)       # first clock, or after clear/readout
    m.d.sync += [prev.eq(count), prev_spike.eq(spike), fresh.eq(p.clear | p.last)]
    step = Mux(prev_spike & (prev < config.ml_max), prev + 1, prev)
    m.d.comb += Assert(fresh | (count == step), "count goes up by each spike, saturating, never wraps")
    if config.is_msb:
        taken = Signal(config.ml_bits + 1, name="taken", reset_less=True)
        value = Mux(spike & (count < config.ml_max), count + 1, count)
        with m.If(p.clear):
            m.d.sync += taken.eq(0)
        with m.Elif(p.last):
            m.d.sync += taken.eq(_power(p.word, config.ml_bits))
        m.d.comb += [
            Assert(~p.last | (p.word <= config.ml_bits), "msb word in 0..ml_bits"),
            Assert(~p.last | ((p.word == 0) == (value == 0)), "msb word 0 iff count 0"),
            Assert(~p.last | (p.word == 0) | ((value >= _power(p.word, config.ml_bits))
                                              & (value < 2 * _power(p.word, config.ml_bits))),
                   "msb word: 2^(w-1) <= count < 2^w"),
            Assert(~fresh | (taken == 0) | (count < taken), "msb remainder below the power read out"),
        ]
    else:
        value = Mux(spike & (count < config.ml_max), count + 1, count)
        m.d.comb += Assert(~p.last | (p.word == value), "count word is the saturated count")
    return h


#: Array (height, width) of the streaming property: three pixels, so two lanes leave one
#: padded lane in the second beat.
STREAM_ARRAY = (1, 3)


def stream_lanes(config: SensorConfig) -> int:
    """Two lanes (two beats, the second padded) where an interval has room, else three."""
    return 2 if SensorConfig.required(config, "stream_lanes").clocks_per_readout >= 2 else 3


# -- the streaming readout ---------------------------------------------------------------------
def amaranth_stream_harness(config: SensorConfig, height: int, width: int, lanes: int, stream_factory=None):
    """SPEC section 6's streaming readout: each interval's words leave exactly once, in raster
    order in beats of ``lanes`` words (0 past the last pixel), ``first`` with beat 0 only, all
    before the next interval's words arrive, the last within 2L clocks of the interval's end.

    The harness copies the array's words when it shows them (``frame_valid``) and follows the
    beats with its own counter; the readout's buffer, beat index and busy flag (read by name:
    ``held``, ``beat``, ``sending``) are asserted equal to that copy and counter, which makes
    the property inductive. ``rst`` is held low: the base case starts from the reset state.
    """
    from amaranth.hdl import Assert, Assume, Cat, Const, Fragment, Module, Mux, ResetSignal, Signal

    if stream_factory is None:
        from tespike.rtl.stream import StreamingPixelArray as stream_factory
    top = stream_factory(config, height, width, lanes)
    body = Fragment.get(top, None)
    arrays = [origin for sub, _, _ in body.subfragments for origin in sub.origins
              if hasattr(origin, "frame_valid")]
    if len(arrays) != 1:
        raise ProofToolError("streaming readout: no pixel array with frame_valid inside it")
    array = arrays[0]
    held, beat, sending = _need(_pixel_state(body), ("held", "beat", "sending"), "streaming readout")
    timing = _find_fragment(body, "frame_valid", "last")
    clock_names = ("primed",) + (("cycle",) if config.alpha > 1 else ()) \
        + (("divider",) if config.clocks_per_tick > 1 else ())
    timing_regs = _need(_pixel_state(timing), clock_names, "readout timing")
    m = Module()
    m.submodules.stream = body
    n, wd, L = lanes, config.word_bits, config.clocks_per_readout
    B = -(-height * width // lanes)
    pad = B * n * wd - height * width * wd
    snap = Signal(B * n * wd, name="snap", reset_less=True)
    expect = Signal(range(max(B, 2)), name="expect", reset_less=True)
    pending = Signal(name="pending", reset_less=True)
    age = Signal(range(2 * L + 2), name="age", reset_less=True)      # clocks since the interval's end
    since = Signal(range(L + 2), name="since", reset_less=True)      # clocks since frame_valid
    seen = Signal(name="seen", reset_less=True)
    out = top.out
    primed = timing_regs[0]
    cycle = timing_regs[1] if config.alpha > 1 else Const(1, 1)
    divider = timing_regs[-1] if config.clocks_per_tick > 1 else Const(0, 1)
    position = Signal(range(L + 1), name="position")
    m.d.comb += position.eq((cycle - 1) * config.clocks_per_tick + divider)
    if config.clocks_per_tick > 1:
        m.d.comb += Assert(divider < config.clocks_per_tick, "timing: divider in 0..F-1")
    m.d.comb += [
        Assume(ResetSignal() == 0),
        Assert(~out.valid | pending, "a beat only while words of the interval are left (each once)"),
        Assert(~out.valid | (out.p.words == snap.word_select(expect, n * wd)),
               "beat carries the next words in raster order"),
        Assert(~out.valid | (out.p.first == (expect == 0)), "first with beat 0 only"),
        Assert(~array.frame_valid | ~pending | (out.valid & (expect == B - 1)),
               "every beat left before the next interval's words"),
        Assert(~pending | (age <= 2 * L), "last beat within 2L clocks of the interval's end"),
        Assert(~array.frame_valid | ~seen | (since == L), "words every L clocks"),
        Assert(sending == pending, "readout busy iff words are left"),
        Assert(~pending | (beat == expect), "readout beat index"),
        Assert(~pending | (held == snap), "readout buffer holds the interval's words"),
        Assert(~pending | (age == expect + 2), "beats leave one per clock after the words"),
        Assert(~pending | (since == expect + 1), "beat index counts clocks since the words"),
        Assert(~seen | (since == position + 1), "clocks since the words = the timing's position + 1"),
        Assert((cycle >= 1) & (cycle <= config.alpha), "timing: CCC in 1..alpha"),
        Assert(seen | ~pending, "no words before the first interval's"),
        Assert(seen | ~primed | (position <= L - 1), "timing position inside the interval"),
    ]
    m.d.sync += since.eq(Mux(since < L + 1, since + 1, since))
    m.d.sync += age.eq(Mux(age < 2 * L + 1, age + 1, age))
    with m.If(array.frame_valid):
        m.d.sync += [snap.eq(Cat(array.frame, Const(0, pad)) if pad else array.frame),
                     expect.eq(0), pending.eq(1), age.eq(2), since.eq(1), seen.eq(1)]
    with m.Elif(out.valid):
        m.d.sync += expect.eq(expect + 1)
        with m.If(expect == B - 1):
            m.d.sync += pending.eq(0)
    harness = _Harness.__new__(_Harness)
    harness.config, harness.m, harness.pixel, harness.state = config, m, top, {}
    harness.inputs = [top.charge]
    harness.gate_level = True
    return harness


def _find_fragment(fragment, *ports: str):
    """The (sub)fragment elaborated from an object with all of ``ports`` (depth first)."""
    def search(node):
        if any(all(hasattr(o, p) for p in ports) for o in getattr(node, "origins", None) or ()):
            return node
        for sub, _, _ in node.subfragments:
            found = search(sub)
            if found is not None:
                return found
        return None
    found = search(fragment)
    if found is None:
        raise ProofToolError(f"no block with ports {', '.join(ports)} inside the design")
    return found
