"""Calibration (recon.calibration, tespike calibrate, reconstruct --calibration)."""

import numpy as np
import pytest

from tespike.golden.config import DESIGN_ELECTRONS, SensorConfig
from tespike.golden.errors import ConfigError, InputError
from tespike.golden.fastsim import simulate_scene
from tespike.golden.io import save_stream
from tespike.golden.noise import Sensor, SensorNoise
from tespike.recon.calibration import (MIN_GAIN, Calibration, correct, estimate, load_calibration, save_calibration)
from tespike.recon.methods import reconstruct
from tests.cli import assert_refused, run_tespike

SENSOR = Sensor(SensorNoise(dark_current="eq12", dark_level=2.0, dsnu=0.3, prnu=0.1), seed=3)


def _streams(config, readouts, shape=(6, 8), flat_light=0.03, sensor=SENSOR):
    dark = simulate_scene(config, np.zeros((readouts, *shape)), seed=1, sensor=sensor)
    flat = simulate_scene(config, np.full((readouts, *shape), flat_light), seed=2, sensor=sensor)
    return dark, flat


@pytest.mark.parametrize("config", [SensorConfig(), SensorConfig.preset("ml-msb")], ids=str)
def test_estimate_finds_the_maps(config):
    """Below the TE overflow level the mean decoded light converges on the maps: dark rate
    within 3 % of its mean, gain within 1.5 % (PRNU here is 10 %)."""
    dark, flat = _streams(config, 400)
    c = estimate(dark, flat, config, 0.03)
    maps = SENSOR.maps((6, 8))
    truth = maps.mean_dark_electrons(SENSOR.noise) / DESIGN_ELECTRONS
    assert np.sqrt(np.mean((c.dark / truth - 1) ** 2)) < 0.03
    assert np.sqrt(np.mean((c.gain / maps.gain - 1) ** 2)) < 0.015
    assert c.dark_readouts == c.flat_readouts == 400 and c.floored == 0 and c.overflow_share < 0.1


def test_correct_inverts_the_pixel_response():
    config = SensorConfig(mode="ml")
    c = Calibration(np.full((2, 2), 0.01), np.array([[1.0, 2.0], [0.5, 1.0]]), config, 1, 1, 0.1)
    light = np.array([[[0.2, 0.3], [0.0, 0.005]]], np.float32)
    seen = light * c.gain + c.dark
    assert np.allclose(correct(seen.copy(), c), light, atol=1e-6)
    below = np.full((1, 2, 2), 0.005, np.float32)         # below the dark rate: no light, not negative
    assert np.array_equal(correct(below, c), np.zeros((1, 2, 2), np.float32))


def test_arguments_of_the_wrong_kind_are_refused_in_one_line(tmp_path):
    """(A configuration's name in estimate and a path where the Calibration belongs were AttributeErrors,
    frames of another size numpy's broadcast error.)"""
    te = SensorConfig()
    words = np.zeros((2, 3, 3), np.uint8)
    calibration = Calibration(np.zeros((3, 3)), np.ones((3, 3)), te, 1, 1, 0.1)
    with pytest.raises(ConfigError, match="^estimate: configuration must be a SensorConfig"):
        estimate(words, words, "te", 0.1)
    for call in (lambda: save_calibration(tmp_path / "C.npz", "C.npz"),
                 lambda: correct(np.zeros((1, 3, 3), np.float32), "C.npz")):
        with pytest.raises(InputError, match=r"^the calibration must be a Calibration \(tespike.recon.calibration"
                                             r".load_calibration\(path\)\), not str$"):
            call()
    for images in (np.zeros((1, 3, 4), np.float32), np.zeros((3, 3), np.float32)):
        with pytest.raises(InputError, match=r"^images of shape .*: the calibration corrects \(K, 3, 3\) frames$"):
            correct(images, calibration)
    assert not list(tmp_path.iterdir())


def test_calibration_wins_back_the_dark_and_the_gain():
    """TFP on a noisy stream: calibrated, its error against the light is far below uncalibrated."""
    config = SensorConfig()
    dark, flat = _streams(config, 200, (16, 16))
    c = estimate(dark, flat, config, 0.03)
    light = np.random.default_rng(0).uniform(0.0, 0.05, (1, 16, 16)).repeat(30, axis=0)
    words = simulate_scene(config, light, seed=5, sensor=SENSOR)
    raw = reconstruct(words, config, "tfp", window=29)[15]
    fixed = reconstruct(words, config, "tfp", window=29, calibration=c)[15]
    assert np.abs(fixed - light[15]).mean() < 0.25 * np.abs(raw - light[15]).mean()


