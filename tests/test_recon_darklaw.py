"""The dark law in the calibration (recon.darklaw) and calibrated TFP and TFI that use it."""

import dataclasses

import numpy as np
import pytest

from tespike.golden.config import SensorConfig
from tespike.golden.errors import InputError
from tespike.golden.fastsim import simulate_scene
from tespike.golden.noise import Sensor, SensorNoise
from tespike.recon.calibration import (FORMAT_MEAN_ONLY, Calibration, correct, estimate, load_calibration,
                                       save_calibration)
from tespike.recon.darklaw import LAW_ATOMS, law_atoms
from tespike.recon.methods import reconstruct

EQ13 = Sensor(SensorNoise(dark_current="eq13"), seed=1)


def _calibrated(config, sensor, shape, readouts=256):
    dark = simulate_scene(config, np.zeros((readouts, *shape)), seed=1, sensor=sensor)
    flat = simulate_scene(config, np.full((readouts, *shape), 0.03), seed=2, sensor=sensor)
    return estimate(dark, flat, config, 0.03)


def test_law_atoms_are_the_quantiles_of_the_dark_readouts():
    """Atom i is the observed value at level (i + 0.5) / Q: readouts 0..K-1 in any order per pixel."""
    K = 256
    readouts = np.stack([np.random.default_rng(p).permutation(K) for p in range(3)], 1).astype(np.float64)
    atoms = law_atoms(readouts, 8)
    expected = np.ceil((np.arange(8) + 0.5) / 8 * K) - 1
    assert atoms.dtype == np.float32 and atoms.shape == (8, 3)
    assert np.array_equal(atoms, np.repeat(expected[:, None], 3, 1))


@pytest.mark.parametrize("config", [SensorConfig(), SensorConfig.preset("ml-msb")], ids=str)
def test_a_calibration_without_dark_current_gives_plain_tfp_exactly(config):
    """A dark stream of zeros: every atom 0, and calibrated TFP is plain TFP (overflow words
    included) divided by the gain, bit for bit; TFI is plain TFI over the gain, to rounding."""
    shape = (5, 7)
    c = _calibrated(config, Sensor(SensorNoise(prnu=0.05), seed=2), shape, readouts=16)
    assert c.dark_law.shape == (LAW_ATOMS, *shape) and not c.dark_law.any() and c.dark_tail == 0
    light = np.random.default_rng(9).uniform(0, 0.3, (16, *shape)) ** 2
    words = simulate_scene(config, light, seed=10)
    if config.is_te:
        assert (words >= 1 << max(config.b1, config.b2)).any() and (words == 0).any()
    plain = reconstruct(words, config, "tfp")
    assert np.array_equal(reconstruct(words, config, "tfp", calibration=c), correct(plain.copy(), c))
    unit = dataclasses.replace(c, gain=np.ones(shape))
    assert np.array_equal(reconstruct(words, config, "tfp", calibration=unit), plain)
    assert np.allclose(reconstruct(words, config, "tfi", calibration=c),
                       reconstruct(words, config, "tfi") / c.gain, rtol=1e-6, atol=0)


@pytest.mark.parametrize("level", [0.0, 0.003, 0.01])
def test_the_law_beats_the_mean_on_eq13_dark_current(level):
    """Uniform light under the paper's eq. 13 dark current, calibrated from 256 dark readouts of the
    same sensor: with the law, TFP's and TFI's RMS error (what PSNR weighs) is below 0.6 times the
    mean dark rate's (measured 0.31 to 0.54), and their bias within 0.3 spikes per readout (measured
    0.10 to 0.21, 3 to 7 % of the dark rate: the own light is modelled as Poisson, wider than a TE
    pixel's own spikes, so a share of a tail readout is read as own light; the mean's own bias is
    up to 0.28 where the light is 0, from its floor at 0)."""
    config = SensorConfig()
    shape = (12, 12)
    c = _calibrated(config, EQ13, shape)
    mean_only = dataclasses.replace(c, dark_law=None)
    words = simulate_scene(config, np.full((24, *shape), level), seed=3, sensor=EQ13)
    for method in ("tfp", "tfi"):
        law = reconstruct(words, config, method, calibration=c)[4:-4]
        mean = reconstruct(words, config, method, calibration=mean_only)[4:-4]
        rms = [np.sqrt(np.mean((images - level) ** 2)) for images in (law, mean)]
        assert rms[0] < 0.6 * rms[1], (method, rms)
        assert abs(law.mean() - level) < 0.3 * config.spike_light, method


