"""The fast engine (golden.sensor) against the literal rule (golden.reference), bit for bit."""

import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import tespike.golden.sensor as sensor
from tespike.golden.config import SensorConfig
from tespike.golden.decode import check_words
from tespike.golden.errors import InputError
from tespike.golden.reference import PixelState, step_reference
from tespike.golden.sensor import PixelArrayModel, simulate
from tests.configs import EDGE_CONFIGS, MSB_EDGE_CONFIGS

MSB = SensorConfig.preset("ml-msb")

STIMULUS_KINDS = ("uniform", "near-threshold", "bursts", "sparse-huge", "zero", "max", "mixed")


def make_stimulus(config, kind, shape, rng):
    """Electrons per clock of one kind, int64 within the configured input range."""
    top, theta = config.input_max, config.threshold
    if kind == "uniform":
        stim = rng.integers(0, top, size=shape, endpoint=True)
    elif kind == "near-threshold":       # around one spike per clock: busy, idle and saturating
        light = rng.uniform(0.2, 2.0, size=(1,) + shape[1:])
        stim = np.minimum(rng.poisson(np.minimum(theta * light, 1e12), size=shape), top)
    elif kind == "bursts":               # quiet stretches, then runs of large values
        on = rng.random((shape[0], 1, 1)) < 0.15
        stim = np.where(on, rng.integers(0, top, size=shape, endpoint=True), rng.integers(0, 2, size=shape))
        stim = np.minimum(stim, top)
    elif kind == "sparse-huge":
        stim = np.where(rng.random(shape) < 0.05, top, 0)
    elif kind == "zero":
        stim = np.zeros(shape, np.int64)
    elif kind == "max":
        stim = np.full(shape, top)
    else:                                # a different kind per pixel
        parts = [make_stimulus(config, k, shape, rng) for k in STIMULUS_KINDS[:-1]]
        choice = rng.integers(0, len(parts), size=shape[1:])
        stim = np.choose(choice, parts)
    return np.asarray(stim, np.int64)


def split_points(T, rng, pieces):
    cuts = sorted(set(int(x) for x in rng.integers(0, T + 1, size=pieces)))
    return [0] + cuts + [T]


def assert_same_state(engine: PixelState, reference: PixelState):
    assert engine.clock == reference.clock
    for name in ("acc", "sfc", "ovf", "m"):
        assert np.array_equal(getattr(engine, name), getattr(reference, name)), name


def run_engine(config, stim, bounds):
    array = PixelArrayModel(config, stim.shape[1:])
    parts = [array.feed(stim[a:b]) for a, b in zip(bounds[:-1], bounds[1:])]
    return np.concatenate(parts), array.state


def check_equal(config, stim, bounds):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        words, state = run_engine(config, stim, bounds)
    expected, expected_state = step_reference(config, stim)
    assert np.array_equal(words, expected), (config, np.argwhere(words != expected)[:3])
    assert_same_state(state, expected_state)
    check_words(words, config)


@st.composite
def configs(draw):
    """Valid configurations over every range of SPEC section 2, with short readouts."""
    mode = draw(st.sampled_from(["te", "ml"]))
    b1 = draw(st.integers(1, 16))
    b2 = draw(st.integers(1, 16))
    alpha = draw(st.integers(1, min(6, (1 << b2) - 1)))
    clocks = draw(st.integers(1, 7))
    theta = draw(st.one_of(st.integers(1, 20), st.integers(1, 5000), st.integers(1, (1 << 62) - 1),
                           st.sampled_from([(1 << 31) - 1, 1 << 31, (1 << 32) - 1, 1 << 32])))
    acc_bits = draw(st.integers(max(1, theta.bit_length()), min(62, theta.bit_length() + draw(
        st.sampled_from([0, 1, 2, 8, 62])))))
    readout = draw(st.sampled_from(["count", "msb"])) if mode == "ml" else "count"
    return SensorConfig(mode=mode, b1=b1, b2=b2, alpha=alpha, clocks_per_tick=clocks, threshold=theta,
                        acc_bits=acc_bits, input_bits=draw(st.integers(1, 32)),
                        ml_bits=draw(st.integers(1, 16)), ml_readout=readout)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(config=configs(), kind=st.sampled_from(STIMULUS_KINDS), seed=st.integers(0, 2**32 - 1),
       readouts=st.integers(1, 12), pieces=st.integers(0, 6))
