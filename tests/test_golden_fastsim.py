"""The fast simulator against the cycle-exact model fed per-clock Poisson electrons.

Statistical tests are seeded (deterministic). "Same distribution": the mean
decoded value agrees within 4 combined standard errors (pixels as the
independent unit, readouts averaged per pixel) and the code histograms within
total variation distance 0.05. Shortcuts that are deterministic are compared
word for word and accumulator for accumulator with the per-clock path.
"""

import re
import warnings

import numpy as np
import pytest

from tespike.golden.config import SensorConfig
from tespike.golden.decode import check_words, decode_spikes
from tespike.golden.errors import InputError
from tespike.golden.fastsim import SceneSimulator, clock, head, simulate_scene, stripe_simulators
from tespike.golden.stimulus import poisson_stimulus
from tespike.golden.noise import Sensor, SensorNoise
from tespike.golden.reference import msb_index
from tespike.golden.sensor import PixelArrayModel, simulate
from tests.configs import EDGE_CONFIGS, MSB_EDGE_CONFIGS

LEVELS = [1e-4, 1e-3, 1e-2, 0.05, 0.2, 0.5, 1.0, 2.0, 10.0]
MSB = SensorConfig.preset("ml-msb")


def _histogram(words, config):
    return np.bincount(words.ravel().astype(np.int64), minlength=1 << config.word_bits) / words.size


def _compare(config, levels, pixels, readouts, seed):
    """Fast and cycle-exact words for each light level -> list of (level, z, tvd)."""
    scene = np.broadcast_to(np.asarray(levels)[None, :, None], (readouts, len(levels), pixels)).copy()
    fast = simulate_scene(config, scene, seed=seed)
    exact = simulate(config, poisson_stimulus(config, scene, seed + 1))
    out = []
    for i, level in enumerate(levels):
        a = decode_spikes(fast[:, i], config).mean(axis=0)             # per-pixel mean
        b = decode_spikes(exact[:, i], config).mean(axis=0)
        se = np.sqrt(a.var() / a.size + b.var() / b.size)
        diff = a.mean() - b.mean()
        z = 0.0 if diff == 0 else diff / max(se, 1e-12)
        tvd = 0.5 * np.abs(_histogram(fast[:, i], config) - _histogram(exact[:, i], config)).sum()
        out.append((level, z, tvd))
    return out


@pytest.mark.parametrize("config, pixels", [
    (SensorConfig(), 2000),                                           # paper TE, L = 240
    (SensorConfig(mode="ml"), 2000),                                  # paper ML
    (MSB, 2000),                                                      # paper eq. 10 ML (msb)
], ids=str)
def test_paper_configs_match_cycle_exact_model(config, pixels):
    for level, z, tvd in _compare(config, LEVELS, pixels, 3, seed=11):
        assert abs(z) < 4 and tvd < 0.05, (level, z, tvd)


@pytest.mark.parametrize("config", [EDGE_CONFIGS[i] for i in (2, 3, 4, 5, 6, 8, 9, 10, 11)]
                         + MSB_EDGE_CONFIGS[1:], ids=str)
def test_edge_configs_match_cycle_exact_model(config):
    for level, z, tvd in _compare(config, LEVELS, 4000, 4, seed=5):
        assert abs(z) < 4 and tvd < 0.05, (level, z, tvd)


def test_carried_residual_matches_over_many_readouts():
    # dim light: a spike needs several readouts of charge, so the words depend
    # entirely on the residual carried from readout to readout
    config = SensorConfig(b1=2, b2=2, threshold=100)                 # L = 12
    for level, z, tvd in _compare(config, [0.0007, 0.0013, 0.004], 3000, 12, seed=3):
        assert abs(z) < 4 and tvd < 0.05, (level, z, tvd)


@pytest.mark.parametrize("config", [SensorConfig(), MSB], ids=str)
def test_light_steps_between_readouts_match(config):
    # bright after dark and dark after bright: backlogged and full accumulators
    # (and msb counter remainders, read out in the dark) carried
    rng = np.random.default_rng(0)
    pixels = 4000
    sequence = np.array([0.0, 3.0, 0.0, 1.0, 0.4, 2.0, 0.02, 0.0])
    scene = np.broadcast_to(sequence[:, None, None], (8, 1, pixels)).copy()
    fast = simulate_scene(config, scene, seed=rng)
    exact = simulate(config, poisson_stimulus(config, scene, rng))
    for k in range(len(sequence)):
        tvd = 0.5 * np.abs(_histogram(fast[k], config) - _histogram(exact[k], config)).sum()
        assert tvd < 0.05, (k, tvd)


def test_each_path_is_exercised(monkeypatch):
    config = SensorConfig()
    monkeypatch.setattr(head, "HEAD_CLOCK_DRAWS", 0)         # a single head takes its path
    sim = SceneSimulator(config, (1, 7), rng=0)
    # the last pixel: light 1.5 from an empty accumulator (a head charges it
    # for the full path), then dim light on the full accumulator (a head drains it)
    sim.readout(np.array([[0.0, 0.01, 10.0, 0.6, 1.0, 10.0, 1.5]]))
    assert sim.path_counts == {"lazy": 1, "event": 1, "bright": 2, "queue": 1, "full": 0, "head": 1,
                               "clock": 1, "fallback": 0}
    assert sim.acc[6] == config.acc_max
    sim.readout(np.array([[0.0, 0.01, 10.0, 0.6, 1.0, 1.5, 0.01]]))     # full after a full accumulator
    assert sim.path_counts == {"lazy": 2, "event": 2, "bright": 3, "queue": 2, "full": 1, "head": 2,
                               "clock": 2, "fallback": 0}


def test_a_readout_with_few_heads_sends_them_per_clock():
    """Heads whose per-clock draws are at most HEAD_CLOCK_DRAWS join the per-clock path (a
    head call's fixed cost exceeds their clocks'); a readout with more keeps the head path."""
    config = SensorConfig()
    L = config.clocks_per_readout
    few = head.HEAD_CLOCK_DRAWS // L                  # heads (light 1.5 on an empty accumulator)
    for pixels, path in ((few, "clock"), (few + 1, "head")):
        sim = SceneSimulator(config, (1, pixels), rng=0)
        sim.readout(np.full((1, pixels), 1.5))
        assert sim.path_counts[path] == pixels, (pixels, sim.path_counts)


@pytest.mark.parametrize("config", [SensorConfig(), SensorConfig(mode="ml"), MSB,
                                    SensorConfig(b1=5, b2=3, acc_bits=12)], ids=str)
def test_queue_and_full_paths_match_cycle_exact_model(config):
    """Light within a factor 2 of one threshold per clock, where charge backs up
    (queue path) or the accumulator stays near full (full path)."""
    per_clock = np.array([0.45, 0.7, 0.85, 1.15, 1.3, 1.6, 2.5])
    levels = per_clock * config.threshold * config.clocks_per_readout / 42000
    for level, z, tvd in _compare(config, levels, 2000, 3, seed=21):
        assert abs(z) < 4 and tvd < 0.05, (level, z, tvd)
    sim = SceneSimulator(config, (len(levels), 200), rng=0)
    for _ in range(3):
        sim.readout(np.broadcast_to(levels[:, None], (len(levels), 200)))
    assert sim.path_counts["queue"] > 0 and sim.path_counts["full"] > 0, sim.path_counts