def test_a_dark_spike_moves_the_law_estimate_little():
    """One readout of 40 dark spikes in a dark pixel's window: the mean-subtracted window rises by
    about 40 / 9 spikes (less where the floor at 0 held it), the law's by less than a tenth of that."""
    config = SensorConfig()
    c = _calibrated(config, EQ13, (4, 4))
    words = simulate_scene(config, np.zeros((9, 4, 4)), seed=4, sensor=EQ13)
    spiky = words.copy()
    spiky[4] = (1 << 4) | 6                            # the overflow word of 240 / 6 = 40 spikes
    for calibration, most in ((c, 0.44), (dataclasses.replace(c, dark_law=None), None)):
        rise = (reconstruct(spiky, config, "tfp", calibration=calibration)[4]
                - reconstruct(words, config, "tfp", calibration=calibration)[4]) / config.spike_light
        if most is None:
            assert rise.mean() > 3 and rise.min() > 2
        else:
            assert rise.max() < most, rise


def test_file_round_trip_old_format_and_refusals(tmp_path):
    config = SensorConfig()
    c = _calibrated(config, EQ13, (3, 4), readouts=32)
    save_calibration(tmp_path / "c.npz", c)
    back = load_calibration(tmp_path / "c.npz")
    assert np.array_equal(back.dark_law, c.dark_law) and back.dark_law.dtype == np.float32
    assert back.dark_tail == c.dark_tail > 0
    values = dict(np.load(tmp_path / "c.npz"))
    # the previous format (no law) is read, and corrected by the mean dark rate
    old = {k: v for k, v in values.items() if k not in ("dark_law", "dark_tail")}
    np.savez(tmp_path / "old.npz", **{**old, "format": np.array(FORMAT_MEAN_ONLY)})
    mean_only = load_calibration(tmp_path / "old.npz")
    assert mean_only.dark_law is None and np.array_equal(mean_only.dark, c.dark)
    words = simulate_scene(config, np.full((9, 3, 4), 0.002), seed=5, sensor=EQ13)
    assert np.array_equal(reconstruct(words, config, "tfp", calibration=mean_only),
                          correct(reconstruct(words, config, "tfp"), c))
    # a calibration without a law saves as an empty law and reads back without one
    save_calibration(tmp_path / "none.npz", dataclasses.replace(c, dark_law=None))
    assert load_calibration(tmp_path / "none.npz").dark_law is None
    bad = {"law.npz": ({"dark_law": values["dark_law"][:, :2]}, "dark_law must be float32"),
           "neg.npz": ({"dark_law": -values["dark_law"]}, "dark_law must be float32"),
           "f64.npz": ({"dark_law": values["dark_law"].astype(np.float64)}, "dark_law must be float32"),
           "tail.npz": ({"dark_tail": np.float64(np.nan)}, "dark_tail"),
           # (a traceback from float() on an array or a complex; a string named the archive unreadable)
           "tail1.npz": ({"dark_tail": np.array([0.0])}, "dark_tail must be a finite number"),
           "tail2.npz": ({"dark_tail": np.array([])}, "dark_tail must be a finite number"),
           "tail3.npz": ({"dark_tail": np.complex128(1)}, "dark_tail must be a finite number"),
           "tail4.npz": ({"dark_tail": np.array("abc")}, "dark_tail must be a finite number"),
           "nolaw.npz": ({"format": np.array("tespike-calibration-2"), "dark_law": None}, "lacks dark_law"),
           "fmt.npz": ({"format": np.array("tespike-calibration-9")}, "has format"),
           "fmt2.npz": ({"format": np.array([b"x"])}, "'format' must be a 0-d string"),
           "est.npz": ({"estimator": np.array(b"\xff")}, "'estimator' holds bytes that are not UTF-8")}
    for name, (change, message) in bad.items():
        written = {k: v for k, v in {**values, **change}.items() if v is not None}
        np.savez(tmp_path / name, **written)
        with pytest.raises(InputError, match=message):
            load_calibration(tmp_path / name)
    # text stored as bytes reads as UTF-8, as a 'config' member's does (it had been refused with
    # numpy's repr of the bytes as the format)
    np.savez(tmp_path / "bytes.npz", **{**values, "format": np.array(b"tespike-calibration-2"),
                                        "estimator": np.array(str(values["estimator"]).encode())})
    assert np.array_equal(load_calibration(tmp_path / "bytes.npz").dark, c.dark)


