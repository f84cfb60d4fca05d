"""tespike.recon.methods: reconstruct() on hand-made and simulated streams, both modes."""

import numpy as np
import pytest
import torch

from tespike.golden.config import DESIGN_ELECTRONS, SensorConfig
from tespike.golden.decode import decode_light
from tespike.golden.errors import ConfigError, InputError
from tespike.golden.sensor import simulate
from tespike.recon.decoding import decode_light as recon_decode_light
from tespike.recon.learned import load_learned
from tespike.recon.methods import RECON_METHODS, reconstruct

#: The training-free methods, which work pixel by pixel along time on any configuration
#: (the network is tested in tests/test_recon_net_*.py, on the presets it has weights for).
PIXEL_METHODS = sorted(name for name, method in RECON_METHODS.items() if method.block is not None)
from tespike.golden.decode import legal_words
from tests.configs import EDGE_CONFIGS, MSB_EDGE_CONFIGS

TE, ML, MSB = SensorConfig(), SensorConfig(mode="ml"), SensorConfig.preset("ml-msb")
K, SIDE = 60, 6          # readouts; each light level covers SIDE x SIDE pixels


def constant_light_stream(config, levels, rng):
    """Per-clock Poisson electrons (SPEC section 6) of constant light; one block per level."""
    L = config.clocks_per_readout
    lam = np.repeat(np.asarray(levels, float) * DESIGN_ELECTRONS / L, SIDE)
    mean = np.broadcast_to(lam[None, :, None], (K * L, lam.size, SIDE))
    stimulus = np.minimum(rng.poisson(mean), config.input_max).astype(np.int64)
    return simulate(config, stimulus)


def level_means(images, count):
    return images.reshape(K, count, SIDE, SIDE).mean(axis=(0, 2, 3))


@pytest.fixture(scope="module")
def te_low(request):
    return constant_light_stream(TE, TE_LEVELS, np.random.default_rng(7))


TE_LEVELS = [1e-3, 1e-2, 0.05, 0.1, 0.3, 0.6, 1.0]
ML_LEVELS = [1e-3, 1e-2, 0.1, 0.5, 1.0, 1.5]


@pytest.mark.parametrize("method", PIXEL_METHODS)
def test_te_constant_light_means(method, te_low):
    images = reconstruct(te_low, TE, method)
    assert images.dtype == np.float32 and images.shape == te_low.shape
    means = level_means(images, len(TE_LEVELS))
    for level, mean in zip(TE_LEVELS, means):
        spikes = level * DESIGN_ELECTRONS / TE.threshold * K * SIDE * SIDE
        noise = 4 / np.sqrt(spikes)                # 4 sigma of Poisson counting over the block
        # the paper's ratio decoder rounds the overflow time up to whole S_h cycles:
        # r = 2^b1 alpha / m >= rho / (1 + rho / (2^b1 alpha)) for rho spikes per readout
        rho = level * DESIGN_ELECTRONS / TE.threshold
        low = level / (1 + rho / (TE.p_max * TE.alpha)) if rho >= TE.p_max else level
        assert low * (1 - noise) <= mean <= level * (1 + noise), (level, mean)
    # in the counting range (below 2^b1 spikes per readout) it is within 5 %
    assert abs(means[1] / TE_LEVELS[1] - 1) < 0.05 and abs(means[2] / TE_LEVELS[2] - 1) < 0.05


@pytest.mark.parametrize("method", PIXEL_METHODS)
def test_ml_constant_light_means(method, rng):
    words = constant_light_stream(ML, ML_LEVELS, rng)
    means = level_means(reconstruct(words, ML, method), len(ML_LEVELS))
    for level, mean in zip(ML_LEVELS, means):
        noise = 4 / np.sqrt(level * DESIGN_ELECTRONS / ML.threshold * K * SIDE * SIDE)
        assert abs(mean / level - 1) <= max(noise, 0.01), (level, mean)


