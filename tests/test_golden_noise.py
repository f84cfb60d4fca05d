"""Sensor non-idealities (golden.noise): the description, the maps of one sensor, the dark draws."""

import json

import numpy as np
import pytest

from tespike.golden.errors import InputError
from tespike.golden.light import dark_electrons
from tespike.golden.noise import Sensor, SensorNoise, load_noise, model_mean


def test_defaults_are_shot_noise_only():
    noise = SensorNoise()
    assert noise.is_ideal and not noise.has_maps
    maps = Sensor(noise, seed=3).maps((4, 5))
    assert np.array_equal(maps.gain, np.ones((4, 5))) and np.array_equal(maps.dark_scale, np.ones((4, 5)))


def test_maps_have_the_stated_statistics():
    noise = SensorNoise(dark_current="eq12", dsnu=0.3, hot_pixels=0.01, hot_factor=50.0, prnu=0.02)
    maps = Sensor(noise, seed=1).maps((400, 500))
    hot = maps.dark_scale > 10
    assert abs(hot.mean() - 0.01) < 0.002
    normal = maps.dark_scale[~hot]
    assert abs(normal.mean() - 1) < 0.01 and abs(normal.std() - 0.3) < 0.01
    assert abs(maps.gain.mean() - 1) < 0.001 and abs(maps.gain.std() - 0.02) < 0.001


def test_comparator_offset_scales_photo_and_dark_alike():
    noise = SensorNoise(dark_current="eq12", comparator_offset=0.1)
    maps = Sensor(noise, seed=2).maps((100, 100))
    assert np.array_equal(maps.gain, maps.dark_scale)
    assert maps.gain.min() >= 1 / 1.4 and maps.gain.max() <= 1 / 0.6
    assert abs(np.std(1 / maps.gain) - 0.1) < 0.005


def test_sensor_seed_fixes_the_maps_and_each_option_has_its_own():
    a = SensorNoise(dark_current="eq13", dsnu=0.2, prnu=0.05)
    b = SensorNoise(dark_current="eq13", dsnu=0.2, prnu=0.05, hot_pixels=0.1)
    m1, m2, m3 = Sensor(a, 7).maps((30, 30)), Sensor(a, 7).maps((30, 30)), Sensor(a, 8).maps((30, 30))
    assert np.array_equal(m1.gain, m2.gain) and not np.array_equal(m1.gain, m3.gain)
    assert np.array_equal(Sensor(b, 7).maps((30, 30)).gain, m1.gain)     # hot pixels leave PRNU alone


@pytest.mark.parametrize("shape", [(-2, 3), (0, 2), (1, 2, 3), (2.0, 3), "ab"])
def test_a_frame_shape_that_is_no_frame_is_refused(shape):
    """Sensor.maps / pixels and pixel_noise (numpy had refused a negative size in its words,
    and a frame without maps took any shape)."""
    from tespike.golden.noise import pixel_noise
    with_maps = Sensor(SensorNoise(prnu=0.01))
    for call in (lambda: with_maps.maps(shape), lambda: with_maps.pixels(shape),
                 lambda: Sensor().pixels(shape), lambda: pixel_noise(None, None, shape)):
        with pytest.raises(InputError, match=r"^sensor frame shape .*: (must be \(H, W\)|H and W must be)"):
            call()


def test_a_sensor_of_no_sensor_noise_is_refused():
    """(Sensor('eq12') had been taken, and failed later on the string's missing fields.)"""
    for noise in ("eq12", {"dark_current": "eq12"}, None):
        with pytest.raises(InputError, match=f"^sensor noise .*: must be a SensorNoise .*not {type(noise).__name__}$"):
            Sensor(noise, 0)


def test_scaled_dark_draws_and_unscaled_ones():
    assert np.array_equal(dark_electrons("eq12", (1000,), np.random.default_rng(5)),
                          dark_electrons("eq12", (1000,), np.random.default_rng(5), scale=None))
    scaled = dark_electrons("eq12", (200000,), np.random.default_rng(5), scale=np.full(200000, 3.0))
    assert abs(scaled.mean() - 1200) < 2 and abs(scaled.std() - 150) < 2


def test_eq13_mean_agrees_with_monte_carlo(rng):
    draws = dark_electrons("eq13", (2_000_000,), rng)
    assert abs(draws.mean() - model_mean("eq13")) < 4 * draws.std() / np.sqrt(draws.size) + 0.5
    assert model_mean("eq12") == 400.0 and model_mean(None) == 0.0


def test_json_round_trip_and_refusals(tmp_path):
    noise = SensorNoise(dark_current="eq12", dark_level=3, dsnu=0.1)
    path = tmp_path / "n.json"
    path.write_text(noise.to_json())
    assert load_noise(path) == noise
    for values, words in [({"dark_current": "eq12", "prnu": 0.9}, "prnu"),
                          ({"dark_current": "eq14"}, "eq14"),
                          ({"gain": 1}, "unknown key 'gain'"),
                          ({"dsnu": 0.1}, "need dark_current"),
                          ({"dark_current": "eq12", "dark_level": float("nan")}, "finite"),
                          ({"dark_current": "eq12", "hot_factor": True}, "hot_factor")]:
        path.write_text(json.dumps(values))
        with pytest.raises(InputError, match=words):
            load_noise(path)
    for text, words in (("{", "is not valid JSON"), ('{"dsnu": 0.1, "dsnu": 0.2}', "key 'dsnu' is given twice"),
                        ("[" * 100000 + "]" * 100000, "nested too deeply"),      # (RecursionError escaped)
                        ('{"dsnu": ' + "9" * 5000 + "}", "number too long"),     # (Python's digit limit)
                        ('{"prnu": 1' + "0" * 400 + "}", r"prnu = 1000\d*\.\.\.0+: must be in \[0, 0.5\]$"),
                        ('{"dark_current": null}', "dark_current = null"),        # (OverflowError escaped)
                        ('{"dark_current": "eq12", "dsnu": null}', "dsnu = null")):
        path.write_text(text)
        with pytest.raises(InputError, match=words):
            load_noise(path)
    path.write_bytes(b"\xff\xfe{")
    with pytest.raises(InputError, match="not readable JSON"):
        load_noise(path)
    with pytest.raises(InputError, match="sensor seed"):
        Sensor(noise, seed=-1)


