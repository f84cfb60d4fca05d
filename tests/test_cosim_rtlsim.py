"""Conformance of the Amaranth RTL with the golden model, through cosim.rtlsim (SPEC sections 3, 4, 6)."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tespike.cosim.rtlsim import (RTLProtocolError, iter_packed_charge, rtl_run, rtl_words, unpack_frames)
from tespike.golden.config import SensorConfig
from tespike.golden.errors import ConfigError, InputError
from tests.configs import EDGE_CONFIGS, MSB_CONFIGS
from tests.cosim_helpers import assert_rtl_matches_golden, golden_words, light_stimulus, threshold_stimulus


def _name(request):
    return request.node.nodeid.split("::", 1)[1]


# -- bus packing ------------------------------------------------------------

@pytest.mark.parametrize("bits", [1, 3, 8, 13, 16, 32])
def test_packing_puts_pixel_rc_at_its_bits(bits, rng):
    stim = rng.integers(0, 1 << bits, size=(5, 2, 3), dtype=np.int64)
    stim[0] = (1 << bits) - 1                         # all ones: every bit of the bus set
    packed = list(iter_packed_charge(stim, bits))
    for t in range(5):
        expected = sum(int(stim[t, r, c]) << ((r * 3 + c) * bits) for r in range(2) for c in range(3))
        assert packed[t] == expected
    assert packed[0] == (1 << (6 * bits)) - 1


def test_unpack_frames_inverts_the_frame_layout(rng):
    words = rng.integers(0, 1 << 5, size=(4, 7))
    frames = [sum(int(w) << (i * 5) for i, w in enumerate(row)) for row in words]
    assert np.array_equal(unpack_frames(frames, 7, 5), words)
    assert unpack_frames([], 7, 5).shape == (0, 7)


# -- RTL == golden -----------------------------------------------------------

@pytest.mark.parametrize("config", EDGE_CONFIGS + MSB_CONFIGS, ids=str)
def test_rtl_equals_golden_on_edge_configs(config, rng, request):
    readouts = max(2, min(4, 1500 // config.clocks_per_readout))
    stim = threshold_stimulus(config, rng, readouts, 2, 4)
    words = assert_rtl_matches_golden(config, stim, _name(request))
    codes = min(3, config.clocks_per_readout + 1, 1 << config.word_bits)
    assert len(np.unique(words)) >= codes             # the stimulus reaches several codes


@pytest.mark.parametrize("config", [SensorConfig(), SensorConfig(mode="ml")], ids=str)
def test_rtl_equals_golden_in_the_papers_settings(config, rng, request):
    # twelve decades of light in one 3 x 4 frame, from 0 to 1e5 x design (the input saturates)
    stim = light_stimulus(config, rng, 3, 3, 4, dtype=np.uint16)
    words = assert_rtl_matches_golden(config, stim, _name(request))
    if config.is_te:      # dark pixels count, bright ones overflow early (small m)
        assert words[:, 0, 0].max() == 0 and (words >> config.d).any() and (words < (1 << config.d)).any()
    else:
        assert words.max() == min(config.ml_max, config.clocks_per_readout) and words.min() == 0


EXTREMES = [SensorConfig(), SensorConfig(mode="ml"), SensorConfig(b1=2, b2=2, threshold=1, acc_bits=1),
            SensorConfig(b1=2, b2=3, input_bits=32, threshold=1000), SensorConfig(b1=1, b2=1),
            SensorConfig(mode="ml", ml_bits=1, b1=2, b2=2, input_bits=3, threshold=40),
            SensorConfig(b1=1, b2=1, clocks_per_tick=2, input_bits=32, threshold=3, acc_bits=62)]   # widest


def _extreme(kind, config, rng):
    L = config.clocks_per_readout
    K = 3 if L > 100 else 6
    shape = (K * L, 2, 2)
    if kind == "zero":
        return np.zeros(shape, np.uint8)
    if kind == "max":
        return np.full(shape, config.input_max, np.uint32 if config.input_bits == 32 else np.int64)
    stim = np.zeros(shape, np.int64)                 # bursts: max input for runs of clocks, else dark
    for _ in range(4 * K):
        start, length = rng.integers(0, K * L), rng.integers(1, max(2, L // 2))
        stim[start:start + length, rng.integers(0, 2), rng.integers(0, 2)] = config.input_max
    return stim


@pytest.mark.parametrize("kind", ["zero", "max", "bursts"])
@pytest.mark.parametrize("config", EXTREMES, ids=str)
def test_rtl_equals_golden_on_extreme_stimuli(kind, config, rng, request):
    stim = _extreme(kind, config, rng)
    words = assert_rtl_matches_golden(config, stim, _name(request))
    if kind == "zero":
        assert not words.any()
    if kind == "max":     # a spike every clock: TE overflows at the 2^b1-th clock, ML counts min(L, max)
        if config.is_te:
            F = config.clocks_per_tick
            top = config.p_max <= config.clocks_per_readout
            expected = ((1 << config.d) | ((config.p_max - 1) // F + 1)) if top else config.clocks_per_readout
        else:
            expected = min(config.clocks_per_readout, config.ml_max)
        assert (words == expected).all()


def test_flat_array_equals_golden(rng, request):
    config = SensorConfig(b1=3, b2=2, clocks_per_tick=5, threshold=9)
    assert_rtl_matches_golden(config, threshold_stimulus(config, rng, 4, 2, 3), _name(request), flat=True)


@st.composite
def configs(draw):
    mode = draw(st.sampled_from(["te", "ml"]))
    b1, b2 = draw(st.integers(1, 4)), draw(st.integers(1, 3))
    theta = draw(st.integers(1, 60))
    return SensorConfig(
        mode=mode, b1=b1, b2=b2, alpha=draw(st.integers(1, (1 << b2) - 1)),
        clocks_per_tick=draw(st.integers(1, 4)), threshold=theta,
        acc_bits=draw(st.integers(theta.bit_length(), theta.bit_length() + 3)),
        input_bits=draw(st.sampled_from([1, 2, 5, 8, 12, 32])), ml_bits=draw(st.integers(1, 6)))


@settings(deadline=None, max_examples=25, suppress_health_check=[HealthCheck.too_slow])
@given(config=configs(), height=st.integers(1, 2), width=st.integers(1, 3), readouts=st.integers(1, 3),
       seed=st.integers(0, 2**32 - 1))
def test_rtl_equals_golden_on_random_configs(config, height, width, readouts, seed):
    stim = threshold_stimulus(config, np.random.default_rng(seed), readouts, height, width)
    assert_rtl_matches_golden(config, stim, f"random-{config}-{height}x{width}-{readouts}-{seed}")


def test_readouts_come_at_one_fixed_latency_of_at_most_L(rng):
    config = SensorConfig(b1=2, b2=2, threshold=20)
    L = config.clocks_per_readout
    run = rtl_run(config, threshold_stimulus(config, rng, 5, 1, 2))
    assert 0 <= run.latency <= L
    assert np.array_equal(run.clocks, np.arange(5) * L + L - 1 + run.latency)
    assert run.cycles == 5 * L + run.latency and run.seconds > 0


def test_long_run_keeps_the_residual_across_readouts(request):
    # 3 electrons per clock against theta = 5, L = 12: 36 electrons = 7.2 spikes per readout.
    # With the residual kept the counts are 7 and 8 (mean 7.2); clearing acc would give 7 always.
    config = SensorConfig(mode="ml", b1=2, b2=2, threshold=5, ml_bits=8)
    stim = np.full((40 * config.clocks_per_readout, 1, 1), 3, np.int64)
    words = assert_rtl_matches_golden(config, stim, _name(request))
    assert set(np.unique(words)) == {7, 8} and words.sum() == 40 * 36 // 5


def test_no_readouts_gives_an_empty_stream():
    assert rtl_words(SensorConfig(), np.zeros((0, 2, 3), np.int16)).shape == (0, 2, 3)


@pytest.mark.parametrize("stimulus, words", [
    (np.zeros((240, 1, 1), np.float64), "float"),
    (np.zeros((239, 1, 1), np.int32), "multiple"),
    (np.full((240, 1, 1), 1 << 16, np.int32), "65536"),
    (np.zeros((240, 1), np.int32), "shape"),
])
def test_bad_stimulus_is_refused_before_simulating(stimulus, words):
    with pytest.raises(InputError, match=words):
        rtl_words(SensorConfig(), stimulus)


@pytest.mark.parametrize("name", ["rtl_words", "rtl_run", "rtl_stream_run", "run_icarus", "run_icarus_stream",
                                  "run_verilator", "run_verilator_stream"])
def test_what_is_no_configuration_is_refused_naming_the_entry_point(name):
    """Before any tool runs (a preset's name was an AttributeError on its first field)."""
    from tespike.cosim import icarus, rtlsim, verilator
    function = next(getattr(m, name) for m in (rtlsim, icarus, verilator) if hasattr(m, name))
    lanes = (1,) if name.endswith("stream_run") or name.endswith("_stream") else ()
    with pytest.raises(ConfigError, match=f"^{name}: configuration must be a SensorConfig .*not str$"):
        function("te", np.zeros((240, 1, 1), np.int16), *lanes)


@pytest.mark.parametrize("name, option", [("run_icarus", "work_dir"), ("run_verilator", "build_dir")])
def test_a_work_folder_that_is_no_path_is_refused_before_any_tool_runs(name, option):
    """(A number had been os.fspath's TypeError.)"""
    from tespike.cosim import icarus, verilator
    function = getattr(icarus if name == "run_icarus" else verilator, name)
    with pytest.raises(InputError, match=f"^{option}: a path must be a str or an os.PathLike, not int$"):
        function(SensorConfig(), np.zeros((240, 1, 1), np.int16), **{option: 3})


def test_a_config_the_rtl_refuses_is_a_config_error(monkeypatch):
    import tespike.rtl.array
    from tespike import rtl

    def refusing(*args, **kwargs):
        raise ValueError("no such array in this process")

    monkeypatch.setattr(rtl.array, "PixelArray", refusing)
    with pytest.raises(ConfigError, match="RTL cannot build.*no such array"):
        rtl_words(SensorConfig(), np.zeros((240, 1, 1), np.int16))


# -- the protocol check can fail --------------------------------------------

def _delayed_array(delay, double=False):
    """A PixelArray whose outputs pass through ``delay`` more registers (optionally pulsing twice)."""
    from amaranth.hdl import Module, Signal
    from amaranth.lib import wiring
    from amaranth.lib.wiring import In, Out

    from tespike.rtl.array import PixelArray

    class Delayed(wiring.Component):
        def __init__(self, config, height, width, flat=False):
            self.inner = PixelArray(config, height, width)
            super().__init__({"charge": In(len(self.inner.charge)), "frame_valid": Out(1),
                              "frame": Out(len(self.inner.frame))})

        def elaborate(self, platform):
            m = Module()
            m.submodules.inner = self.inner
            m.d.comb += self.inner.charge.eq(self.charge)
            valid, frame = self.inner.frame_valid, self.inner.frame
            for i in range(delay):
                v, f = Signal(name=f"v{i}"), Signal(len(frame), name=f"f{i}")
                m.d.sync += [v.eq(valid), f.eq(frame)]
                valid, frame = v, f
            m.d.comb += [self.frame_valid.eq(valid | (self.inner.frame_valid if double else 0)),
                         self.frame.eq(frame)]
            return m
    return Delayed


@pytest.mark.parametrize("delay, double, ok", [(0, False, True), (11, False, True),
                                               (12, False, False), (3, True, False)])
def test_protocol_check_refuses_late_or_doubled_frame_valid(monkeypatch, rng, delay, double, ok):
    import tespike.cosim.rtlsim
    from tespike import cosim
    import tespike.rtl.array
    from tespike import rtl
    config = SensorConfig(b1=2, b2=2, threshold=20)           # L = 12, the RTL's own latency is 1
    monkeypatch.setattr(rtl.array, "PixelArray", _delayed_array(delay, double))
    stim = threshold_stimulus(config, rng, 3, 1, 2)
    if ok:
        assert np.array_equal(cosim.rtlsim.rtl_words(config, stim), golden_words(config, stim))
    else:
        with pytest.raises(RTLProtocolError, match="latency"):
            cosim.rtlsim.rtl_words(config, stim)


@pytest.mark.parametrize("config", [SensorConfig(b1=2, b2=2, threshold=3), SensorConfig(mode="ml", b1=2, b2=2,
                                                                                         threshold=3)], ids=str)
def test_charge_during_reset_is_ignored(config, rng):
    # all ones on the bus while rst is high: a synchronous reset must leave acc, SFC and CCC at zero
    stim = threshold_stimulus(config, rng, 3, 2, 2)
    run = rtl_run(config, stim, reset_charge=(1 << (4 * config.input_bits)) - 1)
    assert np.array_equal(run.words, golden_words(config, stim))