def test_refusals_and_floor():
    config = SensorConfig()
    dark, flat = _streams(config, 4)
    with pytest.raises(InputError, match="flat light"):
        estimate(dark, flat, config, 0.0)
    for stated in (1e-300, 0.03 / 25):                      # far below what the flat shows (it was 0.03)
        with pytest.raises(InputError, match="above 20 times it"):
            estimate(dark, flat, config, stated)
    estimate(dark, flat, config, 0.03 / 15)                 # within the factor: a calibration
    with pytest.raises(InputError, match="differ"):
        estimate(dark, flat[:, :3], config, 0.03)
    for flat_of_nothing in (dark, dark[::-1]):              # a "flat" with no light (or the two swapped)
        with pytest.raises(InputError, match="no brighter than the dark stream .*swapped"):
            estimate(dark, flat_of_nothing, config, 0.03)
    c = estimate(dark, flat, config, 0.03 * 19)             # light overstated 19 x: the dimmer pixels floored
    assert 0 < c.floored < dark[0].size and c.gain.min() == MIN_GAIN
    with pytest.raises(InputError, match="threshold = 175 in the calibration, 100 in the stream"):
        reconstruct(dark, SensorConfig(threshold=100), "tfp", calibration=c)
    with pytest.raises(InputError, match="6 x 8"):
        reconstruct(dark[:, :2], config, "tfp", calibration=c)


@pytest.mark.parametrize("config, light", [(SensorConfig(), 2.0), (SensorConfig.preset("ml"), 10.0),
                                           (SensorConfig.preset("ml-msb"), 2.0)], ids=str)
def test_a_flat_beyond_the_sensor_range_is_refused(config, light):
    """A flat whose words are the sensor's top code (every clock's input saturated) showed half or a
    fifth of its light: the gain came out 0.49 (TE) or 0.19 (ML count), rc 0, and every calibrated
    image 2 to 5 times too bright."""
    dark, flat = _streams(config, 4, flat_light=light)
    with pytest.raises(InputError, match=r"flat stream is saturated: 100.0 % of its words are the sensor's "
                                         r"top code \(\d+:.*below \d"):
        estimate(dark, flat, config, light)
    estimate(*_streams(config, 4), config, 0.03)               # a flat within the range: calibrated
    with pytest.raises(InputError, match="the dark stream is saturated: 100.0 %.*its dark current alone"):
        estimate(flat, flat, config, light)


def test_calibrate_command_and_reconstruct_with_it(tmp_path):
    config = SensorConfig()
    dark, flat = _streams(config, 40)
    save_stream(tmp_path / "d.npz", dark, config)
    save_stream(tmp_path / "f.npz", flat, config)
    result = run_tespike("calibrate", "--dark", tmp_path / "d.npz", "--flat", tmp_path / "f.npz",
                         "--flat-light", "0.03", "--out", tmp_path / "c.npz")
    assert result.returncode == 0 and "6 x 8 pixels from 40 dark and 40 flat" in result.stdout, result.stderr
    c = load_calibration(tmp_path / "c.npz")
    expected = estimate(dark, flat, config, 0.03)
    assert np.array_equal(c.dark, expected.dark) and np.array_equal(c.gain, expected.gain)
    assert c.config == config and c.estimator == "mean-decoded"
    result = run_tespike("reconstruct", "--stream", tmp_path / "f.npz", "--method", "tfp",
                         "--calibration", tmp_path / "c.npz", "--out", tmp_path / "r.npy")
    assert result.returncode == 0, result.stderr
    assert np.array_equal(np.load(tmp_path / "r.npy"), reconstruct(flat, config, "tfp", calibration=c))
    # another configuration's stream, another frame size, a bad file: one line each
    save_stream(tmp_path / "ml.npz", simulate_scene(SensorConfig(mode="ml"), np.zeros((3, 6, 8)), seed=0),
                SensorConfig(mode="ml"))
    assert_refused(run_tespike("reconstruct", "--stream", tmp_path / "ml.npz", "--method", "tfp",
                               "--calibration", tmp_path / "c.npz", "--out", tmp_path / "r2.npy"),
                   "another sensor configuration")
    assert_refused(run_tespike("calibrate", "--dark", tmp_path / "d.npz", "--flat", tmp_path / "ml.npz",
                               "--flat-light", "0.03", "--out", tmp_path / "c2.npz"), "different configurations")
    assert_refused(run_tespike("calibrate", "--dark", tmp_path / "d.npz", "--flat", tmp_path / "f.npz",
                               "--flat-light", "-1", "--out", tmp_path / "c2.npz"), "flat light")
    (tmp_path / "bad.npz").write_bytes(b"PK no zip")
    assert_refused(run_tespike("reconstruct", "--stream", tmp_path / "f.npz", "--method", "tfp",
                               "--calibration", tmp_path / "bad.npz", "--out", tmp_path / "r2.npy"), "bad.npz")
    assert not (tmp_path / "r2.npy").exists() and not (tmp_path / "c2.npz").exists()