@pytest.mark.parametrize("method", PIXEL_METHODS)
def test_msb_constant_light_means(method, rng):
    """The msb readout keeps what it does not read, so over 60 readouts the mean
    is the light's up to the remainder left at the end (at most half a readout's
    count over K readouts: 1 / (2 K) relative) and counting noise."""
    levels = [1e-3, 1e-2, 0.1, 0.5, 0.75, 1.0]
    words = constant_light_stream(MSB, levels, rng)
    assert set(np.unique(words)) <= set(range(9))
    means = level_means(reconstruct(words, MSB, method), len(levels))
    for level, mean in zip(levels, means):
        noise = 4 / np.sqrt(level * DESIGN_ELECTRONS / MSB.threshold * K * SIDE * SIDE)
        assert -max(noise, 0.01) - 1 / (2 * K) <= mean / level - 1 <= max(noise, 0.01), (level, mean)


@pytest.mark.parametrize("method", PIXEL_METHODS)
@pytest.mark.parametrize("config", [TE, ML, MSB], ids=str)
def test_saturates_above_range(method, config, rng):
    """10x and 1000x the design light: every word is the top code, light = its decoded value.

    TE: overflow in the first S_h cycle (m = 1), 2^b1 alpha spikes = I 0.9999. ML: one
    spike per pixel clock at most, so the count stops at L = 240 < 255 = 2^8 - 1 (I 1.874).
    ML msb: 240 spikes have bit_length 8, read as 2^7 = 128 (I 0.9996), the rest fills the counter.
    """
    words = constant_light_stream(config, [10.0, 1e3], rng)
    top = ((1 << config.d) | 1 if config.is_te else 8 if config.is_msb
           else min(config.ml_max, config.clocks_per_readout))
    assert (words == top).all()
    expected = decode_light(np.array([top]), config)[0]
    assert expected == pytest.approx(240 * 175 / 42000 if config.is_te else 128 * 328 / 42000 if config.is_msb
                                     else 240 * 328 / 42000, rel=1e-12)
    images = reconstruct(words, config, method)
    assert np.allclose(images, expected, rtol=1e-6, atol=0)
    assert np.all(reconstruct(words, config, method, dtype="float64") == np.float32(expected))


@pytest.mark.parametrize("config", EDGE_CONFIGS + MSB_EDGE_CONFIGS, ids=str)
def test_extreme_streams_every_edge_config(config, rng):
    u = config.threshold / DESIGN_ELECTRONS
    zeros = np.zeros((7, 2, 3), np.uint16)
    assert np.all(reconstruct(zeros, config, "tfp") == 0)
    assert np.allclose(reconstruct(zeros, config, "tfi"), u / 7, rtol=1e-6)
    top = max(legal_words(config), key=lambda c: decode_light(np.array([c]), config)[0])
    full = np.full((7, 2, 3), top)
    value = np.float32(decode_light(np.array([top]), config)[0])
    for method in PIXEL_METHODS:
        assert np.allclose(reconstruct(full, config, method), value, rtol=1e-6, atol=0)
    words = rng.choice(legal_words(config), size=(12, 3, 2))
    a = reconstruct(words, config, "tfi", window=3, search="window")
    b = reconstruct(torch.from_numpy(words), config, "tfi", window=3, search="window", chunk_elements=5)
    assert np.array_equal(a, b) and np.isfinite(a).all() and (a >= 0).all()


def test_tfp_window_1_is_the_decoded_stream(rng):
    words = rng.choice(legal_words(TE), size=(9, 4, 5))
    assert np.array_equal(reconstruct(words, TE, "tfp", window=1),
                          decode_light(words, TE).astype(np.float32))


def test_block_size_does_not_change_results(rng):
    words = rng.choice(legal_words(ML), size=(20, 7, 5))
    for method in PIXEL_METHODS:
        ref = reconstruct(words, ML, method)
        assert np.array_equal(ref, reconstruct(words, ML, method, chunk_elements=1))
        assert np.array_equal(ref, reconstruct(words, ML, method, chunk_elements=77))


