import dataclasses
import json

import pytest

from tespike.golden.config import KEYS, SensorConfig, load_config
from tespike.golden.errors import ConfigError


def test_te_defaults_follow_spec():
    c = SensorConfig()
    assert c.to_dict() == {"mode": "te", "b1": 4, "b2": 4, "alpha": 15, "clocks_per_tick": 16,
                           "threshold": 175, "acc_bits": 9, "input_bits": 16, "ml_bits": 8,
                           "ml_readout": "count"}
    assert c.clocks_per_readout == 240 and c.word_bits == 5


def test_ml_defaults_follow_spec():
    c = SensorConfig.preset("ml")
    assert c.threshold == 328 and c.acc_bits == 10 and c.word_bits == 8


def test_ml_msb_preset_follows_spec():
    c = load_config("ml-msb")
    assert c == SensorConfig(mode="ml", ml_readout="msb") and c.is_msb
    assert c.threshold == 328 and c.word_bits == 4          # bit_length(8)
    assert SensorConfig(mode="ml", ml_readout="msb", ml_bits=1).word_bits == 1
    assert SensorConfig(mode="ml", ml_readout="msb", ml_bits=16).word_bits == 5
    assert SensorConfig.from_json(c.to_json()) == c


def test_ml_readout_refusals_name_the_key():
    with pytest.raises(ConfigError, match="ml_readout.*mode"):
        SensorConfig(mode="te", ml_readout="msb")
    with pytest.raises(ConfigError, match="ml_readout"):
        SensorConfig.from_dict({"mode": "ml", "ml_readout": "lsb"})
    with pytest.raises(ConfigError, match="ml_readout"):
        SensorConfig.from_dict({"mode": "ml", "ml_readout": 1})


def test_config_without_ml_readout_reads_as_count():
    old = {"mode": "ml", "b1": 4, "b2": 4, "alpha": 15, "clocks_per_tick": 16, "threshold": 328,
           "acc_bits": 10, "input_bits": 16, "ml_bits": 8}
    assert SensorConfig.from_dict(old).ml_readout == "count"


def test_a_recorded_configuration_must_hold_every_key_but_those_added_later():
    """SPEC section 6: a stream's config is the full configuration used; only ml_readout, added
    after streams were first written, may be missing (and reads as "count")."""
    whole = SensorConfig(mode="ml").to_dict()
    del whole["ml_readout"]
    assert SensorConfig.from_json(json.dumps(whole), whole=True).ml_readout == "count"
    del whole["b1"], whole["threshold"]
    assert SensorConfig.from_json(json.dumps(whole)) == SensorConfig(mode="ml")     # a config file may omit keys
    with pytest.raises(ConfigError, match="lacks keys 'b1', 'threshold'"):
        SensorConfig.from_json(json.dumps(whole), whole=True)


def test_a_threshold_too_large_for_any_accumulator_is_named_itself():
    assert SensorConfig(threshold=2 ** 61 - 1).acc_bits == 62
    with pytest.raises(ConfigError, match=r"'threshold' = .*must be < 2\^61"):
        SensorConfig(threshold=2 ** 61)