def test_a_noise_file_setting_that_would_be_ignored_is_refused(tmp_path):
    """hot_factor without hot pixels changes nothing: a file giving one is refused (a file
    to_json wrote, which always holds the default, is not)."""
    from tespike.golden.noise import load_noise
    path = tmp_path / "n.json"
    path.write_text('{"dark_current": "eq12", "hot_factor": 50}')
    with pytest.raises(InputError, match="hot_factor = 50 .* needs hot_pixels > 0"):
        load_noise(path)
    path.write_text(SensorNoise(prnu=0.05).to_json())
    assert load_noise(path) == SensorNoise(prnu=0.05)


def test_settings_that_would_change_nothing_are_refused():
    """Each was accepted and changed no word (so --sensor-seed was ignored, and evaluate took two files
    of one sensor for two sensors)."""
    for keys, words in (({"dark_current": "eq12", "dsnu": 1e-300}, "dsnu = 1e-300: must be 0 or at least"),
                        ({"prnu": 5e-324}, "prnu"), ({"comparator_offset": 1e-7}, "comparator_offset"),
                        ({"dark_current": "eq12", "hot_pixels": 1e-12}, "hot_pixels"),
                        ({"dark_current": "eq12", "dark_level": 0.0}, "dark_level 0"),
                        ({"dark_current": "eq12", "hot_pixels": 0.1, "hot_factor": 1.0}, "hot_factor 1.0"),
                        # ... and just past the refused values: as inert (words identical to eq12 alone)
                        ({"dark_current": "eq12", "dark_level": 1e-300}, "dark_level 1e-300"),
                        ({"dark_current": "eq13", "dark_level": 9e-13}, "dark_level 9e-13"),
                        ({"dark_current": "eq12", "hot_pixels": 0.5, "hot_factor": 1 + 1e-13}, "hot_factor 1.0000")):
        with pytest.raises(InputError, match=words):
            SensorNoise(**keys)
    SensorNoise(dark_current="eq12", dsnu=1e-6, hot_pixels=1e-9, hot_factor=1.5)
    SensorNoise(dark_current="eq12", dark_level=1e-12, hot_pixels=0.1, hot_factor=1 + 1e-6)


def test_dark_electrons_of_an_extreme_hot_pixel_do_not_wrap(rng):
    """Legal settings (eq. 13 x 1e6, hot factor 1e6, DSNU 2) reached 1e19 electrons: the int64 cast came out
    negative and the simulators stopped with a traceback."""
    d = dark_electrons("eq13", (100000,), rng, scale=np.full(100000, 8e14))
    assert d.min() >= 0 and d.max() == 1 << 62


def test_model_mean_refuses_a_model_that_is_no_name_in_one_line():
    """A list was the cache's "unhashable type" traceback."""
    from tespike.golden.noise import model_mean
    with pytest.raises(InputError, match=r"^dark current model \['eq12'\]: must be a name \(none, eq12, eq13\) or None$"):
        model_mean(["eq12"])
    assert model_mean("none") == model_mean(None) == 0.0


def test_dark_electrons_refuses_an_rng_that_is_no_generator_in_one_line():
    """None or a seed had been an AttributeError of ``normal``."""
    for rng in (None, 3):
        with pytest.raises(InputError, match="^dark_electrons rng: must be a numpy Generator"):
            dark_electrons("eq12", (2,), rng)


def test_pixel_noise_refuses_counts_rows_and_noise_that_are_none_in_one_line():
    """``dark(-1, rng)`` was numpy's error and 2.5 a TypeError, ``rows(slice, 4)`` of 6 pixels a reshape
    error, ``mean_dark_electrons('eq12')`` an AttributeError."""
    from tespike.golden.noise import PixelNoise, SensorMaps, SensorNoise
    rng, maps = np.random.default_rng(0), PixelNoise(SensorNoise(), np.ones(6), np.ones(6))
    for n in (-1, 2.5):
        with pytest.raises(InputError, match=f"^dark electrons of {n!r} pixels: must be an integer >= 0$"):
            PixelNoise(SensorNoise(), None, None).dark(n, rng)
    with pytest.raises(InputError, match="^dark electrons of 5 pixels: these maps hold 6$"):
        maps.dark(5, rng)
    with pytest.raises(InputError, match="^width 4: must be an integer >= 1 dividing the 6 pixels$"):
        maps.rows(slice(0, 1), 4)
    with pytest.raises(InputError, match="^rows 3: must be a slice of the frame's rows$"):
        maps.rows(3, 2)
    with pytest.raises(InputError, match="^mean_dark_electrons: noise must be a SensorNoise, not str$"):
        SensorMaps(np.ones(2), np.ones(2)).mean_dark_electrons("eq12")