def test_file_round_trip(tmp_path):
    config = SensorConfig()
    c = estimate(*_streams(config, 8), config, 0.03)
    save_calibration(tmp_path / "c.npz", c)
    back = load_calibration(tmp_path / "c.npz")
    assert np.array_equal(back.gain, c.gain) and back.flat_light == 0.03 and back.overflow_share == c.overflow_share
    import dataclasses
    save_calibration(tmp_path / "neg.npz", dataclasses.replace(c, dark=c.dark - 5.0))   # no decoded light is < 0
    with pytest.raises(InputError, match=r"dark must lie in \[0, 1\]"):
        load_calibration(tmp_path / "neg.npz")


@pytest.mark.parametrize("member, value, words", [
    ("gain", lambda c: np.full(c.gain.shape, 1e-308), "gain must lie in"),          # TFP and TFI wrote inf
    ("gain", lambda c: np.full(c.gain.shape, 1e308), "gain must lie in"),
    ("dark", lambda c: np.full(c.dark.shape, 1e308), "dark must lie in"),           # the network wrote NaN
    ("dark", lambda c: np.full(c.dark.shape, "a"), "dark must be a float"),         # a traceback
    ("gain", lambda c: c.gain.astype(np.complex128), "gain must be a float"),       # the imaginary part dropped
    ("dark_law", lambda c: c.dark_law[:1], "Q >= 2"),
    ("dark_law", lambda c: c.dark_law[::-1].copy(), "ascending"),
    ("dark_law", lambda c: np.full(c.dark_law.shape, 3e38, np.float32), r"dark_law must lie in \[0, 240\]"),
    ("estimator", lambda c: np.array("bogus"), "estimator 'bogus' unknown"),
    ("dark_readouts", lambda c: np.array(0), "dark_readouts must be an integer >= 1"),
    ("flat_light", lambda c: np.array(np.nan), "flat_light must be a finite number > 0"),
    ("flat_light", lambda c: np.array(-1.0), "flat_light must be a finite number > 0, not -1.0$"),  # not array(-1.)
    ("flat_light", lambda c: np.array("0.03"), "flat_light must be a finite number > 0, not '0.03'$"),
    ("flat_light", lambda c: np.zeros(3), r"flat_light must be a finite number > 0, not a float64 array of shape \(3,\)$"),
    ("extra", lambda c: np.zeros(2), "holds 'extra' beside the members 'tespike calibrate' writes$"),    # dropped
    ("format", lambda c: np.array("tespike-calibration-1"),                 # its law dropped without a word
     "has format 'tespike-calibration-1' and holds 'dark_law', which only format 'tespike-calibration-2' has$"),
])
def test_a_calibration_tespike_calibrate_could_not_write_is_refused(tmp_path, member, value, words):
    """Finite but absurd maps and numbers made R.npy files of inf or NaN (rc 0), or a traceback."""
    config = SensorConfig()
    c = estimate(*_streams(config, 8), config, 0.03)
    save_calibration(tmp_path / "c.npz", c)
    members = dict(np.load(tmp_path / "c.npz"))
    members[member] = value(c)
    np.savez(tmp_path / "bad.npz", **members)
    with pytest.raises(InputError, match=f"calibration file .*bad.npz.*{words}"):
        load_calibration(tmp_path / "bad.npz")