def test_dependent_defaults():
    c = SensorConfig(b1=2, b2=3)
    assert (c.alpha, c.clocks_per_tick, c.threshold) == (7, 4, 42000 // 28)
    assert SensorConfig(b1=16, b2=16, alpha=65535, clocks_per_tick=1).threshold == 1


@pytest.mark.parametrize("changes, key", [
    ({"b1": 0}, "b1"), ({"b1": 17}, "b1"), ({"b2": 17}, "b2"), ({"alpha": 16}, "alpha"),
    ({"alpha": 0}, "alpha"), ({"clocks_per_tick": 0}, "clocks_per_tick"),
    ({"clocks_per_tick": 2 ** 24}, "clocks_per_tick"), ({"threshold": 0}, "threshold"),
    ({"acc_bits": 63}, "acc_bits"), ({"threshold": 8, "acc_bits": 3}, "acc_bits"),
    ({"threshold": 2 ** 70}, "threshold"), ({"threshold": 2 ** 61}, "threshold"),
    ({"input_bits": 33}, "input_bits"), ({"ml_bits": 0}, "ml_bits"), ({"b1": 4.0}, "b1"),
    ({"b1": True}, "b1"), ({"mode": "xx"}, "mode"), ({"colour": 1}, "colour"),
])
def test_refusals_name_key_and_value(changes, key):
    with pytest.raises(ConfigError) as info:
        SensorConfig.from_dict(changes)
    message = str(info.value)
    assert repr(key) in message and repr(list(changes.values())[-1]) in message


def test_json_round_trip(tmp_path):
    c = SensorConfig(mode="ml", ml_bits=6, b1=3)
    path = tmp_path / "c.json"
    c.save(path)
    assert load_config(path) == c
    assert set(json.loads(path.read_text())) == set(KEYS)
    assert load_config("te") == SensorConfig()


def test_bad_json_and_missing_file(tmp_path):
    (tmp_path / "bad.json").write_text("{nope")
    with pytest.raises(ConfigError, match="not valid JSON"):
        load_config(tmp_path / "bad.json")
    with pytest.raises(ConfigError, match="missing.json.*does not exist"):
        load_config(tmp_path / "missing.json")
    with pytest.raises(ConfigError, match=r"'ml_msb' is neither a preset \(te, ml, ml-msb\)"):
        load_config("ml_msb")                       # a mistyped preset names the presets
    (tmp_path / "list.json").write_text("[1]")
    with pytest.raises(ConfigError, match="JSON object"):
        load_config(tmp_path / "list.json")


def test_differences_name_every_key_in_spec_order_in_one_wording():
    te = SensorConfig.preset("te")
    assert te.key_differences(te) == [] and te.differences_text(te, "a", "b") is None
    other = dataclasses.replace(te, threshold=100, acc_bits=10)
    assert te.key_differences(other) == [("threshold", 175, 100), ("acc_bits", 9, 10)]
    assert te.differences_text(other, "X", "Y") == "threshold = 175 in X, 100 in Y; acc_bits = 9 in X, 10 in Y"
    assert SensorConfig.preset("ml").key_differences(SensorConfig.preset("ml-msb")) == [("ml_readout", "count", "msb")]


def test_describe_shows_keys_and_values_apart():
    """str() glues them (b14 for b1 = 4, the dataset store's names); messages use describe()."""
    assert SensorConfig.preset("te").describe().startswith("te (b1=4, b2=4, alpha=15, clocks_per_tick=16")
    assert SensorConfig.preset("ml-msb").describe().startswith("ml-msb (b1=4") and "ml_bits=8" in \
        SensorConfig.preset("ml-msb").describe()


def test_a_clock_structure_too_long_from_defaults_says_they_are_defaults():
    """b1 = b2 = 16 alone: the refusal named clocks_per_tick and alpha, keys never given."""
    with pytest.raises(ConfigError, match=r"alpha is its default 2\^b2 - 1; clocks_per_tick is its default 2\^b1"):
        SensorConfig(b1=16, b2=16)
    with pytest.raises(ConfigError, match=r"must be <= 2\^24 = 16777216$"):
        SensorConfig(b1=16, b2=16, alpha=300, clocks_per_tick=65536)


def test_the_largest_threshold_is_named_with_the_acc_bits_that_allow_it():
    """'must be < 2^61' read as the rule, yet 2^62 - 1 runs with acc_bits = 62 given."""
    big = (1 << 62) - 1
    with pytest.raises(ConfigError, match="with the default acc_bits .* up to 2\\^62 - 1 with acc_bits = 62"):
        SensorConfig(threshold=big)
    assert SensorConfig(threshold=big, acc_bits=62).threshold == big


def test_top_light_is_what_a_pixel_firing_every_clock_reads():
    """The most light a word can tell: 1.0 for the TE preset (its top code is the design light), the
    ML presets' 240 spikes of 328 e-; below 1 for legal configurations that saturate early."""
    from tespike.golden.config import SensorConfig
    assert SensorConfig.preset("te").top_light == 1.0
    assert SensorConfig.preset("ml").top_light == SensorConfig.preset("ml-msb").top_light == 240 * 328 / 42000
    assert SensorConfig.from_dict({"mode": "ml", "ml_bits": 12}).top_light == 240 * 20 / 42000
    assert SensorConfig.from_dict({"mode": "te", "clocks_per_tick": 1}).top_light == 15 * 175 / 42000
    assert SensorConfig.from_dict({"mode": "te", "input_bits": 4}).top_light == 240 * 15 / 42000
    assert SensorConfig.from_dict({"mode": "ml", "ml_bits": 3, "threshold": 5000}).top_light == 7 * 5000 / 42000


def _golden_entry_points():
    """Each public golden entry point that takes a configuration, called with ``config``."""
    import numpy as np

    from tespike.golden import dynamic_range as dr
    from tespike.golden.decode import decode_light, decode_spikes
    from tespike.golden.fastsim import SceneSimulator, scene_stimulus, simulate_scene
    from tespike.golden.fastsim.scene import stripe_simulators
    from tespike.golden.io import save_stream
    from tespike.golden.sensor import PixelArrayModel, simulate
    from tespike.golden.stimulus import poisson_stimulus
    words, light = np.zeros((1, 2, 2), np.uint8), np.full((1, 2, 2), 0.1)
    return {
        "decode_spikes": lambda config: decode_spikes(words, config),
        "decode_light": lambda config: decode_light(words, config),
        "simulate": lambda config: simulate(config, np.zeros((240, 2, 2), np.int64)),
        "PixelArrayModel": lambda config: PixelArrayModel(config, (2, 2)),
        "save_stream": lambda config: save_stream("never-written.npz", words, config),
        "simulate_scene": lambda config: simulate_scene(config, light),
        "stripe_simulators": lambda config: stripe_simulators(config, (2, 2)),
        "scene_stimulus": lambda config: scene_stimulus(config, light),
        "SceneSimulator": lambda config: SceneSimulator(config, (2, 2)),
        "poisson_stimulus": lambda config: poisson_stimulus(config, light, 0),
        "formula_db": lambda config: dr.formula_db(config),
        "constant_light_words": lambda config: dr.constant_light_words(config, np.ones(1), 1),
        "measure": lambda config: dr.measure(config),
        "estimator_error": lambda config: dr.estimator_error(config, "ratio", np.ones(1)),
    }


@pytest.mark.parametrize("name", list(_golden_entry_points()))
@pytest.mark.parametrize("not_config", ["te", {"mode": "te"}, None])
def test_library_entry_points_refuse_what_is_no_configuration(name, not_config, tmp_path, monkeypatch):
    """A preset's name or a dict where the object belongs is refused in one line naming the entry
    point (it was numpy's or Python's AttributeError on the first field read), and nothing is written."""
    monkeypatch.chdir(tmp_path)
    call = _golden_entry_points()[name]
    with pytest.raises(ConfigError, match=rf"^{name}: configuration must be a SensorConfig "
                                          rf"\(SensorConfig.preset\(name\) or load_config\(path\)\), "
                                          rf"not {type(not_config).__name__}$"):
        call(not_config)
    assert not list(tmp_path.iterdir())
    call(SensorConfig())                                # the same call with a configuration runs


def test_load_config_takes_a_name_a_path_or_a_configuration_and_refuses_the_rest(tmp_path):
    """(A number or a dict had been os.fspath's TypeError.)"""
    path = tmp_path / "C.json"
    path.write_text('{"mode": "ml"}')
    assert load_config(path) == load_config(str(path)) == SensorConfig(mode="ml")
    assert load_config(SensorConfig(b1=3)) == SensorConfig(b1=3)
    with pytest.raises(ConfigError, match=r"^configuration 3: must be a preset's name or a JSON file's path, not int$"):
        load_config(3)
    with pytest.raises(ConfigError, match=r"not dict \(a dict of keys: SensorConfig.from_dict\)$"):
        load_config({"mode": "te"})


def test_the_two_tests_behind_the_refusals_of_numbers():
    """golden.errors.is_count (counts, sizes, seeds) and is_positive_number (lights, peaks, constants,
    durations): Python's and numpy's numbers pass, bools, strings, NaN and infinities do not."""
    import numpy as np

    from tespike.golden.errors import is_count, is_positive_number
    assert all(is_count(v, 1) for v in (1, np.int64(3), np.uint8(2)))
    assert not any(is_count(v, 1) for v in (0, True, 1.0, "1", np.float64(2), None))
    assert all(is_positive_number(v) for v in (1, 0.5, np.float32(2.5), np.int16(3), 1e300))
    assert not any(is_positive_number(v) for v in (0, -1.0, True, np.bool_(True), float("nan"), float("inf"),
                                                   "1", None, np.array([1.0])))


def test_a_metrics_peak_of_true_is_refused():
    """(is_positive_number: a peak of True had been taken as 1.)"""
    import numpy as np

    from tespike.recon.metrics import psnr_mu
    with pytest.raises(ValueError, match=r"^peak = True: must be a finite number > 0$"):
        psnr_mu(np.ones((1, 4, 4)), np.ones((1, 4, 4)), peak=True)


def test_a_configuration_method_refuses_what_is_no_text_name_or_configuration_in_one_line():
    """``from_json(3)`` was json's TypeError naming no input, ``preset(['te'])`` an "unhashable type",
    and ``key_differences('ml')`` an AttributeError of the first key."""
    with pytest.raises(ConfigError, match="^configuration: JSON must be text, not int$"):
        SensorConfig.from_json(3)
    with pytest.raises(ConfigError, match=r"^unknown preset \['te'\]: must be one of"):
        SensorConfig.preset(["te"])
    for call in (lambda: SensorConfig().key_differences("ml"), lambda: SensorConfig().differences_text("ml", "a", "b")):
        with pytest.raises(ConfigError, match="^key_differences: configuration must be a SensorConfig"):
            call()