def test_engine_equals_reference_random_configs(config, kind, seed, readouts, pieces):
    rng = np.random.default_rng(seed)
    T = config.clocks_per_readout * readouts + int(rng.integers(0, config.clocks_per_readout))
    stim = make_stimulus(config, kind, (T, 2, 3), rng)
    check_equal(config, stim, split_points(T, rng, pieces))


@pytest.mark.parametrize("kind", STIMULUS_KINDS)
@pytest.mark.parametrize("config", EDGE_CONFIGS + MSB_EDGE_CONFIGS, ids=str)
def test_engine_equals_reference_edge_configs(config, kind, rng):
    T = config.clocks_per_readout * max(2, 300 // config.clocks_per_readout)
    stim = make_stimulus(config, kind, (T, 3, 4), rng)
    check_equal(config, stim, split_points(T, rng, 4))


@pytest.mark.parametrize("config", [SensorConfig(), SensorConfig(mode="ml"), MSB, EDGE_CONFIGS[6], EDGE_CONFIGS[7]],
                         ids=str)
def test_wide_array_in_pixel_blocks(config, rng, monkeypatch):
    """More pixels than one block: columns are cut into blocks of BLOCK_PIXELS (forced small here)."""
    monkeypatch.setattr(sensor, "BLOCK_PIXELS", 100)
    L = config.clocks_per_readout
    stim = make_stimulus(config, "mixed", (2 * L + 37, 24, 24), rng)
    check_equal(config, stim, split_points(len(stim), rng, 3))


@pytest.mark.parametrize("config", [SensorConfig(), SensorConfig(mode="ml"), MSB, EDGE_CONFIGS[6], EDGE_CONFIGS[8],
                                    SensorConfig(acc_bits=20), SensorConfig(threshold=(1 << 61) - 1, acc_bits=62,
                                                                            input_bits=32)],
                         ids=str)
def test_step_equals_reference_clock_by_clock(config, rng):
    """_Engine.step: acc and the spike count after every clock equal the reference's, random acc0."""
    engine = sensor._Engine(config)
    T = engine.block_clocks
    stim = make_stimulus(config, "mixed", (T, 5, 7), rng)
    stim[:, 0, :3] = [0, config.input_max, min(config.input_max, config.threshold + config.acc_max)]
    acc0 = rng.integers(0, config.acc_max, size=35, endpoint=True)
    acc0[:3] = [config.acc_max, config.acc_max, 0]
    e = stim.reshape(T, 35)
    C, acc = engine.step(engine._inputs(e, int(e.max()), False), acc0)
    assert C.dtype == engine.dtype
    state = PixelState.zeros((5, 7))
    state.acc = acc0.reshape(5, 7).copy()
    free = SensorConfig(mode="ml", b1=config.b1, b2=config.b2, alpha=config.alpha,
                        clocks_per_tick=config.clocks_per_tick, threshold=config.threshold,
                        acc_bits=config.acc_bits, input_bits=config.input_bits, ml_bits=16)
    read = np.zeros((5, 7), np.int64)                        # spikes in readouts already emitted
    for t in range(T):
        words, state = step_reference(free, stim[t:t + 1], state)
        read += words.sum(axis=0)
        N = t + 1 + C[t].astype(np.int64)
        assert np.array_equal(N, (read + state.sfc).reshape(35)), t
    assert np.array_equal(acc, state.acc.reshape(35))


@pytest.mark.parametrize("config", [SensorConfig(), SensorConfig(mode="ml"), MSB, EDGE_CONFIGS[6], EDGE_CONFIGS[8]],
                         ids=str)
def test_every_input_at_least_theta_shortcut(config, rng):
    """Blocks with e >= theta everywhere: every pixel fires every clock; capped walk and pinned top."""
    theta, M, top = config.threshold, config.acc_max, config.input_max
    if top < theta:
        pytest.skip("input cannot reach theta")
    T = config.clocks_per_readout * 3
    walk = rng.integers(theta, min(top, theta + M), size=(T, 4, 5), endpoint=True)
    pinned = rng.integers(min(top, theta + M), top, size=(T, 4, 5), endpoint=True)
    for stim in (walk, pinned, np.concatenate([pinned[:T // 2], walk[T // 2:]])):
        check_equal(config, stim, split_points(T, rng, 3))


@pytest.mark.parametrize("config", [SensorConfig(), SensorConfig(mode="ml"), MSB, EDGE_CONFIGS[6], EDGE_CONFIGS[8]],
                         ids=str)
def test_quiet_pinned_and_firing_pixels_mixed(config, rng, monkeypatch):
    """Blocks mixing dark, pinned (e >= theta + M), firing and other pixels; whole-block shortcuts taken."""
    steps = []
    original = sensor._Engine.step
    monkeypatch.setattr(sensor._Engine, "step", lambda self, ep, *a: steps.append(ep.shape) or
                        original(self, ep, *a))
    theta, M, top = config.threshold, config.acc_max, config.input_max
    T, shape = config.clocks_per_readout * 3, (24, 24)
    kind = rng.integers(0, 5, size=shape)
    kind[0, :4] = [0, 1, 2, 3]
    zero = np.zeros((T,) + shape, np.int64)
    pinned = np.full((T,) + shape, top) if top >= theta + M else zero
    firing = rng.integers(min(theta, top), min(top, theta + M), size=(T,) + shape, endpoint=True)
    dark_then_bright = np.where(np.arange(T)[:, None, None] < T // 2, 0, top)
    mixed = make_stimulus(config, "mixed", (T,) + shape, rng)
    stim = np.choose(kind, [zero, pinned, firing, dark_then_bright, mixed])
    check_equal(config, stim, split_points(T, rng, 3))
    assert steps, "the stepping path was not taken"
    for whole in (zero, firing, pinned):                     # one kind everywhere: no stepping
        steps.clear()
        check_equal(config, whole, split_points(T, rng, 2))
        assert not steps or (whole is not zero and top < theta), "a whole-block shortcut was not taken"


@pytest.mark.parametrize("config", [SensorConfig(), SensorConfig(acc_bits=14), EDGE_CONFIGS[6], MSB_EDGE_CONFIGS[3]],
                         ids=str)
def test_zero_input_after_bright_drains_the_residual(config, rng):
    """Zero input with acc0 >= theta must still fire: the no-spike shortcut needs acc0 < theta."""
    L = config.clocks_per_readout
    stim = np.zeros((L * 3, 4, 4), np.int64)
    stim[L - 3:L] = config.input_max                     # fill the accumulator, then darkness
    stim[:, 0, 0] = 0
    check_equal(config, stim, split_points(len(stim), rng, 3))
    if config.acc_max >= 2 * config.threshold and config.input_max > config.threshold:
        assert step_reference(config, stim)[1].acc.max() < config.threshold   # it did drain


@pytest.mark.parametrize("config", [SensorConfig(b1=2, b2=2, threshold=9, acc_bits=5),
                                    SensorConfig(mode="ml", ml_readout="msb", ml_bits=4, b1=2, b2=2, threshold=9,
                                                 acc_bits=5)], ids=str)
def test_chunks_of_one_clock(config, rng):
    stim = make_stimulus(config, "mixed", (config.clocks_per_readout * 4, 3, 3), rng)
    check_equal(config, stim, list(range(len(stim) + 1)))


@pytest.mark.parametrize("config", [SensorConfig(b1=2, b2=1, clocks_per_tick=2, threshold=5, acc_bits=4),  # L = 2
                                    SensorConfig(mode="ml", ml_readout="msb", ml_bits=6, b1=2, b2=1,
                                                 clocks_per_tick=2, threshold=5, acc_bits=4)], ids=str)
def test_long_run_of_thousands_of_readouts_in_chunks(config, rng):
    stim = make_stimulus(config, "mixed", (config.clocks_per_readout * 3000, 2, 3), rng)
    bounds = [0]
    while bounds[-1] < len(stim):
        bounds.append(min(len(stim), bounds[-1] + int(rng.integers(1, 700))))
    check_equal(config, stim, bounds)
    assert len(simulate(config, stim)) == 3000


@pytest.mark.parametrize("config", [SensorConfig(), MSB], ids=str)
def test_simulate_chunking_gives_identical_stream(config, rng):
    stim = make_stimulus(config, "near-threshold", (config.clocks_per_readout * 6, 5, 4), rng).astype(np.uint16)
    whole = simulate(config, stim)
    pieces = simulate(config, stim, chunks=(stim[a:b] for a, b in [(0, 1), (1, 500), (500, 1440)]))
    assert np.array_equal(whole, pieces)
    assert np.array_equal(whole, step_reference(config, stim)[0])
    with pytest.raises(ValueError, match="covered"):
        simulate(config, stim, chunks=[stim[:240]])


@pytest.mark.parametrize("acc_bits, theta", [(62, 1), (61, 3), (60, (1 << 59) + 5), (62, (1 << 62) - 1)])
def test_widest_accumulators(acc_bits, theta, rng):
    for mode in ({"mode": "te"}, {"mode": "ml", "ml_readout": "msb", "ml_bits": 3}):
        config = SensorConfig(b1=2, b2=2, clocks_per_tick=2, threshold=theta, acc_bits=acc_bits, input_bits=32,
                              **mode)
        for kind in ("max", "sparse-huge", "uniform"):
            stim = make_stimulus(config, kind, (config.clocks_per_readout * 3, 2, 2), rng)
            check_equal(config, stim, split_points(len(stim), rng, 2))


def test_working_dtype_follows_the_bound():
    """The narrowest dtype holding max(2M, theta + M): the paper configs run in int16."""
    assert sensor._plan(SensorConfig()) == np.int16
    assert sensor._plan(SensorConfig(mode="ml")) == np.int16
    assert sensor._plan(SensorConfig(acc_bits=14)) == np.int16          # 2M = 32766
    assert sensor._plan(SensorConfig(acc_bits=15)) == np.int32
    assert sensor._plan(SensorConfig(input_bits=32, threshold=1000, b1=2, b2=3, acc_bits=30)) == np.int32
    assert sensor._plan(SensorConfig(input_bits=32, threshold=1000, b1=2, b2=3, acc_bits=31)) == np.int64
    assert sensor._plan(SensorConfig(threshold=(1 << 62) - 1, acc_bits=62, input_bits=32)) == np.int64


def test_feed_refuses_bad_chunks():
    array = PixelArrayModel(SensorConfig(), (2, 2))
    with pytest.raises(InputError, match="65536"):
        array.feed(np.full((3, 2, 2), 65536, np.int64))
    with pytest.raises(InputError, match="float"):
        array.feed(np.zeros((3, 2, 2)))
    with pytest.raises(InputError, match="chunk shape \\(2, 3\\) != pixel array shape \\(2, 2\\)"):
        array.feed(np.zeros((3, 2, 3), np.int64))
    assert array.state.clock == 0


@pytest.mark.parametrize("shape", [(0, 2), (2, -1), (1, 2, 3), (2,), 4, (2.0, 2), (True, 2), None])
def test_a_pixel_array_of_no_pixels_or_no_frame_shape_is_refused(shape):
    """One line naming the shape (numpy had refused a negative size in its own words, and an
    array had been made of three numbers or of no pixels); the fast simulator shares the rule."""
    from tespike.golden.fastsim import SceneSimulator
    with pytest.raises(InputError, match="pixel array shape") as info:
        PixelArrayModel(SensorConfig(), shape)
    assert repr(shape) in str(info.value)
    with pytest.raises(InputError, match="simulator shape"):
        SceneSimulator(SensorConfig(), shape, rng=1)


# -- extreme cases (docs/golden-model.md) ---------------------------------------------

def test_zero_stimulus_gives_zero_words_and_state():
    for config in EDGE_CONFIGS + MSB_EDGE_CONFIGS:
        stim = np.zeros((config.clocks_per_readout * 3, 2, 2), np.uint8)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            words, state = run_engine(config, stim, [0, 5 % len(stim), len(stim)])
        assert not words.any() and not state.acc.any()


@pytest.mark.parametrize("config", [SensorConfig(input_bits=32), SensorConfig(mode="ml", input_bits=32),
                                    SensorConfig(mode="ml", ml_readout="msb", input_bits=32),
                                    SensorConfig(input_bits=32, threshold=(1 << 32) - 1, acc_bits=40),
                                    SensorConfig(b1=2, b2=3, input_bits=32, threshold=1000)], ids=str)
def test_max_input_every_clock_at_32_bits(config):
    """2^32 - 1 electrons every clock: a spike every clock, the accumulator pinned at its top."""
    stim = np.full((config.clocks_per_readout * 4, 3, 2), config.input_max, np.uint32)
    check_equal(config, stim, [0, 1, 300, len(stim)])
    words = simulate(config, stim)
    if config.is_te:
        m = (config.p_max - 1) // config.clocks_per_tick + 1     # overflow at clock 2^b1 - 1
        assert (words == ((1 << config.d) | m)).all()
    elif config.is_msb:      # L = 240 spikes: msb 8 each time (the counter tops out at 255)
        assert (words == min(config.ml_max, config.clocks_per_readout).bit_length()).all()
    else:
        assert (words == min(config.ml_max, config.clocks_per_readout)).all()


@pytest.mark.parametrize("config", [SensorConfig(), SensorConfig(mode="ml"), SensorConfig(input_bits=32), MSB,
                                    SensorConfig(mode="ml", ml_readout="msb", ml_bits=16, input_bits=32),
                                    SensorConfig(mode="ml", ml_readout="msb", ml_bits=1)], ids=str)
def test_twelve_decades_in_one_frame(config, rng):
    """Light from 1e-7 to 1e5 x design light across one frame (and 1e30 clipped to the input's top)."""
    L = config.clocks_per_readout
    light = np.append(np.logspace(-7, 5, 47), 1e30).reshape(1, 6, 8)
    mean = np.minimum(42000.0 * light / L, 1e15)
    stim = np.minimum(rng.poisson(np.broadcast_to(mean, (L * 3, 6, 8))), config.input_max)
    stim = stim.astype(np.uint32 if config.input_bits > 16 else np.uint16)
    check_equal(config, stim, [0, 17, L + 3, len(stim)])
    words = simulate(config, stim)
    assert not words[:, 0, 0].any()                                 # 1e-7: no spike in 3 readouts
    assert (words[:, -1, -1] == words[:, -1, -2]).all()             # 1e30 reads like the next-brightest


def test_words_dtype_and_legality_for_every_edge_config(rng):
    for config in EDGE_CONFIGS + MSB_EDGE_CONFIGS:
        stim = make_stimulus(config, "mixed", (config.clocks_per_readout * 5, 3, 3), rng)
        words = simulate(config, stim)
        assert words.dtype == np.int64 and words.shape == (5, 3, 3)
        check_words(words, config)