def test_reconstruct_with_calibration_and_weights(tmp_path):
    """``reconstruct --calibration C.npz --weights W.pt``: the user's learned weights run on
    input corrected by the calibration (not the shipped weights, not uncorrected, not an output
    correction)."""
    import torch

    from tespike.recon.learned import method_classes
    from tespike.recon.learning.weights import save_weights
    config = SensorConfig()
    dark, flat = _streams(config, 40)
    c = estimate(dark, flat, config, 0.03)
    save_calibration(tmp_path / "c.npz", c)
    save_stream(tmp_path / "f.npz", flat, config)
    torch.manual_seed(0)
    module, sizes = method_classes("bsf")
    save_weights(tmp_path / "mine.pt", module(sizes.preset("cpu")).eval(), config, {}, "bsf")
    result = run_tespike("reconstruct", "--stream", tmp_path / "f.npz", "--method", "bsf",
                         "--weights", tmp_path / "mine.pt", "--calibration", tmp_path / "c.npz",
                         "--out", tmp_path / "r.npy")
    assert result.returncode == 0, result.stderr
    written = np.load(tmp_path / "r.npy")
    raw = reconstruct(flat, config, "bsf", weights=tmp_path / "mine.pt")
    assert np.array_equal(written, reconstruct(flat, config, "bsf", weights=tmp_path / "mine.pt", calibration=c))
    assert not np.array_equal(written, raw) and not np.array_equal(written, correct(raw.copy(), c))
    assert not np.array_equal(written, reconstruct(flat, config, "bsf", calibration=c))     # shipped weights


def test_learned_methods_are_corrected_at_their_input():
    """A learned method with a calibration equals the same module fed ``(x - dark) / gain`` (not
    floored) with its image floored at 0 (a uniform calibration, applied by a wrapper module: an
    independent route), and differs from correcting its output; TFP stays corrected at its output."""
    import torch

    from tespike.recon.learned import load_learned
    from tespike.recon.learning.infer import reconstruct_model

    class InputCorrected(torch.nn.Module):
        def __init__(self, model, dark, gain):
            super().__init__()
            self.model, self.sizes, self.dark, self.gain = model, model.sizes, dark, gain

        def forward(self, light, inside, spike_light):
            return self.model((light - self.dark) / self.gain, inside, spike_light).clamp(min=0)

    config = SensorConfig()
    words = simulate_scene(config, np.random.default_rng(4).uniform(0, 0.2, (5, 16, 24)), seed=5, sensor=SENSOR)
    dark, gain = 0.004, 1.25
    c = Calibration(np.full((16, 24), dark), np.full((16, 24), gain), config, 64, 64, 0.03)
    model = load_learned(config, "net")
    ours = reconstruct(words, config, "net", calibration=c)
    assert np.array_equal(ours, reconstruct_model(model, words, config, tile=None, calibration=c))
    wrapped = reconstruct_model(InputCorrected(model, np.float32(dark), np.float32(gain)), words, config, tile=None)
    assert np.allclose(ours, wrapped, rtol=1e-5, atol=1e-7)
    assert not np.allclose(ours, correct(reconstruct(words, config, "net"), c), rtol=1e-3, atol=1e-6)
    assert np.array_equal(reconstruct(words, config, "tfp", calibration=c), correct(reconstruct(words, config, "tfp"), c))


def _dark_free_light_loop(spikes, dark_spikes):
    """The rule of recon.calibration.dark_free_light, readout by readout for one pixel (spike units)."""
    net = high = fired_at = 0.0
    out = np.zeros(len(spikes))
    for k, x in enumerate(spikes):
        net += x - dark_spikes
        if net > high:
            if np.floor(net) > np.floor(high):       # the high-water mark passes a new whole spike
                out[k], fired_at = net - fired_at, net
            high = net
    return out