def test_refusals():
    words = np.zeros((3, 2, 2), np.uint8)
    with pytest.raises(InputError, match="unknown reconstruction method 'cnn'"):
        reconstruct(words, TE, "cnn")
    with pytest.raises(InputError, match="option 'search' is not an option of method 'tfp'"):
        reconstruct(words, TE, "tfp", search="window")
    with pytest.raises(InputError, match="window = 4"):
        reconstruct(words, TE, "tfp", window=4)
    with pytest.raises(InputError, match="device"):
        reconstruct(words, TE, "tfp", device="nonsense")
    with pytest.raises(InputError, match="not an integer"):
        reconstruct(words.astype(float), TE, "tfi")
    with pytest.raises(InputError, match=r"must be \(K, H, W\)"):
        reconstruct(words[0], TE, "tfi")
    with pytest.raises(InputError, match="readout word 16 at index"):
        reconstruct(words + 16, TE, "tfi")
    assert reconstruct(np.zeros((0, 2, 2), np.uint8), TE, "tfp").shape == (0, 2, 2)


@pytest.mark.parametrize("options, refusal", [
    ({"device": None}, r"^device = None: must be a torch device name such as 'cpu' or 'cuda:0' \(or a torch.device\)$"),
    ({"device": True}, r"^device = True: must be a torch device name"),
    ({"device": ["cpu"]}, r"^device = \['cpu'\]: must be a torch device name"),
    ({"calibration": "C.npz"}, r"^the calibration must be a Calibration \(tespike.recon.calibration.load_calibration"
                               r"\(path\)\), not str$"),
    ({"weights": 123}, r"^weights: a path must be a str or an os.PathLike, not int$"),
])
def test_library_arguments_of_the_wrong_kind_are_refused_in_one_line(options, refusal):
    """(device None was torch's TypeError, a calibration's path an AttributeError, weights of a
    number os.fspath's TypeError.)"""
    method = "net" if "weights" in options else "tfp"
    with pytest.raises(InputError, match=refusal):
        reconstruct(np.zeros((3, 2, 2), np.uint8), TE, method, **options)


@pytest.mark.parametrize("call, name", [
    (lambda config: reconstruct(np.zeros((3, 2, 2), np.uint8), config, "tfp"), "reconstruct"),
    (lambda config: recon_decode_light(np.zeros((3, 2, 2), np.uint8), config), "decode_light"),
    (lambda config: load_learned(config, "net"), "load_learned"),
])
@pytest.mark.parametrize("not_config", ["te", {"mode": "te"}])
def test_what_is_no_configuration_is_refused_naming_the_entry_point(call, name, not_config):
    """(A preset's name was numpy's AttributeError; a dict, 'unhashable type')."""
    with pytest.raises(ConfigError, match=f"^{name}: configuration must be a SensorConfig .*"
                                          f"not {type(not_config).__name__}$"):
        call(not_config)


@pytest.mark.parametrize("method", ["tfp", "tfi", "net"])
@pytest.mark.parametrize("as_tensor", [False, True])
def test_an_illegal_word_is_named_by_readout_row_and_column(method, as_tensor):
    """The methods decode flattened blocks; the refusal names the word where the caller has it."""
    words = np.zeros((3, 16, 16), np.uint8)
    words[1, 5, 7] = 16                                                # no TE word of the preset
    given = torch.from_numpy(words.astype(np.int64)) if as_tensor else words
    with pytest.raises(InputError, match=r"readout word 16 at index \(1, 5, 7\)"):
        reconstruct(given, SensorConfig(), method)