@pytest.mark.parametrize("config", EDGE_CONFIGS + MSB_EDGE_CONFIGS, ids=str)
def test_deterministic_shortcuts_equal_per_clock_path(config):
    """No light, and light far above saturation: same words and same carried
    accumulator (and msb counter remainder) as the per-clock path, for any
    seed (nothing random is left)."""
    light = np.array([[0.0, 10.0, 1e3, 1e30, 1e308, 0.0]])
    fast = SceneSimulator(config, light.shape, rng=1)
    full = SceneSimulator(config, light.shape, rng=2, method="per-clock")
    # start from non-trivial carried charge (and counter remainder, below the
    # msb's worth a readout leaves: 2^(word - 1) - 1 at most)
    rest = (1 << (config.ml_bits - 1)) - 1
    for sim in (fast, full):
        sim.acc[:] = [0, 0, 1, config.acc_max, 0, min(config.threshold - 1, config.acc_max)]
        if config.is_msb:
            sim.sfc[:] = [rest, 0, rest, 1 % (rest + 1), rest // 2, rest]
    for _ in range(3):
        a, b = fast.readout(light), full.readout(light)
        assert np.array_equal(a[0, [0, 2, 3, 4, 5]], b[0, [0, 2, 3, 4, 5]])
        assert np.array_equal(fast.acc[[0, 2, 3, 4, 5]], full.acc[[0, 2, 3, 4, 5]])
        assert np.array_equal(fast.sfc[[0, 2, 3, 4, 5]], full.sfc[[0, 2, 3, 4, 5]])
    assert fast.path_counts["clock"] <= 3 * light.size


def test_bright_path_accumulator_matches_per_clock_in_distribution():
    # every clock surely spikes but the accumulator fills in about 3
    # readouts: its level is drawn from Poisson(mu) + carry, clipped when full
    config = SensorConfig(b1=2, b2=2, threshold=50, acc_bits=12)     # L = 12, acc_max = 4095
    light = np.full((1, 6000), 164 * 12 / 42000)                     # 164 electrons per clock
    fast = SceneSimulator(config, light.shape, rng=4)
    full = SceneSimulator(config, light.shape, rng=5, method="per-clock")
    for sim in (fast, full):
        for _ in range(3):
            sim.readout(light)
    assert fast.path_counts["bright"] == 3 * light.size
    assert 0.2 < (full.acc == config.acc_max).mean() < 0.8
    a, b = fast.acc.astype(float), full.acc.astype(float)
    se = np.sqrt(a.var() / a.size + b.var() / b.size)
    assert abs(a.mean() - b.mean()) < 4 * se and abs(a.std() / b.std() - 1) < 0.05


def test_event_path_accumulator_matches_per_clock_in_distribution():
    config = SensorConfig()
    light = np.full((1, 10000), 0.013)
    fast = SceneSimulator(config, light.shape, rng=6)
    full = SceneSimulator(config, light.shape, rng=7, method="per-clock")
    for sim in (fast, full):
        for _ in range(3):
            sim.readout(light)
    assert fast.path_counts["event"] == 3 * light.size
    bins = np.arange(0, config.threshold + 8, 8)
    ha = np.histogram(fast.acc, bins)[0] / fast.acc.size
    hb = np.histogram(full.acc, bins)[0] / full.acc.size
    assert 0.5 * np.abs(ha - hb).sum() < 0.05


@pytest.mark.parametrize("config", [EDGE_CONFIGS[i] for i in (0, 1, 5, 11)] + MSB_EDGE_CONFIGS, ids=str)
def test_noise_free_equals_cycle_exact_model_on_noise_free_stimulus(config):
    scene = np.zeros((5, 2, 6))
    scene[:, 0] = [0, 1e-3, 0.07, 0.5, 1.3, 1e30]
    scene[:, 1] = np.linspace(0, 3, 6)
    expected = simulate(config, poisson_stimulus(config, scene, noise=False))
    assert np.array_equal(simulate_scene(config, scene, noise=False), expected)


@pytest.mark.parametrize("config", EDGE_CONFIGS + MSB_EDGE_CONFIGS, ids=str)
def test_extreme_light_gives_legal_codes_without_warnings(config):
    scene = np.zeros((3, 3, 7))
    scene[:, 0] = [0, 1e-7, 1, 1e3, 1e30, 1e308, 5e-324]
    scene[:, 1] = np.logspace(-12, 0, 7)                             # twelve decades in one frame
    scene[:, 2] = np.logspace(-6, 6, 7)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        words = simulate_scene(config, scene, seed=0)
        dark = simulate_scene(config, scene, seed=0, dark_current="eq13")
    for w in (words, dark):
        check_words(w, config)
        assert w.shape == scene.shape
    assert not words[:, 0, 0].any()
    # 1e30 and 1e308 x design light saturate every input word: the same
    # deterministic codes, whatever the seed
    assert np.array_equal(words[:, 0, 4], words[:, 0, 5])
    assert np.array_equal(words[:, 0, 4], simulate_scene(config, scene[:, :1, 4:5], seed=99)[:, 0, 0])


def test_seed_reproduces_and_chunking_does_not_matter():
    config = SensorConfig()
    scene = np.random.default_rng(0).uniform(0, 2, (3, 5, 7))
    a = simulate_scene(config, scene, seed=9)
    assert np.array_equal(a, simulate_scene(config, scene, seed=9))
    assert not np.array_equal(a, simulate_scene(config, scene, seed=10))


def test_refuses_bad_input():
    with pytest.raises(InputError, match="negative"):
        simulate_scene(SensorConfig(), np.full((1, 1, 1), -1.0))
    with pytest.raises(InputError, match="non-finite"):
        simulate_scene(SensorConfig(), np.full((1, 1, 1), np.inf))
    late = np.ones((3, 2, 2), np.float32)                 # values are checked readout by readout
    late[2, 1, 1] = np.nan
    with pytest.raises(InputError, match="non-finite"):
        simulate_scene(SensorConfig(), late)
    with pytest.raises(InputError, match="must be \\(K, H, W\\)"):
        simulate_scene(SensorConfig(), np.ones((2, 2)))
    with pytest.raises(InputError, match="method"):
        simulate_scene(SensorConfig(), np.zeros((1, 1, 1)), method="magic")
    with pytest.raises(InputError, match="noise"):
        simulate_scene(SensorConfig(), np.zeros((1, 1, 1)), noise=False, dark_current="eq12")


@pytest.mark.parametrize("seed", ["abc", -1, 1.5, True, [1, -2], ["a"], []])
def test_a_seed_numpy_would_refuse_in_its_own_words_or_take_as_another_is_refused(seed):
    """Every entry that takes a seed (numpy's SeedSequence TypeError or ValueError named no argument,
    and True was taken as 1); integers >= 0, numpy generators, bit generators and seed sequences go."""
    light = np.full((1, 2, 2), 0.1)
    for call in (lambda: simulate_scene(SensorConfig(), light, seed=seed),
                 lambda: simulate_scene(SensorConfig(), np.full((1, 64, 2048), 0.1), seed=seed, workers=1),
                 lambda: SceneSimulator(SensorConfig(), (2, 2), rng=seed),
                 lambda: poisson_stimulus(SensorConfig(), light, seed)):
        with pytest.raises(InputError, match=f"^seed {re.escape(repr(seed))}: must be an integer >= 0 \\(or a list "
                                             "of them\\), a numpy Generator, SeedSequence or BitGenerator, or None"):
            call()
    for good in (0, np.int64(7), [3, 1], np.random.SeedSequence(3), np.random.SFC64(3), np.random.default_rng(3)):
        assert simulate_scene(SensorConfig(), light, seed=good).shape == (1, 2, 2)


@pytest.mark.parametrize("options, refusal", [
    ({"noise": "no"}, r"^noise 'no': must be True or False"),
    ({"noise": 0}, r"^noise 0: must be True or False"),
    ({"progress": 3}, r"^progress 3: must be None or a function that wraps the readouts' iterable"),
])
def test_a_switch_or_progress_of_the_wrong_kind_is_refused(options, refusal):
    """('no' had been taken as True, a progress of 3 'int object is not callable' after the work began.)"""
    with pytest.raises(InputError, match=refusal):
        simulate_scene(SensorConfig(), np.full((2, 2, 2), 0.1), **options)
    if "noise" in options:
        with pytest.raises(InputError, match=refusal):
            SceneSimulator(SensorConfig(), (2, 2), noise=options["noise"])


@pytest.mark.parametrize("method", ["fast", "per-clock"])
@pytest.mark.parametrize("light,words", [
    (np.full((2, 3), -1e-300), "negative"), (np.full((2, 3), np.nan), "non-finite"),
    (np.full((2, 3), np.inf), "non-finite"), (np.ones((3, 2)), "shape \\(2, 3\\)"),
    (np.ones((2, 3), np.int64), "float array"), (np.ones(6), "shape \\(2, 3\\)"),
])
def test_a_simulators_readout_checks_its_light(method, light, words):
    """The library's one-readout entry refuses bad light in one line (negative light had given
    words of darkness, NaN numpy's 'lam value too large'), changes no state, and names it."""
    sim = SceneSimulator(SensorConfig(), (2, 3), rng=1, method=method)
    with pytest.raises(InputError, match=words) as info:
        sim.readout(light, "frame 7")
    assert str(info.value).startswith("frame 7") and sim.readouts == 0
    if method == "per-clock":
        with pytest.raises(InputError, match=words):
            sim.clock_stimulus(light)
    assert sim.readout(np.full((2, 3), 0.5, np.float32)).shape == (2, 3)


@pytest.mark.parametrize("count", [0, -5, 2.5, True, "10"])
def test_a_simulators_pixel_readout_count_must_be_positive(count):
    """The count the error budget is spread over (a negative one had been taken as one)."""
    with pytest.raises(InputError, match="total_pixel_readouts"):
        SceneSimulator(SensorConfig(), (2, 3), rng=1, total_pixel_readouts=count)


def test_an_empty_scene_gives_no_words_on_every_method():
    for options in ({}, {"method": "per-clock"}, {"noise": False}):
        assert simulate_scene(SensorConfig(), np.zeros((0, 2, 3)), seed=1, **options).shape == (0, 2, 3)


def test_dark_current_matches_cycle_exact_model():
    config = SensorConfig()
    levels = [0.0, 0.005, 0.1]
    scene = np.broadcast_to(np.asarray(levels)[None, :, None], (3, 3, 1500)).copy()
    for model in ("eq12", "eq13"):
        fast = simulate_scene(config, scene, seed=1, dark_current=model)
        exact = simulate(config, poisson_stimulus(config, scene, 2, dark_current=model))
        for i in range(len(levels)):
            a = decode_spikes(fast[:, i], config).mean(axis=0)
            b = decode_spikes(exact[:, i], config).mean(axis=0)
            se = np.sqrt(a.var() / a.size + b.var() / b.size)
            assert abs(a.mean() - b.mean()) < 4 * se + 1e-12, (model, levels[i])


NON_IDEAL = [
    SensorNoise(dark_current="eq12", dark_level=2.5, dsnu=0.4, hot_pixels=0.05, prnu=0.05, comparator_offset=0.05),
    SensorNoise(dark_current="eq13", dsnu=0.2, hot_pixels=0.02, hot_factor=8.0, prnu=0.1),
    SensorNoise(prnu=0.2, comparator_offset=0.1),                       # gain maps, no dark current
]


@pytest.mark.parametrize("config", [SensorConfig(), MSB], ids=str)
@pytest.mark.parametrize("noise", NON_IDEAL, ids=lambda n: n.dark_current or "gain")
def test_sensor_non_idealities_match_cycle_exact_model(config, noise):
    """One sensor (same sensor seed: same per-pixel maps), two noise seeds: the fast
    simulator and the cycle-exact model on the per-clock stimulus agree in law per
    light level (mean decoded value within 4 standard errors, code histogram TVD < 0.05)."""
    levels = [0.0, 0.004, 0.05, 0.3, 1.5]
    pixels = 1200
    scene = np.broadcast_to(np.repeat(levels, pixels)[None, None, :], (3, 1, len(levels) * pixels)).copy()
    sensor = Sensor(noise, seed=4)
    fast = simulate_scene(config, scene, seed=1, sensor=sensor)
    exact = simulate(config, poisson_stimulus(config, scene, 2, sensor=sensor))
    for i, level in enumerate(levels):
        part = slice(i * pixels, (i + 1) * pixels)
        a = decode_spikes(fast[:, 0, part], config).mean(axis=0)
        b = decode_spikes(exact[:, 0, part], config).mean(axis=0)
        se = np.sqrt(a.var() / a.size + b.var() / b.size)
        tvd = 0.5 * np.abs(_histogram(fast[:, 0, part], config) - _histogram(exact[:, 0, part], config)).sum()
        assert abs(a.mean() - b.mean()) <= 4 * se + 1e-12 and tvd < 0.05, (level, a.mean(), b.mean(), se, tvd)


def test_sensor_maps_reach_the_stream():
    """The maps act: a pixel's mean code follows its gain and its dark scale (so a
    simulator that dropped them would fail), and the stripes of a large frame get
    their own rows of the frame's maps."""
    config = SensorConfig(mode="ml")
    sensor = Sensor(SensorNoise(dark_current="eq12", dsnu=0.5, prnu=0.3), seed=9)
    maps = sensor.maps((2, 300))
    dark = decode_spikes(simulate_scene(config, np.zeros((40, 2, 300)), seed=3, sensor=sensor), config)
    flat = decode_spikes(simulate_scene(config, np.full((40, 2, 300), 0.3), seed=3, sensor=sensor), config)
    theta = config.threshold
    assert np.corrcoef(dark.mean(axis=0).ravel(), maps.dark_scale.ravel())[0, 1] > 0.95
    assert np.corrcoef((flat - dark).mean(axis=0).ravel(), maps.gain.ravel())[0, 1] > 0.95
    assert abs(dark.mean() * theta - 400 * maps.dark_scale.mean()) < 0.03 * 400
    rows, sims = stripe_simulators(config, (64, 2048), seed=0, sensor=sensor)
    assert len(rows) > 1
    frame = sensor.maps((64, 2048))
    for r, sim in zip(rows, sims):
        assert np.array_equal(sim.pixels.gain, frame.gain[r].ravel())
        assert np.array_equal(sim.pixels.dark_scale, frame.dark_scale[r].ravel())


@pytest.mark.parametrize("config, per_clock, pixels", [
    (SensorConfig(), [0.7, 0.85, 1.15, 1.3], 3000),
    (SensorConfig(mode="ml"), [0.7, 0.85, 1.15, 1.3], 3000),
    # a small threshold makes backlogs and dips below full common enough that
    # a wrong backlog or dip shows plainly
    (SensorConfig(threshold=5, acc_bits=8), [0.4, 0.5, 1.6, 2.0], 5000),
    (SensorConfig(mode="ml", threshold=5, acc_bits=8), [0.4, 0.5, 1.6, 2.0], 5000),
    (SensorConfig(mode="ml", ml_readout="msb", threshold=5, acc_bits=8), [0.4, 0.5, 1.6, 2.0], 5000),
], ids=str)
def test_carried_accumulator_of_queue_and_full_paths_matches_per_clock(config, per_clock, pixels):
    """The accumulator carried out of the queue path (backlog left at readout)
    and the full path (dips below full near the end) has the per-clock law:
    mean, P(backlog), P(full) within 4 standard errors, histogram TVD < 0.05."""
    theta, acc_max = config.threshold, config.acc_max
    per_clock = np.asarray(per_clock)
    levels = per_clock * theta * config.clocks_per_readout / 42000
    light = np.repeat(levels, pixels)[None, :]
    fast = SceneSimulator(config, light.shape, rng=31)
    full = SceneSimulator(config, light.shape, rng=32, method="per-clock")
    for sim in (fast, full):
        for _ in range(3):
            sim.readout(light)
    assert fast.path_counts["queue"] >= 1.6 * pixels and fast.path_counts["full"] >= pixels, fast.path_counts
    width = max(1, theta // 8)
    bins = np.arange(0, acc_max + width + 1, width)
    for i in range(len(levels)):
        a = fast.acc[i * pixels:(i + 1) * pixels]
        b = full.acc[i * pixels:(i + 1) * pixels]
        se = np.sqrt(a.var() / pixels + b.var() / pixels)
        assert abs(a.mean() - b.mean()) <= 4 * se, (per_clock[i], a.mean(), b.mean())
        for event in (lambda x: x >= theta, lambda x: x == acc_max):
            pa, pb = event(a).mean(), event(b).mean()
            se = np.sqrt((pa * (1 - pa) + pb * (1 - pb)) / pixels)
            assert abs(pa - pb) <= 4 * se + 1e-12, (per_clock[i], pa, pb)
        tvd = 0.5 * np.abs(np.histogram(a, bins)[0] - np.histogram(b, bins)[0]).sum() / pixels
        assert tvd < 0.05, (per_clock[i], tvd)


@pytest.mark.parametrize("model", ["eq12", "eq13"])
def test_per_clock_path_spreads_dark_electrons_like_the_stimulus(model):
    # L = 12, theta = 100, acc_max = 255: ~400 dark electrons per readout are
    # ~33 per clock; bunched into few clocks they would back up, clip and
    # overflow at other clocks, so where they fall shows in the code histogram
    config = SensorConfig(b1=2, b2=2, threshold=100)
    scene = np.full((4, 1, 4000), 0.002)
    fast = simulate_scene(config, scene, seed=7, dark_current=model, method="per-clock")
    exact = simulate(config, poisson_stimulus(config, scene, 8, dark_current=model))
    tvd = 0.5 * np.abs(_histogram(fast, config) - _histogram(exact, config)).sum()
    a = decode_spikes(fast, config).mean(axis=0)
    b = decode_spikes(exact, config).mean(axis=0)
    se = np.sqrt(a.var() / a.size + b.var() / b.size)
    assert abs(a.mean() - b.mean()) < 4 * se and tvd < 0.05, (a.mean(), b.mean(), se, tvd)


def test_lindley_closed_form_equals_the_step_by_step_queue(rng):
    from tespike.golden.fastsim import lindley_ends
    for w in (1, 2, 7, 40):
        x = rng.poisson(rng.uniform(0.2, 1.8, (1, 500)), (w, 500))
        b0 = rng.integers(0, 6, 500)
        b = b0.copy()
        for j in range(w):
            b = np.maximum(b + x[j] - 1, 0)
        ends = lindley_ends(np.cumsum(x - 1, axis=0), b0, np.zeros(500, np.int64))
        assert np.array_equal(ends[0], b), w
        assert np.array_equal(ends[1], np.maximum(np.cumsum(x - 1, axis=0)[-1] - np.minimum(0, np.cumsum(x - 1, axis=0).min(axis=0)), 0)), w


def _msb_path_levels(config):
    """Light per pixel group sending an msb pixel down each path: lazy (dark and
    0.0004 theta per clock), bright, event (0.02 theta per clock), queue (0.7),
    full (1.3), per-clock (1.02)."""
    per_clock = np.array([0.0004, 0.02, 0.7, 1.3, 1.02]) * config.threshold * config.clocks_per_readout / 42000
    return np.concatenate([[0.0, 1e3], per_clock])


@pytest.mark.parametrize("config", [MSB, SensorConfig(mode="ml", ml_readout="msb", ml_bits=5, threshold=30, acc_bits=12)],
                         ids=str)
def test_msb_paths_equal_the_per_clock_path_in_distribution(config):
    """Every path against the full (per-clock) path on msb streams: the words of
    each readout and the counter remainder carried out of it have the same law
    over readouts in which the remainder builds up and drains (light that
    changes: the dark group reads out what earlier light left)."""
    levels = _msb_path_levels(config)
    pixels = 2500
    fast = SceneSimulator(config, (len(levels), pixels), rng=41)
    full = SceneSimulator(config, (len(levels), pixels), rng=42, method="per-clock")
    bins = np.arange(config.ml_max + 2)
    for k in range(8):
        # the first two readouts at 0.75 x the levels, then the levels: remainders
        # left at one light are carried into another; the dark group was lit before
        light = np.broadcast_to(levels[:, None], (len(levels), pixels)) * (0.75 if k < 2 else 1.0)
        if k < 2:
            light = light.copy()
            light[0] = 0.6
        a, b = fast.readout(light), full.readout(light)
        for i in range(len(levels)):
            ha, hb = (np.bincount(w[i], minlength=config.ml_bits + 1) / pixels for w in (a, b))
            assert 0.5 * np.abs(ha - hb).sum() < 0.05, (k, levels[i], ha, hb)
            ra, rb = (np.histogram(s.sfc.reshape(len(levels), pixels)[i], bins)[0] / pixels for s in (fast, full))
            assert 0.5 * np.abs(ra - rb).sum() < 0.05, (k, levels[i])
            da, db = (decode_spikes(w[i], config).astype(float) for w in (a, b))
            se = np.sqrt(da.var() / pixels + db.var() / pixels)
            assert abs(da.mean() - db.mean()) <= 4 * se + 1e-12, (k, levels[i], da.mean(), db.mean())
    for name in ("lazy", "event", "bright", "queue", "full", "clock"):
        assert fast.path_counts[name] > 0, fast.path_counts
    assert full.path_counts["clock"] == 8 * levels.size * pixels


def test_msb_remainder_is_read_out_in_the_dark():
    """After a bright readout leaves a remainder, the dark path drains it one
    msb at a time, as the per-clock path does (deterministic: no light)."""
    config = MSB
    fast = SceneSimulator(config, (1, 4), rng=0)
    full = SceneSimulator(config, (1, 4), rng=1, method="per-clock")
    for sim in (fast, full):
        sim.sfc[:] = [0, 1, 100, 127]
    dark = np.zeros((1, 4))
    seen = []
    for _ in range(8):
        a, b = fast.readout(dark), full.readout(dark)
        assert np.array_equal(a, b) and np.array_equal(fast.sfc, full.sfc)
        seen.append(a[0].tolist())
    assert seen[:3] == [[0, 1, 7, 7], [0, 0, 6, 6], [0, 0, 3, 5]]
    assert seen[-1] == [0, 0, 0, 0] and not fast.sfc.any()
    assert fast.path_counts["lazy"] == 32


@pytest.mark.parametrize("config", [SensorConfig(), SensorConfig(mode="ml"), MSB,
                                    SensorConfig(b1=5, b2=3, acc_bits=12),
                                    SensorConfig(b1=2, b2=4, threshold=40, acc_bits=9),
                                    SensorConfig(mode="ml", ml_readout="msb", ml_bits=5, threshold=30, acc_bits=9)],
                         ids=str)
def test_head_path_matches_per_clock_from_carried_charge(config, monkeypatch):
    """A carried backlog drained under dim light (the rest by the event or the
    queue path) and light above one threshold per clock on a low accumulator
    (charged by the head, the rest by the full path): words, decoded mean and
    the carried accumulator (and msb remainder) have the per-clock law, and the
    rest of the interval takes each of the event, queue and full paths."""
    theta, acc_max, L = config.threshold, config.acc_max, config.clocks_per_readout
    per_clock = np.array([0.0, 0.05, 0.3, 0.6, 0.8, 1.3, 1.6, 2.0])
    levels = per_clock * theta * L / 42000
    pixels = 4000
    light = np.repeat(levels, pixels)[None, :]
    backlog = acc_max - np.arange(light.size) % (acc_max - theta + 1)     # theta .. acc_max
    low = np.arange(light.size) % theta                                    # 0 .. theta - 1
    acc0 = np.where(np.repeat(per_clock, pixels) > 1, low, backlog)
    tails = {}
    for name in ("queue_walk", "full_walk"):
        original = getattr(head, name)

        def spy(sim, sel, w, lam, acc0, clocks, *rest, _name=name, _original=original):
            if clocks < L:
                tails[_name] = tails.get(_name, 0) + sel.size
            return _original(sim, sel, w, lam, acc0, clocks, *rest)
        monkeypatch.setattr(head, name, spy)
    fast = SceneSimulator(config, light.shape, rng=51)
    full = SceneSimulator(config, light.shape, rng=52, method="per-clock")
    for sim in (fast, full):
        sim.acc[:] = acc0
        if config.is_msb:
            sim.sfc[:] = np.arange(light.size) % (1 << (config.ml_bits - 1))
    a, b = fast.readout(light)[0], full.readout(light)[0]
    assert fast.path_counts["head"] >= 3 * pixels, fast.path_counts
    assert fast.path_counts["fallback"] < fast.path_counts["head"] / 2, fast.path_counts
    assert tails.get("queue_walk", 0) > pixels // 2 and tails.get("full_walk", 0) > pixels // 2, tails
    width = max(1, theta // 2)                     # two bins below theta: sampling noise well under 0.05
    bins = np.arange(0, acc_max + width + 1, width)
    for i in range(len(levels)):
        part = slice(i * pixels, (i + 1) * pixels)
        tvd = 0.5 * np.abs(_histogram(a[part], config) - _histogram(b[part], config)).sum()
        da, db = (decode_spikes(w[part], config).astype(float) for w in (a, b))
        se = np.sqrt(da.var() / pixels + db.var() / pixels)
        assert tvd < 0.05 and abs(da.mean() - db.mean()) <= 4 * se + 1e-12, (per_clock[i], tvd, da.mean(), db.mean())
        ca, cb = (s.acc[part].astype(float) for s in (fast, full))
        ha, hb = (np.histogram(x, bins)[0] / pixels for x in (ca, cb))
        assert 0.5 * np.abs(ha - hb).sum() < 0.05, per_clock[i]
        se = np.sqrt(ca.var() / pixels + cb.var() / pixels)
        assert abs(ca.mean() - cb.mean()) <= 4 * se + 1e-12, (per_clock[i], ca.mean(), cb.mean())
        if config.is_msb:
            ra, rb = (np.bincount(msb_index(s.sfc[part]), minlength=config.ml_bits + 1) / pixels
                      for s in (fast, full))
            assert 0.5 * np.abs(ra - rb).sum() < 0.05, per_clock[i]


@pytest.mark.parametrize("config", [SensorConfig(), SensorConfig(mode="ml"), MSB, SensorConfig(b1=1, b2=2),
                                    SensorConfig(b1=3, b2=3, threshold=5, acc_bits=3),
                                    SensorConfig(mode="ml", ml_readout="msb", ml_bits=3, b1=2, b2=2, threshold=5)],
                         ids=str)
def test_lazy_path_matches_per_clock_over_readouts(config):
    """Dim light on the lazy path (a draw only at threshold crossings) over 12
    readouts, with pixel groups that leave it for brighter light and come back
    (a sync draws their charge) and start dark: words of every readout,
    decoded means and the carried charge (read mid-way, a draw for lazy pixels, and at
    the end) have the per-clock law."""
    theta, L = config.threshold, config.clocks_per_readout
    K, pixels = 12, 3000
    lazy_mean = SceneSimulator(config, (6, pixels), total_pixel_readouts=K * 6 * pixels).levels.mean_lazy
    assert lazy_mean > 0                             # the largest interval mean the path takes
    dim = np.array([0.05, 0.3, 0.9]) * lazy_mean / 42000
    bright = 0.25 * theta * L / 42000                # brighter: the lazy pixels leave
    scene = np.zeros((K, 6, pixels))
    scene[:, :3] = dim[None, :, None]                           # steady dim light
    scene[:, 3] = np.where(np.arange(K) % 4 == 2, bright, dim[1])[:, None]   # leaves and returns
    scene[:, 4] = np.where(np.arange(K) < 5, 0.0, dim[2])[:, None]           # dark, then dim
    scene[:, 5] = np.where(np.arange(K) % 3 == 0, dim[0], dim[2])[:, None]   # dim, changing
    fast = SceneSimulator(config, (6, pixels), rng=61, total_pixel_readouts=scene.size)
    full = SceneSimulator(config, (6, pixels), rng=62, method="per-clock")
    width = max(1, theta // 4)
    bins = np.arange(0, config.acc_max + width + 1, width)
    for k in range(K):
        a, b = fast.readout(scene[k]), full.readout(scene[k])
        for g in range(6):
            tvd = 0.5 * np.abs(_histogram(a[g], config) - _histogram(b[g], config)).sum()
            da, db = (decode_spikes(w[g], config).astype(float) for w in (a, b))
            se = np.sqrt(da.var() / pixels + db.var() / pixels)
            assert tvd < 0.05 and abs(da.mean() - db.mean()) <= 4 * se + 1e-12, (k, g, tvd)
        if k in (6, K - 1):                                   # reading acc draws the lazy pixels' charge
            for g in range(6):
                ca, cb = (s.acc.reshape(6, pixels)[g].astype(float) for s in (fast, full))
                ha, hb = (np.histogram(c, bins)[0] / pixels for c in (ca, cb))
                se = np.sqrt(ca.var() / pixels + cb.var() / pixels)
                assert 0.5 * np.abs(ha - hb).sum() < 0.05, (k, g)
                assert abs(ca.mean() - cb.mean()) <= 4 * se + 1e-12, (k, g, ca.mean(), cb.mean())
                if config.is_msb:
                    ra, rb = (np.bincount(msb_index(s.sfc.reshape(6, pixels)[g]), minlength=config.ml_bits + 1)
                              / pixels for s in (fast, full))
                    assert 0.5 * np.abs(ra - rb).sum() < 0.05, (k, g)
    assert fast.path_counts["lazy"] > 0.6 * K * 6 * pixels, fast.path_counts


@pytest.mark.parametrize("readouts", [1, 3])
def test_lazy_sync_draws_the_charge_with_its_law(readouts):
    """The charge a sync draws (Binomial of the electrons before the next
    crossing): a threshold of 12 makes the charge's law sharp enough that one
    electron too many or too few shows in the mean."""
    config = SensorConfig(threshold=12)
    pixels = 20000
    fast = SceneSimulator(config, (1, pixels), rng=71, total_pixel_readouts=readouts * pixels)
    full = SceneSimulator(config, (1, pixels), rng=72, method="per-clock")
    light = np.full((1, pixels), 0.8 * fast.levels.mean_lazy / 42000)
    for _ in range(readouts):
        fast.readout(light), full.readout(light)
    assert fast.path_counts["lazy"] == readouts * pixels
    a, b = fast.acc.astype(float), full.acc.astype(float)
    se = np.sqrt(a.var() / pixels + b.var() / pixels)
    assert abs(a.mean() - b.mean()) <= 4 * se, (a.mean(), b.mean(), se)
    ha, hb = (np.bincount(x.astype(np.int64), minlength=config.threshold) / pixels for x in (a, b))
    assert 0.5 * np.abs(ha - hb).sum() < 0.03


@pytest.mark.parametrize("config", [SensorConfig(), MSB], ids=str)
def test_reading_acc_changes_no_later_word(config):
    """Reading ``acc`` between readouts (lazy pixels' charge drawn on a generator
    of its own) leaves every later word and the carried state as in a run
    without the reads, also for pixels that leave the lazy path afterwards;
    the value read is read-only and lies between the charge at the pixel's
    last sync and theta - 1; assigning ``acc`` still sets the charge."""
    theta = config.threshold
    probe = SceneSimulator(config, (2, 500), total_pixel_readouts=6 * 1000)
    dim = 0.5 * probe.levels.mean_lazy / 42000
    scene = np.full((6, 2, 500), dim)
    scene[3:, 1] = 0.3 * theta * config.clocks_per_readout / 42000     # row 1 leaves the lazy path
    quiet = SceneSimulator(config, (2, 500), rng=81, total_pixel_readouts=scene.size)
    read = SceneSimulator(config, (2, 500), rng=81, total_pixel_readouts=scene.size)
    for k in range(6):
        assert np.array_equal(quiet.readout(scene[k]), read.readout(scene[k])), k
        if k < 3:
            before = read.carried.copy()
            seen = read.acc
            assert read.lazy.mask.any() and not seen.flags.writeable
            assert np.all(seen >= before) and np.all(seen[read.lazy.mask] < theta)
    assert quiet.path_counts == read.path_counts and quiet.path_counts["lazy"] > 0
    assert np.array_equal(quiet.carried, read.carried) and np.array_equal(quiet.sfc, read.sfc)
    read.acc = np.arange(1000) % theta                      # a write: no pixel is lazy any more
    assert np.array_equal(read.acc, np.arange(1000) % theta) and read.acc.flags.writeable


def test_reading_acc_is_a_function_of_the_seed_and_the_readouts_done():
    """Reading ``acc`` has no side effect: a second read before the next readout gives the
    same charges, and so does a twin simulator with the same seed after the same readouts."""
    config = SensorConfig()
    probe = SceneSimulator(config, (2, 500), total_pixel_readouts=6 * 1000)
    scene = np.full((3, 2, 500), 0.5 * probe.levels.mean_lazy / 42000)
    sims = [SceneSimulator(config, (2, 500), rng=81, total_pixel_readouts=scene.size) for _ in range(2)]
    for k in range(2):
        for sim in sims:
            sim.readout(scene[k])
    first = sims[0].acc
    assert sims[0].lazy.mask.any() and not np.array_equal(first, sims[0].carried)   # lazy charges were drawn
    assert np.array_equal(first, sims[0].acc) and np.array_equal(first, sims[1].acc)
    sims[0].readout(scene[2])
    assert sims[0].readouts == 3


@pytest.mark.parametrize("phases", [1, clock.MAX_PHASES])
@pytest.mark.parametrize("config", EDGE_CONFIGS + MSB_EDGE_CONFIGS,
                         ids=str)
def test_walk_equals_the_cycle_exact_model_word_for_word(config, phases, monkeypatch):
    """The per-clock path's shortcut for few pixels (``tespike.golden.fastsim.clock.walk_clocks``:
    the queue of threshold crossings and, past a clip, the firing phase, both in closed
    form) gives the cycle-exact model's words, charges and msb remainders on the same
    electrons, from any carried charge (backlogs included), light around one threshold
    per clock included (where the accumulator clips); pixels it leaves (after
    ``MAX_PHASES`` phases; one phase: every pixel that clipped) are left untouched."""
    monkeypatch.setattr(clock, "MAX_PHASES", phases)
    rng = np.random.default_rng(12)
    L, theta, n = config.clocks_per_readout, config.threshold, 600
    lam = np.exp(rng.uniform(np.log(0.005), np.log(1.5), n)) * theta      # dim .. above a threshold a clock
    lam[:200] = rng.uniform(0.9, 1.15, 200) * theta                        # where charge backs up and clips
    e = np.minimum(rng.poisson(lam[None, :], size=(L, n)), config.input_max).astype(np.int64)
    sim = SceneSimulator(config, (1, n), rng=0)
    sim.carried[:] = rng.integers(0, config.acc_max + 1, n)
    if config.is_msb:
        sim.sfc[:] = rng.integers(0, config.ml_max + 1, n)
    array = PixelArrayModel(config, (1, n))
    array.state.acc[0], array.state.sfc[0] = sim.carried, sim.sfc
    exact = array.feed(e.reshape(L, 1, n))[0, 0]
    words = np.full(n, -1, np.int64)
    settled = clock.walk_clocks(sim, np.arange(n), e, words)
    if phases > 1:
        assert settled.all()
    else:
        assert settled.sum() > 0.2 * n
        if config.input_max > 2 * config.threshold and L >= 8:   # some clip before the last clock
            assert not settled.all()
    assert np.array_equal(words[settled], exact[settled])
    assert np.array_equal(sim.carried[settled], array.state.acc[0][settled])
    assert np.array_equal(sim.sfc[settled], array.state.sfc[0][settled])
    assert (words[~settled] == -1).all()                  # the others are left untouched


def test_walk_goes_on_past_max_phases_where_the_model_would_cost_more(monkeypatch):
    """At 61440 clocks a pixel at one threshold a clock alternates queue and firing tens of times: it
    was left to the cycle-exact model after MAX_PHASES phases (at 7.9 million clocks, a minute a
    pixel-readout against 6 s walked). The walk goes on while its phases cost less than the model's
    steps would (``clock.walk_on``), and gives the model's words and charges; at 240 clocks it stops
    at MAX_PHASES as before."""
    config = SensorConfig(mode="te", clocks_per_tick=4096, threshold=100, acc_bits=8)
    L, n = config.clocks_per_readout, 1
    phases = []
    walk_on = clock.walk_on
    monkeypatch.setattr(clock, "walk_on", lambda phase, *rest: phases.append(phase) or walk_on(phase, *rest))
    e = np.random.default_rng(0).poisson(99.0, (L, n)).astype(np.int64)
    sim = SceneSimulator(config, (1, n), rng=0)
    words = np.full(n, -1, np.int64)
    settled = clock.walk_clocks(sim, np.arange(n), e, words)
    array = PixelArrayModel(config, (1, n))
    exact = array.feed(e.reshape(L, 1, n))[0, 0]
    assert settled.all() and max(phases) > clock.MAX_PHASES
    assert np.array_equal(words, exact) and np.array_equal(sim.carried, array.state.acc[0])
    assert not clock.walk_on(clock.MAX_PHASES, 1, 240) and clock.walk_on(clock.MAX_PHASES - 1, 10 ** 6, 240)


@pytest.mark.parametrize("config", EDGE_CONFIGS + MSB_EDGE_CONFIGS, ids=str)
def test_head_state_equals_the_cycle_exact_model(config):
    """The head's first clocks (``tespike.golden.fastsim.head.run_head``: the walk, the
    cycle-exact model where it leaves a pixel) end in the cycle-exact model's state
    (charge, counter, TE overflow flag and latched tick) on the same electrons."""
    rng = np.random.default_rng(3)
    theta, n, L = config.threshold, 500, config.clocks_per_readout
    for h in sorted({min(8, L // 2), L // 2} - {0}):
        lam = np.exp(rng.uniform(np.log(0.005), np.log(1.5), n)) * theta
        e = np.minimum(rng.poisson(lam[None, :], size=(h, n)), config.input_max).astype(np.int64)
        acc0 = rng.integers(0, config.acc_max + 1, n)
        sfc0 = rng.integers(0, config.ml_max + 1, n) if config.is_msb else np.zeros(n, np.int64)
        state = head.run_head(config, acc0, sfc0, e)
        array = PixelArrayModel(config, (1, n))
        array.state.acc[0], array.state.sfc[0] = acc0, sfc0
        array.feed(e.reshape(h, 1, n))
        assert state.clock == array.state.clock == h
        for name in ("acc", "sfc", "ovf", "m"):
            assert np.array_equal(getattr(state, name), getattr(array.state, name)), (h, name)


def test_window_groups_cover_each_pixel_once_at_a_length_it_allows():
    """``tespike.golden.fastsim.window.groups``: every pixel in exactly one block, run at a
    length at least its own (a longer window is as exact), neighbouring lengths merged
    only while the draws a block adds stay within MERGE_DRAWS."""
    from tespike.golden.fastsim import window
    rng = np.random.default_rng(4)
    for n in (5, 256, 3000, 40000):
        size = window.round_window(rng.uniform(1, 120, n) ** rng.uniform(0.5, 1.0, n))
        sel = rng.permutation(10 * n)[:n]
        blocks = window.groups(sel, size)
        got = np.concatenate([pixels for _, pixels in blocks])
        assert np.array_equal(np.sort(got), np.sort(sel))
        where = {p: i for i, p in enumerate(sel)}
        for length, pixels in blocks:
            own = size[[where[p] for p in pixels]]
            assert (own <= length).all()
            if n > window.SMALL_GROUP and np.unique(own).size > 1:
                assert (length - own).sum() <= window.MERGE_DRAWS
        if n > window.SMALL_GROUP:
            assert len(blocks) < np.unique(size).size or n >= 40000


def test_clock_draws_take_tables_only_where_they_pay():
    """Per-clock draws use the table sampler only with TABLE_DRAWS draws per distinct
    integer mean; a call of a few hundred pixels with as many means (a wide-range
    scene's windows) is numpy's own draws, bit for bit, and builds no table."""
    config = SensorConfig.preset("te")
    spread = np.random.default_rng(0).uniform(70.0, 160.0, 600)    # ~90 means, 8 clocks each
    sim = SceneSimulator(config, (1, spread.size), rng=3)
    assert not clock.tabled_call(spread, 8)
    got = clock.clock_draws(sim, spread, 8)
    assert np.array_equal(got, np.random.default_rng(3).poisson(spread[None, :], size=(8, spread.size)))
    assert sim.sampler is None
    few = np.repeat([70.5, 71.5], 300)                              # two means, 8 x 300 draws each
    assert clock.tabled_call(few, 8) and not clock.tabled_call(few[:2], 8)
    drawn = clock.clock_draws(sim, few, 8)
    assert sim.sampler is not None and drawn.shape == (8, few.size)
    assert abs(drawn.mean() - 71.0) < 4 * np.sqrt(71.0 / drawn.size)


@pytest.mark.parametrize("config", EDGE_CONFIGS + MSB_EDGE_CONFIGS, ids=str)
def test_walk_from_a_head_state_equals_the_cycle_exact_model(config):
    """The per-clock path from a state part-way through the interval (after a head:
    ``run_clocks(..., start)``, which walks few pixels) gives the cycle-exact model's
    words, charges and msb remainders on the same electrons: counters part-full, TE
    overflows latched in the head or reached in the rest, backlogs and clipping."""
    rng = np.random.default_rng(21)
    theta, n, L = config.threshold, 400, config.clocks_per_readout
    for h in sorted({min(8, L // 2), L // 2} - {0}):
        lam = np.exp(rng.uniform(np.log(0.005), np.log(1.5), n)) * theta
        lam[:150] = rng.uniform(0.9, 1.15, 150) * theta                 # backlogs, clipping
        e = np.minimum(rng.poisson(lam[None, :], size=(L, n)), config.input_max).astype(np.int64)
        acc0 = rng.integers(0, config.acc_max + 1, n)
        sfc0 = rng.integers(0, config.ml_max + 1, n) if config.is_msb else np.zeros(n, np.int64)
        array = PixelArrayModel(config, (1, n))
        array.state.acc[0], array.state.sfc[0] = acc0, sfc0
        array.feed(e[:h].reshape(h, 1, n))
        start = array.state.copy()
        exact = array.feed(e[h:].reshape(L - h, 1, n))[0, 0]
        sim = SceneSimulator(config, (1, n), rng=0)
        sim.carried[:], sim.sfc[:] = acc0, sfc0
        words = np.full(n, -1, np.int64)
        clock.run_clocks(sim, np.arange(n), e[h:], words, start)
        assert np.array_equal(words, exact), h
        assert np.array_equal(sim.carried, array.state.acc[0])
        if config.is_msb:
            assert np.array_equal(sim.sfc, array.state.sfc[0])
        if config.is_te:                                                # both overflow cases met
            over = (words >> config.d) == 1
            assert start.ovf[0].any() == (config.p_max <= h)
            assert (over & ~start.ovf[0]).any() == (config.p_max <= L)


@pytest.mark.parametrize("config", [c for c in EDGE_CONFIGS if c.is_te], ids=str)
def test_sure_te_overflow_on_the_event_path_matches_per_clock(config):
    """Light on the event path that surely overflows a TE pixel (``mean_overflow`` and
    up, where the overflow electron's light-time is drawn first, then the electrons
    after it): words (the overflow tick's law), decoded mean and the carried residual
    have the per-clock law over readouts, from the carried charges they leave; just
    below the level (the Beta draw) too, and in one pixel and one readout."""
    L, theta = config.clocks_per_readout, config.threshold
    probe = SceneSimulator(config, (1, 1), rng=0, total_pixel_readouts=3 * 6000)
    low, high = probe.levels.mean_overflow, probe.levels.mean_event * L
    if not low < high:
        pytest.skip("no light both on the event path and surely overflowing")
    means = np.array([low, np.sqrt(low * high), high, 0.8 * low])      # the last: below the level
    pixels = 1500
    light = np.repeat(means / 42000, pixels)[None, :]
    fast = SceneSimulator(config, light.shape, rng=61, total_pixel_readouts=3 * light.size)
    full = SceneSimulator(config, light.shape, rng=62, method="per-clock", total_pixel_readouts=3 * light.size)
    a, b = [], []
    for _ in range(3):
        a.append(fast.readout(light)[0])
        b.append(full.readout(light)[0])
    assert fast.path_counts["event"] == 3 * light.size, fast.path_counts
    a, b = np.array(a), np.array(b)
    for i in range(len(means)):
        part = slice(i * pixels, (i + 1) * pixels)
        if i < 3:
            assert ((a[:, part] >> config.d) == 1).all()                # overflowed, all of them
        tvd = 0.5 * np.abs(_histogram(a[:, part], config) - _histogram(b[:, part], config)).sum()
        da, db = (decode_spikes(w[:, part], config).mean(axis=0) for w in (a, b))
        se = np.sqrt(da.var() / pixels + db.var() / pixels)
        assert tvd < 0.05 and abs(da.mean() - db.mean()) <= 4 * se + 1e-12, (means[i], tvd, da.mean(), db.mean())
        ha, hb = (np.bincount(s.acc[part], minlength=theta) / pixels for s in (fast, full))
        width = max(1, theta // 8)
        ha, hb = (np.add.reduceat(h, np.arange(0, theta, width)) for h in (ha, hb))
        assert 0.5 * np.abs(ha - hb).sum() < 0.05, means[i]
    one = SceneSimulator(config, (1, 1), rng=3)
    word = one.readout(np.array([[means[0] / 42000]]))[0, 0]
    assert (word >> config.d) == 1 and 0 <= one.acc[0] < theta


def test_sure_te_overflow_puts_the_overflow_electron_first(monkeypatch):
    """The arithmetic of the sure-overflow draw on given random numbers: the overflow
    electron (``2^b1 theta - acc`` after the sync) at light-time G is in clock
    ``floor(L G / expected)``, and the charge left is that of ``2^b1 theta`` plus the
    electrons drawn after it."""
    from tespike.golden.fastsim import interval
    monkeypatch.setattr(interval, "poisson_draws", lambda rng, mean: rng.poisson(mean))

    class Given:                                   # a generator that returns chosen numbers
        def __init__(self):
            self.calls = []

        def standard_gamma(self, shape):
            self.calls.append("gamma")
            return 0.25 * shape + 0.5

        def poisson(self, mean):
            self.calls.append("poisson")
            return np.floor(mean).astype(np.int64)

    config = SensorConfig()
    theta, L, F = config.threshold, config.clocks_per_readout, config.clocks_per_tick
    sim = SceneSimulator(config, (1, 3), rng=0)
    mean = np.full(3, 1.1 * sim.levels.mean_overflow)
    sim.carried[:] = [0, 17, theta - 1]
    sim.rng = Given()
    words = np.zeros(3, np.int64)
    interval.event_path(sim, slice(None), mean, np.zeros(3, np.int64), words)
    need = config.p_max * theta - np.array([0, 17, theta - 1])
    g = 0.25 * need + 0.5
    after = np.floor(mean - g).astype(np.int64)
    assert sim.rng.calls == ["gamma", "poisson"]
    assert np.array_equal(words, (1 << config.d) | ((g / mean * L).astype(np.int64) // F + 1))
    assert np.array_equal(sim.carried, after % theta)


def test_queue_draws_a_te_pixels_first_crossings_first():
    """The arithmetic of the TE queue path's crossings on given random numbers: where
    the 2^b1 = p crossings surely come before the window, crossing p comes at
    light-time ``T = G(p theta - acc)``, in clock ``c_p = floor(T / lam)``, and the rest
    holds the crossings' electrons plus those drawn from the light left after it.
    Spike p fires within ``b_max`` clocks of ``c_p``: where those lie in one tick,
    ``c_p`` is a clock of the word's tick and nothing more is drawn; elsewhere the
    earlier crossings come at ``T`` times the shares of the gaps ``G_1`` (shape ``theta -
    acc``), ``G_2..G_p`` (shape ``theta``), and spike p at ``max_i (c_i + p - i)``."""
    from tespike.golden.fastsim import window

    class Given:                                   # a generator that returns chosen numbers
        def __init__(self):
            self.calls = []

        def standard_gamma(self, shape, size=None, out=None):
            self.calls.append("gamma")
            value = np.broadcast_to(0.9 * np.asarray(shape, np.float64) + 3.0, size or np.shape(shape))
            if out is None:
                return value.copy()
            out[...] = value
            return out

        def poisson(self, mean, size=None):
            self.calls.append("poisson")
            return np.broadcast_to(np.floor(mean).astype(np.int64), size or np.shape(mean)).copy()

    def drawn_way(acc0, lam, p, last):
        gaps = np.cumsum([0.9 * (theta - acc0) + 3.0] + [0.9 * theta + 3.0] * (p - 1))
        cross = np.floor(gaps * (last / gaps[-1]) / lam).astype(np.int64)
        return (cross - np.arange(1, p + 1)).max() + p

    config = SensorConfig()
    theta, L, p, per_tick = config.threshold, config.clocks_per_readout, config.p_max, config.clocks_per_tick
    sim = SceneSimulator(config, (1, 3), rng=0)
    lam = np.array([0.4, 0.6, 0.85]) * theta                          # per clock, all queue light
    acc0 = np.array([0, 17, theta - 1])
    w = 8
    last = 0.9 * (p * theta - acc0) + 3.0
    c_p = np.floor(last / lam).astype(np.int64)
    sim.rng = Given()
    ok, spikes, end, at, drawn, rest = window.queue_walk(sim, np.arange(3), w, lam, acc0, L,
                                                         np.full(3, p), np.zeros(3))
    assert sim.rng.calls == ["poisson", "gamma", "poisson"]           # window, crossing p, rest
    assert np.array_equal(at, c_p)                                      # no backlog: one tick surely
    assert np.array_equal(rest, p * theta - acc0 + np.floor(lam * (L - w) - last).astype(np.int64))
    assert np.array_equal(drawn, np.broadcast_to(np.floor(lam).astype(np.int64), (w, 3)))
    assert ok.all() and (spikes >= p).all()
    # a backlog bound as long as a tick: every crossing drawn, given T
    sim.rng = Given()
    at, reached, light_time = window.first_crossings(sim, lam, acc0, np.full(3, p), L - w, np.full(3, per_tick))
    assert sim.rng.calls == ["gamma", "gamma", "gamma"] and reached.all() and np.array_equal(light_time, last)
    assert np.array_equal(at, [drawn_way(acc0[j], lam[j], p, last[j]) for j in range(3)])
    # bunched crossings (the later gaps tiny): spike p waits behind the others; the
    # recursion s_j = max(c_j, s_(j-1) + 1) on the crossings drawn given T
    sim.rng = Given()
    bunched = sim.rng.standard_gamma

    def tiny(shape, size=None, out=None):
        value = bunched(shape, size, out)
        if size is not None:                               # the later gaps: one scalar shape
            value[...] = 0.01 * theta
        return value
    sim.rng.standard_gamma = tiny
    at, _, _ = window.first_crossings(sim, lam, acc0, np.full(3, p), L - w, np.full(3, per_tick))
    for j in range(3):
        gaps = np.cumsum([0.9 * (theta - acc0[j]) + 3.0] + [0.01 * theta] * (p - 1))
        cross = np.floor(gaps * (last[j] / gaps[-1]) / lam[j]).astype(np.int64)
        fired = cross[0]
        for c_j in cross[1:]:
            fired = max(c_j, fired + 1)
        assert at[j] == fired and fired > cross[-1], j
    # the tick decides, from the head's offset: c_p 2 clocks before a tick's end with b_max 1
    # is sure; with b_max 2, or 1 clock later (an offset of 1), it is drawn
    j = 0
    for b_max, offset, drawn_again in ((1, per_tick - 2 - c_p[j] % per_tick, False),
                                       (2, per_tick - 2 - c_p[j] % per_tick, True),
                                       (1, per_tick - 1 - c_p[j] % per_tick, True)):
        sim.rng = Given()
        at, _, _ = window.first_crossings(sim, lam[:1], acc0[:1], np.full(1, p), L - w, np.full(1, b_max), offset)
        assert (sim.rng.calls.count("gamma") > 1) == drawn_again, (b_max, offset)
        assert at[0] == (drawn_way(acc0[j], lam[j], p, last[j]) if drawn_again else c_p[j])
    # a head's rest (fewer clocks, spikes still needed per pixel): each pixel its own count
    rest_clocks, need = L - 40, np.array([3, 1, 3])
    sim.rng = Given()
    _, _, _, at, _, rest = window.queue_walk(sim, np.arange(3), w, lam, acc0, rest_clocks, need, np.zeros(3))
    for j in range(3):
        last = 0.9 * (need[j] * theta - acc0[j]) + 3.0
        assert at[j] == np.floor(last / lam[j]), j
        assert rest[j] == need[j] * theta - acc0[j] + np.floor(lam[j] * (rest_clocks - w) - last), j


class _ByClock:
    """A generator that returns chosen numbers: a per-clock electron count that depends
    on the mean and on the clock's distance from the window's end (so a window padded
    at its start gets the numbers of the same window drawn alone), the floor of a total's
    mean, and ``0.9 shape + 3`` for a Gamma draw."""

    def poisson(self, mean, size=None):
        mean = np.broadcast_to(np.asarray(mean, np.float64), size or np.shape(mean))
        if mean.ndim < 2:
            return np.floor(mean).astype(np.int64)
        from_end = np.arange(mean.shape[0])[::-1, None]
        return np.floor(mean * (0.55 + 0.3 * ((7 * from_end) % 5))).astype(np.int64)

    def standard_gamma(self, shape, size=None, out=None):
        value = np.broadcast_to(0.9 * np.asarray(shape, np.float64) + 3.0, size or np.shape(shape))
        if out is None:
            return value.copy()
        out[...] = value
        return out

    def multinomial(self, n, p):
        raise AssertionError("no fallback expected")


@pytest.mark.parametrize("config", [SensorConfig(), SensorConfig(mode="ml"), MSB], ids=str)
def test_padded_windows_give_each_pixel_its_own_windows_outcome(config):
    """Queue and full windows of several lengths run as one block padded at its start
    (``tespike.golden.fastsim.window.window_rows``): on the same numbers, each pixel's
    outcome (settled or not, spikes, end charge, TE overflow clock, its electrons and
    rest total) is that of its own window drawn alone, from the interval's start and
    from a head's rest alike."""
    from tespike.golden.fastsim import window
    theta, L = config.threshold, config.clocks_per_readout
    sim = SceneSimulator(config, (1, 12), rng=0)
    sim.rng = _ByClock()
    rho = np.array([0.35, 0.5, 0.62, 0.7, 0.78, 0.85, 0.9, 0.45, 0.55, 0.66, 0.8, 0.88])
    lam, acc0 = rho * theta, np.array([0, 5, 40, 90, theta - 1, 17, 0, 60, 130, 3, 100, 150])
    keep, bound, length = window.queue_plan(sim.levels, rho)
    own = window.round_window(length).astype(np.int64)
    w = int(own.max())
    assert keep.all() and own.min() < w and np.unique(own).size > 3
    for clocks, offset, need in ((L, 0, np.full(12, config.p_max)), (L - 40, 40, np.arange(12) % 4 + 1)):
        padded = window.queue_walk(sim, np.arange(12), w, lam, acc0, clocks, need, bound, offset, own)
        for j in range(12):
            alone = window.queue_walk(sim, np.array([j]), int(own[j]), lam, acc0[j:j + 1], clocks,
                                      need[j:j + 1], bound[j:j + 1], offset)
            for name, a, b in zip(("ok", "spikes", "end", "at"), padded[:4], alone[:4]):
                assert a[j] == b[0], (name, j, offset)
            assert np.array_equal(padded[4][w - own[j]:, j], alone[4][:, 0]) and padded[4][:w - own[j], j].sum() == 0
            assert padded[5][j] == alone[5][0]
    lam_full = np.array([1.15, 1.3, 1.6, 2.0, 2.5, 1.2]) * theta
    acc_full = np.array([config.acc_max, 300, 200, 120, 80, 400]) % (config.acc_max + 1)
    keep, length = window.full_plan(sim.levels, lam_full, acc_full)
    own = window.round_window(length).astype(np.int64)
    w = int(own.max())
    assert own.min() < w
    padded = window.full_walk(sim, np.arange(6), w, lam_full, acc_full, L, own)
    for j in range(6):
        alone = window.full_walk(sim, np.array([j]), int(own[j]), lam_full, acc_full[j:j + 1], L)
        assert padded[0][j] == alone[0][0] and padded[1][j] == alone[1][0], j
        assert np.array_equal(padded[2][w - own[j]:, j], alone[2][:, 0]) and padded[3][j] == alone[3][0]


def test_padded_windows_that_do_not_settle_go_per_clock_with_their_own_clocks(monkeypatch):
    """Full windows of several lengths padded into one block whose outcome is not
    settled go per clock (``tespike.golden.fastsim.clock.fallback``, one call per window
    length) on each pixel's own window and rest: with every full window made to fail,
    the words and carried charge keep the cycle-exact model's law."""
    from tespike.golden.fastsim import window
    config = SensorConfig(mode="ml")
    theta, L = config.threshold, config.clocks_per_readout
    real, seen = window.full_walk, []

    def unsettled(sim, sel, w, lam, acc0, clocks, own=None):
        ok, end, drawn, rest = real(sim, sel, w, lam, acc0, clocks, own)
        seen.append(own is not None and own.min() < w)
        return np.zeros_like(ok), end, drawn, rest
    monkeypatch.setattr(window, "full_walk", unsettled)
    levels = np.array([1.15, 1.3, 1.6, 2.0, 2.5]) * theta * L / 42000
    readouts, pixels = 60, 50                           # a block of at most SMALL_GROUP pixels: one, padded
    scene = np.broadcast_to(levels[None, :, None], (readouts, levels.size, pixels)).copy()
    sim = SceneSimulator(config, scene.shape[1:], rng=5)
    fast = np.stack([sim.readout(scene[k]) for k in range(readouts)])
    assert any(seen) and sim.path_counts["fallback"] >= sim.path_counts["full"] > 0
    exact = simulate(config, poisson_stimulus(config, scene, 6))
    for i in range(levels.size):
        a, b = fast[:, i].astype(np.float64), exact[:, i].astype(np.float64)
        z = (a.mean() - b.mean()) / np.sqrt(a.var() / a.size + b.var() / b.size + 1e-24)
        tvd = 0.5 * np.abs(_histogram(fast[:, i], config) - _histogram(exact[:, i], config)).sum()
        assert abs(z) < 4 and tvd < 0.05, (i, z, tvd)


def test_distinct_values_equal_numpys_unique():
    """``tespike.golden.fastsim.distinct``: the sorted distinct values and their counts,
    as ``np.unique`` gives them (which the simulator avoids: its first call imports
    numpy.ma in every worker process)."""
    from tespike.golden.fastsim.distinct import distinct, distinct_counts
    rng = np.random.default_rng(8)
    for values in (rng.integers(0, 9, 500), rng.uniform(0, 1, 7), np.zeros(0, np.int64), np.full(3, 4.0),
                   rng.integers(0, 3, (4, 5))):
        want, counts = np.unique(values, return_counts=True)
        got, got_counts = distinct_counts(values)
        assert np.array_equal(got, want) and np.array_equal(got_counts, counts)
        assert np.array_equal(distinct(values), want)


def test_a_simulation_does_not_import_numpy_ma(tmp_path):
    """A scene through every path (window blocks of many lengths, heads with
    different needs, table and numpy draws) and its stream written as ``tespike simulate``
    writes it never import numpy.ma, which costs a forked worker 10-40 ms of CPU and the
    command 7 ms (``np.unique``'s first call imports it; ``np.setdiff1d`` in the words'
    check of ``save_stream`` did)."""
    import subprocess
    import sys
    code = ("import sys, numpy as np\n"
            "from tespike.golden.config import SensorConfig\n"
            "from tespike.golden.fastsim import simulate_scene\n"
            "from tespike.golden.io import save_stream\n"
            "rng = np.random.default_rng(0)\n"
            "scene = 10.0 ** rng.uniform(-4, 1, (2, 64, 320))\n"
            "for mode in ('te', 'ml', 'ml-msb'):\n"
            "    config = SensorConfig.preset(mode)\n"
            f"    save_stream({str(tmp_path)!r} + f'/{{mode}}.npz', simulate_scene(config, scene, seed=1), config)\n"
            "print('numpy.ma' in sys.modules)\n")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert run.stdout.strip() == "False", run.stdout + run.stderr


@pytest.mark.parametrize("config", [SensorConfig(), SensorConfig(mode="ml"), MSB,
                                    SensorConfig(b1=1, threshold=1400, acc_bits=12, clocks_per_tick=2)],
                         ids=str)
# the larger frame: its masked call passes PTRS_DRAWS means with the zeros, the gathered one not
@pytest.mark.parametrize("shape, event_columns", [((40, 50), 35), ((100, 100), 75)],
                         ids=["small", "frame-past-PTRS_DRAWS"])
def test_event_path_under_a_mask_equals_the_gathered_path(config, shape, event_columns, monkeypatch):
    """The event path run on the whole frame under a mask (where it holds most pixels)
    gives the gathered path's words, charges and msb remainders bit for bit, from the
    same generator state: the other pixels' means are 0, which draw nothing. The frame
    mixes event light (some surely overflowing) with lazy, bright and near-threshold
    pixels whose charge alone may pass an overflow's (2^b1 = 2 in the last config)."""
    from tespike.golden.fastsim import interval
    rng = np.random.default_rng(5)
    light = 10.0 ** rng.uniform(-3, 0.5, (6, *shape))
    light[:, :, :event_columns] = rng.uniform(0.02, 0.3, (6, shape[0], event_columns))   # most of it: event light

    def run(share):
        monkeypatch.setattr(interval, "EVENT_MASK_SHARE", share)
        sim = SceneSimulator(config, light.shape[1:], rng=11)
        words = [sim.readout(frame) for frame in light]
        return np.array(words), sim.carried.copy(), None if sim.sfc is None else sim.sfc.copy(), sim.path_counts

    masked, gathered = run(2), run(0)                                  # share 0: never a mask
    assert masked[3]["event"] > light.size // 2 and masked[3] == gathered[3]
    for a, b in zip(masked[:3], gathered[:3]):
        assert (a is None and b is None) or np.array_equal(a, b)


@pytest.mark.parametrize("config, per_clock, pixels", [
    (SensorConfig(), [0.5, 0.7, 0.8], 3000),
    (SensorConfig(clocks_per_tick=4), [0.5, 0.7, 0.8], 3000),
    (SensorConfig(clocks_per_tick=4, threshold=40, acc_bits=8), [0.5, 0.7, 0.8], 3000),
    # a tick of one clock: the word is the spike's clock; a mean wait of 0.09 clock
    (SensorConfig(b2=8, alpha=240, clocks_per_tick=1, threshold=10, acc_bits=8), [0.8], 20000),
], ids=str)
def test_queue_overflow_tick_matches_per_clock_near_tick_ends(config, per_clock, pixels, monkeypatch):
    """TE queue light that surely overflows: the overflow word's tick has the
    per-clock law, both where crossing 2^b1's clock settles it and where a backlog
    may carry the spike into the next tick (the earlier crossings then drawn given
    the last's light-time); short ticks make the second case common, and with a tick
    of one clock and a low threshold the word is the spike's clock, queueing included."""
    from tespike.golden.fastsim import window
    calls = {"pixels": 0, "drawn": 0}
    original = window.first_crossings

    def spy(sim, lam, acc0, need, span, b_max, offset=0):
        out = original(sim, lam, acc0, need, span, b_max, offset)
        calls["pixels"] += lam.size
        calls["drawn"] += int(np.count_nonzero(out[1] & (need > 1)
                                               & ((offset + np.minimum((out[2] / lam).astype(np.int64), span - 1))
                                                  % config.clocks_per_tick + b_max >= config.clocks_per_tick)))
        return out

    monkeypatch.setattr(window, "first_crossings", spy)
    theta, L = config.threshold, config.clocks_per_readout
    per_clock = np.asarray(per_clock)
    light = np.repeat(per_clock * theta * L / 42000, pixels)[None, :]
    fast = SceneSimulator(config, light.shape, rng=71)
    full = SceneSimulator(config, light.shape, rng=72, method="per-clock")
    a = np.array([fast.readout(light)[0] for _ in range(3)])
    b = np.array([full.readout(light)[0] for _ in range(3)])
    assert fast.path_counts["queue"] >= 0.9 * a.size and calls["pixels"] >= 0.9 * a.size, fast.path_counts
    assert calls["drawn"] > 0.02 * a.size, calls
    for i in range(len(per_clock)):
        part = slice(i * pixels, (i + 1) * pixels)
        wa, wb = a[:, part], b[:, part]
        assert ((wa >> config.d) == 1).all() and ((wb >> config.d) == 1).all()
        ta, tb = (w & ((1 << config.d) - 1) for w in (wa, wb))
        se = np.sqrt(ta.var() / ta.size + tb.var() / tb.size)
        tvd = 0.5 * np.abs(_histogram(wa, config) - _histogram(wb, config)).sum()
        assert abs(ta.mean() - tb.mean()) <= 4 * se and tvd < 0.05, (per_clock[i], ta.mean(), tb.mean(), tvd)


@pytest.mark.parametrize("config", [SensorConfig(), SensorConfig(mode="ml"), MSB,
                                    SensorConfig(b1=1, b2=4, threshold=100, acc_bits=8)], ids=str)
def test_lazy_pixels_crossing_out_into_brighter_light_match_per_clock(config, monkeypatch):
    """Lazy pixels whose light steps up past the path's level leave it at their next crossing
    (:func:`tespike.golden.fastsim.lazy.cross_out`: the crossing's spike, then the event
    path's arithmetic on the electrons after it, TE overflows at their clock; or, where the
    crossing lies past the interval, no spike and the charge drawn at its end): the words of
    the step and of the readout after it, and the charge carried, have the per-clock law,
    for steps to just above the lazy level, to a few thresholds and to overflowing light."""
    from tespike.golden.fastsim import lazy
    settled = []
    cross_out = lazy.cross_out

    def counted(sim, leave, *rest):
        left, done = cross_out(sim, leave, *rest)
        settled.append(done.size)
        return left, done

    monkeypatch.setattr(lazy, "cross_out", counted)
    theta, L = config.threshold, config.clocks_per_readout
    pixels = 8000
    probe = SceneSimulator(config, (1, 1), total_pixel_readouts=4 * 3 * pixels)
    lazy_mean, event_mean = probe.levels.mean_lazy, probe.levels.mean_event * L
    steps = np.array([1.3 * lazy_mean, min(6 * theta, 0.9 * event_mean), 0.9 * event_mean]) / 42000
    scene = np.zeros((4, 3, pixels))
    scene[:2] = 0.6 * lazy_mean / 42000                           # lazy first
    scene[2:] = steps[None, :, None]
    fast = SceneSimulator(config, (3, pixels), rng=81, total_pixel_readouts=scene.size)
    full = SceneSimulator(config, (3, pixels), rng=82, method="per-clock")
    for k in range(4):
        a, b = fast.readout(scene[k]), full.readout(scene[k])
        if k < 2:
            continue
        for g in range(3):
            tvd = 0.5 * np.abs(_histogram(a[g], config) - _histogram(b[g], config)).sum()
            da, db = (decode_spikes(w[g], config).astype(float) for w in (a, b))
            se = np.sqrt(da.var() / pixels + db.var() / pixels)
            assert tvd < 0.04 and abs(da.mean() - db.mean()) <= 4 * se + 1e-12, (k, g, tvd)
            ca, cb = (s.acc.reshape(3, pixels)[g].astype(float) for s in (fast, full))
            se = np.sqrt(ca.var() / pixels + cb.var() / pixels)
            assert abs(ca.mean() - cb.mean()) <= 4 * se + 1e-12, (k, g, ca.mean(), cb.mean())
    assert sum(settled) > 2 * pixels                   # most of the lazy pixels crossed out


@pytest.mark.parametrize("config", [SensorConfig(b1=1, b2=4), SensorConfig(b1=1, b2=1)], ids=str)
def test_lazy_pixels_whose_crossing_lies_past_a_brighter_interval_match_per_clock(config):
    """Pixels that enter the lazy path in the dark (their crossing a whole ``Gamma(theta)`` away) and
    leave it for light of about one threshold an interval: where the lazy level is below a threshold
    (2^b1 = 2: its overflow bound) half of the crossings lie past the interval. Those pixels were
    synced at the interval's start and their electrons drawn afresh: a spike in 76 % of the pixels
    where the law gives 50 % (2^b1 = 2, the paper's threshold)."""
    theta = config.threshold
    pixels = 20000
    probe = SceneSimulator(config, (1, 1), total_pixel_readouts=3 * pixels)
    step = theta
    assert probe.levels.mean_lazy < step <= probe.levels.mean_event * config.clocks_per_readout
    scene = np.zeros((3, 1, pixels))
    scene[1:] = step / 42000
    fast = SceneSimulator(config, (1, pixels), rng=91, total_pixel_readouts=scene.size)
    full = SceneSimulator(config, (1, pixels), rng=92, method="per-clock")
    for k in range(3):
        a, b = fast.readout(scene[k]), full.readout(scene[k])
        da, db = (decode_spikes(w, config).astype(float) for w in (a, b))
        ca, cb = (np.asarray(s.acc, float) for s in (fast, full))
        for x, y in ((da, db), (ca, cb), (a > 0, b > 0)):
            se = np.sqrt(x.var() / pixels + y.var() / pixels)
            assert abs(x.mean() - y.mean()) <= 4.5 * se + 1e-12, (k, x.mean(), y.mean())
        assert 0.5 * np.abs(_histogram(a, config) - _histogram(b, config)).sum() < 0.03
    assert fast.path_counts["lazy"] > pixels


@pytest.mark.parametrize("mode", ["te", "ml", "ml-msb"])
def test_cross_out_arithmetic_on_given_random_numbers(mode, monkeypatch):
    """The arithmetic of a lazy pixel crossing out, on given random numbers: the crossing's spike,
    then the electrons after it (``expected - remaining``, here its floor) in further spikes and
    the charge left; TE, an overflow's clock from the ``(2^b1 - 1) theta``-th electron after the
    crossing at light-time ``remaining + (expected - remaining) B``; a pixel whose crossing is
    past the interval has no spike (msb: its counter's remainder read out) and its charge drawn at
    the interval's end; one whose light is above event light is left to the sync."""
    from tespike.golden.fastsim import lazy

    class Given:                                   # a generator that returns chosen numbers
        def __init__(self):
            self.calls = []

        def beta(self, a, b):
            self.calls.append((int(a), list(b)))
            return np.full(np.shape(b), 0.5)

        def binomial(self, n, p):
            self.calls.append(("binomial", list(n), list(p)))
            return np.full(np.shape(n), 7)

    monkeypatch.setattr(lazy, "poisson_draws", lambda rng, mean: np.floor(mean).astype(np.int64))
    config = SensorConfig.preset(mode)
    theta, L, F = config.threshold, config.clocks_per_readout, config.clocks_per_tick
    sim = SceneSimulator(config, (1, 6), rng=0)
    top = sim.levels.mean_event * L
    # a few spikes, many (overflowing), two, exactly 2^b1 (TE: overflowing), no crossing, too bright
    remaining = np.array([0.57, 0.34, 0.97, 0.5, 2.3, 0.17]) * theta
    expected = np.array([3 * theta + 0.5, 20 * theta + 0.75, 2.5 * theta, 0, 2.1 * theta, 1.5 * top])
    expected[3] = remaining[3] + (config.p_max - 1) * theta + 0.25
    assert expected[1] < top and remaining[4] > expected[4]
    sim.lazy.mask[:] = True
    sim.lazy.remaining[:] = remaining
    sim.lazy.span[:] = 2.5 * theta
    sim.carried[:] = [0, 10, 20, 5, 30, 40]
    sim.sfc[4] = 5 if config.is_msb else 0                # a remainder left in the msb counter
    sim.rng = Given()
    words = np.zeros(6, np.int64)
    left, settled = lazy.cross_out(sim, np.arange(6), expected, np.zeros(6, np.int64), words)
    assert list(settled) == [0, 1, 2, 3, 4] and list(left) == [5]
    after = np.floor(expected[:4] - remaining[:4]).astype(np.int64)
    spikes = 1 + after // theta
    assert np.array_equal(sim.carried, np.concatenate([after % theta, [30 + 7, 40]]))
    # the quiet pixel's charge: n - 1 electrons before its crossing, the share of its span passed at the end
    quiet = ("binomial", [theta - 30 - 1], [pytest.approx((2.5 - (2.3 - 2.1)) / 2.5)])
    assert sim.rng.calls[0] == quiet and not sim.lazy.mask[4] and sim.lazy.mask[5]
    if config.is_msb:
        count = np.minimum(np.append(spikes, 5), config.ml_max)
        assert np.array_equal(words[:5], sim.tables.msb_word[count]) and words[4] > 0
        assert np.array_equal(sim.sfc[:5], sim.tables.msb_rest[count]) and sim.rng.calls == [quiet]
        return
    if mode == "ml":
        assert np.array_equal(words[:5], np.append(np.minimum(spikes, config.ml_max), 0))
        assert sim.rng.calls == [quiet]
        return
    need = (config.p_max - 1) * theta
    assert list(spikes >= config.p_max) == [False, True, False, True] and spikes[3] == config.p_max
    assert sim.rng.calls == [quiet, (need, [after[1] - need + 1, 1])]
    ticks = [int((remaining[i] + (expected[i] - remaining[i]) * 0.5) / expected[i] * L) // F + 1 for i in (1, 3)]
    assert list(words) == [spikes[0], (1 << config.d) | ticks[0], spikes[2], (1 << config.d) | ticks[1], 0, 0]


def test_setting_the_charge_refuses_what_no_pixel_can_hold_in_one_line():
    """``sim.acc = 2.7`` had been truncated to 2, -5 simulated at the next readout, and booleans
    taken as 1 and 0."""
    config = SensorConfig()
    sim = SceneSimulator(config, (1, 2), rng=0)
    for values in (2.7, [True, False], [1, 2, 3]):
        with pytest.raises(InputError, match=r"^acc: must be integers, one a pixel \(2, or \(1, 2\)\) or one for all"):
            sim.acc = values
    for values in (-5, config.acc_max + 1):
        with pytest.raises(InputError, match=f"^acc: charges must lie in 0 .. {config.acc_max} "):
            sim.acc = values
    sim.acc = [3, 4]
    assert sim.acc.tolist() == [3, 4]