def test_tfi_is_corrected_at_its_input():
    """TFI with a calibration: TFI of the pixel's own charge (decoded spikes less the dark rate,
    carried from readout to readout, a readout firing where the charge passes a new whole spike,
    a readout-by-readout loop here, the product vectorised in blocks of a few pixels), divided by
    the gain; an output correction and the old per-readout floor are different estimates. The
    calibration here carries only the mean dark rate (a format-1 file; with a dark law the readout's
    dark charge is its expectation under the law, tests/test_recon_darklaw.py)."""
    import dataclasses

    import torch

    from tespike.recon.decoding import decode_light, decode_spikes
    from tespike.recon.tfi import tfi
    config = SensorConfig()
    dark_words, flat_words = _streams(config, 64)
    c = dataclasses.replace(estimate(dark_words, flat_words, config, 0.03), dark_law=None)
    light = np.random.default_rng(6).uniform(0, 0.05, (20, 6, 8))
    words = simulate_scene(config, light, seed=8, sensor=SENSOR)
    spikes = decode_spikes(torch.from_numpy(words.astype(np.int64)), config).numpy().reshape(20, -1)
    dark = c.dark.reshape(-1) / config.spike_light
    own = np.stack([_dark_free_light_loop(spikes[:, i], dark[i]) for i in range(48)], 1) * config.spike_light
    own = torch.from_numpy(own.reshape(20, 6, 8))
    expected = (tfi(own, own > 0, config.spike_light, 4, "stream") / torch.from_numpy(c.gain)).numpy()
    ours = reconstruct(words, config, "tfi", calibration=c, chunk_elements=20 * 5)
    assert np.allclose(ours, expected, rtol=1e-5, atol=1e-8)
    assert (own == 0).any() and not np.allclose(ours, correct(reconstruct(words, config, "tfi"), c))
    decoded = decode_light(torch.from_numpy(words.astype(np.int64)), config, dtype=torch.float32)
    floored = torch.clamp((decoded - torch.from_numpy(c.dark).float()) / torch.from_numpy(c.gain).float(), min=0)
    assert not np.allclose(ours, tfi(floored, floored > 0, config.spike_light, 4, "stream").numpy())


def test_tfi_with_a_dark_free_calibration_is_tfi_over_the_gain():
    """Dark 0: the pixel's own charge is its decoded light, overflow words included, so calibrated
    TFI is uncalibrated TFI divided by the gain."""
    config = SensorConfig()
    light = np.random.default_rng(9).uniform(0, 0.3, (16, 5, 7)) ** 2     # dark pixels to overflow words
    words = simulate_scene(config, light, seed=10)
    assert (words >= 1 << max(config.b1, config.b2)).any() and (words == 0).any()
    gain = np.random.default_rng(11).uniform(0.8, 1.2, (5, 7))
    c = Calibration(np.zeros((5, 7)), gain, config, 1, 1, 0.03)
    assert np.allclose(reconstruct(words, config, "tfi", calibration=c),
                       reconstruct(words, config, "tfi") / gain, rtol=1e-6, atol=0)


@pytest.mark.parametrize("light_level", [0.0, 0.0005])
def test_calibrated_tfi_error_does_not_grow_as_the_dark_level_falls(light_level):
    """Dim uniform light under eq. 12 dark current at 1/8 to 2 x, calibrated with the exact dark
    rate: the bias of calibrated TFI (its mean over the readouts against the light) falls with the
    dark level and stays below a tenth of the dark rate. Flooring each readout at 0 after
    subtracting the dark rate kept a pixel's dark charge at the readouts that fire: at 1/4 x the
    bias was 43 % of the dark rate and larger than at 1/2 x."""
    config = SensorConfig()
    light = np.full((48, 16, 16), light_level)
    errors = []
    for level in (0.125, 0.25, 0.5, 1.0, 2.0):
        sensor = Sensor(SensorNoise(dark_current="eq12", dark_level=level))
        words = simulate_scene(config, light, seed=3, sensor=sensor)
        dark = 400 * level / DESIGN_ELECTRONS
        c = Calibration(np.full((16, 16), dark), np.ones((16, 16)), config, 1, 1, 0.03)
        images = reconstruct(words, config, "tfi", calibration=c)[8:-8]
        errors.append(np.abs(images.mean(axis=0) - light_level).mean())
        assert errors[-1] < 0.1 * dark, (level, errors[-1], dark)
    assert all(a <= b * (1 + 1e-6) for a, b in zip(errors, errors[1:])), errors