def test_the_learned_methods_registry_refuses_what_is_no_name_path_or_configuration_in_one_line():
    """``weights_path('te')`` was an AttributeError of ``describe``, ``load_weights(None)`` pathlib's
    TypeError, ``weights_by_sensor(paths, [config])`` an AttributeError of ``items`` (and one path given
    as a string was taken letter by letter), ``method_classes(['net'])`` an "unhashable type"."""
    from tespike.golden.errors import ConfigError, InputError
    from tespike.recon.learned import load_weights, method_classes, weights_by_sensor, weights_path
    with pytest.raises(ConfigError, match="^weights_path: configuration must be a SensorConfig"):
        weights_path("te")
    with pytest.raises(InputError, match="^weights: a path must be a str or an os.PathLike, not NoneType$"):
        load_weights(None)
    with pytest.raises(InputError, match="^configs: must map sensor names to configurations, not list$"):
        weights_by_sensor([], [SensorConfig()])
    with pytest.raises(ConfigError, match="^sensor 'te': configuration must be a SensorConfig"):
        weights_by_sensor([], {"te": "te"})
    with pytest.raises(InputError, match="^cannot read --weights 'absent.pt': No such file or directory$"):
        weights_by_sensor("absent.pt", {"te": SensorConfig()})
    with pytest.raises(InputError, match=r"^unknown learned method \['net'\] \(known: net, "):
        method_classes(["net"])


def test_reconstruct_and_write_outputs_refuse_switches_that_are_no_bool_in_one_line(tmp_path):
    """``reconstruct(..., progress='no')`` showed a bar and ``write_outputs(..., plot='no')`` wrote the
    plot; a results folder given as a number was a TypeError and an evaluation that is none an
    AttributeError."""
    from tespike.recon.report import write_outputs
    with pytest.raises(InputError, match="^progress = 'no': must be True or False$"):
        reconstruct(np.zeros((3, 2, 2), np.uint8), SensorConfig(), "tfp", progress="no")
    with pytest.raises(InputError, match="^plot = 'no': must be True or False$"):
        write_outputs(None, tmp_path, plot="no")
    with pytest.raises(InputError, match="^write_outputs: the evaluation must be an Evaluation, not NoneType$"):
        write_outputs(None, tmp_path)
    assert not list(tmp_path.iterdir())


def test_reconstruct_settings_and_registry_refuse_outputs_estimators_and_configurations_that_are_none():
    """``out=[0] * 20`` was an AttributeError of ``shape``, a read-only out numpy's "assignment
    destination is read-only", ``ReconSettings(estimator=['ratio'])`` an "unhashable type",
    ``available_methods(config)`` a TypeError (one configuration is now one), a preset's name an
    AttributeError; --workers of 2.5 or True had been taken."""
    from tespike.golden.resources import check_workers_argument, require_memory
    from tespike.recon.methods import available_methods
    from tespike.recon.settings import ReconSettings
    words, config = np.zeros((4, 3, 3), np.uint8), SensorConfig()
    with pytest.raises(InputError, match=r"^out must be a float32 \(4, 3, 3\) numpy array, not list$"):
        reconstruct(words, config, "tfp", out=[0] * 20)
    with pytest.raises(InputError, match="^out is read-only: give an array the reconstruction can fill$"):
        reconstruct(words, config, "tfp", out=np.broadcast_to(np.zeros((4, 3, 3), np.float32), (4, 3, 3)))
    with pytest.raises(InputError, match=r"^estimator = \['ratio'\]: must be one of ratio, midpoint, residual$"):
        ReconSettings(estimator=["ratio"])
    assert available_methods(config) == available_methods([config])
    with pytest.raises(ConfigError, match="^available_methods: configuration must be a SensorConfig"):
        available_methods(["te"])
    for workers in (2.5, True, "4", 0):
        with pytest.raises(InputError, match=f"^--workers {workers!r}: must be in 1..256$"):
            check_workers_argument(workers)
    for needed in ("5", -5, float("nan")):
        with pytest.raises(InputError, match=f"^require_memory: {needed!r} bytes must be a finite number >= 0$"):
            require_memory(needed, "x")