def test_a_learned_method_sees_the_law_input_and_without_dark_charge_the_mean_rate_input():
    """The learned methods' input under a law (recon.learning.infer.law_input): the mean-rate input, and
    a readout the law puts in its upper tail less that charge.
    A law without dark charge gives the mean-rate input (decoded light over the gain) exactly, so the
    network's images are those of the mean-rate calibration; a readout of 40 dark spikes in a dark
    pixel's window reaches the input at under a tenth of the mean-rate input's 40 spikes less the
    dark rate."""
    from tespike.recon.learning.infer import law_input
    from tespike.recon.decoding import decode_light
    config = SensorConfig()
    clean = _calibrated(config, Sensor(SensorNoise(prnu=0.05), seed=2), (8, 8), readouts=16)
    words = simulate_scene(config, np.random.default_rng(3).uniform(0, 0.2, (6, 8, 8)), seed=6)
    plain = decode_light(words, config).numpy() / clean.gain
    assert np.allclose(law_input(words, config, clean).numpy(), plain, rtol=1e-6, atol=0)
    mean_only = dataclasses.replace(clean, dark_law=None)
    assert np.allclose(reconstruct(words, config, "net", calibration=clean),
                       reconstruct(words, config, "net", calibration=mean_only), rtol=1e-4, atol=1e-6)
    c = _calibrated(config, EQ13, (4, 4))
    dark = simulate_scene(config, np.zeros((9, 4, 4)), seed=4, sensor=EQ13)
    dark[4] = (1 << 4) | 6                             # the overflow word of 240 / 6 = 40 spikes
    own = law_input(dark, config, c).numpy()[4] * c.gain / config.spike_light
    mean_rate = 40 - c.dark / config.spike_light
    assert (mean_rate > 30).all() and (own < 0.1 * mean_rate).all(), own


def test_the_law_input_is_made_a_block_of_readouts_at_a_time_as_the_whole_streams():
    """recon.learning.infer.LawInputs: blocks of readouts, each read with its windows' readouts around
    it, give the whole stream's law input (to float rounding), and blocks the keys have passed go."""
    from tespike.recon.learning.infer import LawInputs, law_input
    config = SensorConfig()
    c = _calibrated(config, EQ13, (5, 6), readouts=64)
    words = simulate_scene(config, np.random.default_rng(4).uniform(0, 0.05, (23, 5, 6)), seed=7, sensor=EQ13)
    whole = law_input(words, config, c).numpy()
    assert (whole != (law_input(words, config, dataclasses.replace(c, dark_law=np.zeros_like(c.dark_law),
                                                                   dark_tail=0.0)).numpy())).any()
    inputs = LawInputs(words, config, c, block=4)
    rows, cols = np.array([4, 0, 0, 2]), np.arange(6)[::-1]
    for key in range(23):
        times = np.clip(np.arange(9) + key - 4, 0, 22)
        got = inputs(times, rows, cols).numpy()
        assert np.allclose(got, whole[times][:, rows][:, :, cols], rtol=1e-6, atol=1e-9), key
        assert len(inputs.blocks) <= 4
    assert np.allclose(law_input(words, config, c, readouts=(5, 9)).numpy(), whole[5:9], rtol=1e-6, atol=1e-9)