def test_a_te_flat_of_overflow_words_is_refused_and_an_msb_flat_below_its_ceiling_is_taken():
    """A TE flat at 0.1 to 0.9 (every word an overflow word) read gains 2 to 43 % low, exit 0; an msb
    flat at 0.8 to 0.99, whose mean decoding is exact, was refused as saturated (its top word is also
    the ordinary reading of 2^(ml_bits - 1) spikes or more)."""
    te = SensorConfig()
    dark, flat = _streams(te, 8, flat_light=0.3)
    with pytest.raises(InputError, match="flat light 0.3 is above the TE overflow level .0.0667.: 100.0 % of"):
        estimate(dark, flat, te, 0.3)
    msb = SensorConfig.preset("ml-msb")
    dark, flat = _streams(msb, 64, flat_light=0.9, sensor=None)
    c = estimate(dark, flat, msb, 0.9)
    assert abs(float(np.median(c.gain)) - 1) < 0.02
    dark, flat = _streams(msb, 16, flat_light=1.5, sensor=None)
    with pytest.raises(InputError, match="saturated.*below 1"):
        estimate(dark, flat, msb, 1.5)


def test_a_calibration_file_with_a_gain_calibrate_never_writes_is_refused(tmp_path):
    config = SensorConfig()
    c = estimate(*_streams(config, 4), config, 0.03)
    import dataclasses
    save_calibration(tmp_path / "c.npz", dataclasses.replace(c, gain=c.gain * 1e3, flat_light=1e-6))
    with pytest.raises(InputError, match="median gain .* above 20"):
        load_calibration(tmp_path / "c.npz")


@pytest.mark.parametrize("dark", [None, "dark.npz", np.zeros((4, 2, 2))], ids=["none", "path-text", "float"])
def test_estimate_refuses_a_dark_stream_that_is_no_word_array_in_one_line(dark):
    """``estimate(None, ...)`` or a list was an AttributeError of ``.ndim``; a float array went on."""
    from tespike.recon.calibration import estimate
    with pytest.raises(InputError, match="^dark stream: readout words dtype .* is not an integer type$"):
        estimate(dark, np.zeros((4, 2, 2), np.uint8), SensorConfig(), 0.03)


def test_the_calibration_helpers_refuse_words_configurations_and_counts_that_are_none_in_one_line():
    """Empty words were ZeroDivisionErrors, float words an overflow share, a preset's name or a file's
    name AttributeErrors, 0 or 2.5 atoms an empty law or a TypeError, and a spike light of 0 zeros."""
    from tespike.recon.calibration import (calibration_summary, dark_free_light, estimate_dark_law, flat_ceiling,
                                           input_correction, mean_decoded_light, overflow_share, saturated_share,
                                           saturated_words)
    from tespike.recon.darklaw import law_atoms
    config, words = SensorConfig(), np.zeros((4, 2, 2), np.uint8)
    for atoms in (0, 2.5, -2):
        with pytest.raises(InputError, match=f"^dark law atoms {atoms!r}: must be an integer >= 1$"):
            estimate_dark_law(words, config, atoms)
        with pytest.raises(InputError, match=f"^dark law atoms {atoms!r}: must be an integer >= 1$"):
            law_atoms(np.ones((3, 2)), atoms)
    empty = np.zeros((0, 2, 2), np.uint8)
    for call in (lambda: mean_decoded_light(empty, config), lambda: saturated_share(empty, np.array([1])),
                 lambda: overflow_share(empty, config)):
        with pytest.raises(InputError, match=r"^words shape \(0, 2, 2\) must be \(K, H, W\) with K, H, W >= 1$"):
            call()
    with pytest.raises(InputError, match="^words: readout words dtype float64 is not an integer type$"):
        overflow_share(np.zeros((2, 2, 2)), config)
    for call, what in ((flat_ceiling, "flat_ceiling"), (saturated_words, "saturated_words"),
                       (lambda c: overflow_share(words, c), "overflow_share")):
        with pytest.raises(ConfigError, match=f"^{what}: configuration must be a SensorConfig"):
            call("te")
    for call, what in ((calibration_summary, "calibration_summary"), (input_correction, "input_correction")):
        with pytest.raises(InputError, match=f"^{what}'s calibration must be a Calibration"):
            call("C.npz")
    for light in (0.0, float("nan")):
        with pytest.raises(InputError, match=f"^spike light {light!r}: must be a finite number > 0$"):
            dark_free_light(np.ones((3, 2)), 0.0, light)
