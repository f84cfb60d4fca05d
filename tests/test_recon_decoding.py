"""tespike.recon.decoding: lookup-table decoding equals golden.decode on every code; sub-streams (eq. 4)."""

import numpy as np
import pytest
import torch

import tespike.golden.decode as gd
from tespike.golden.config import SensorConfig
from tespike.golden.errors import InputError
from tespike.recon import decoding
from tespike.recon.learning import span
from tespike.recon.learning.layers import substreams
from tests.configs import EDGE_CONFIGS, MSB_EDGE_CONFIGS

WIDE_CONFIGS = [
    SensorConfig(b1=16, b2=16, clocks_per_tick=1),       # 17-bit words: the largest table
    SensorConfig(b1=16, b2=1),
    SensorConfig(b1=1, b2=16, alpha=12345),
    SensorConfig(mode="ml", ml_bits=16),
    SensorConfig(mode="ml", ml_readout="msb"),           # msb words: the msb index 0..B
    SensorConfig(mode="ml", ml_bits=16, ml_readout="msb"),
]
CONFIGS = EDGE_CONFIGS + WIDE_CONFIGS + MSB_EDGE_CONFIGS


def _golden_legal(code: int, config) -> bool:
    try:
        gd.check_words(np.array([code]), config)
        return True
    except InputError:
        return False


@pytest.mark.parametrize("config", CONFIGS, ids=str)
def test_table_equals_golden_on_every_code(config):
    codes = np.arange(1 << config.word_bits)
    light, spikes, legal = decoding.code_tables(config)
    assert light.shape == spikes.shape == legal.shape == codes.shape
    ok = codes[legal]
    assert np.array_equal(light[ok], gd.decode_light(ok, config))          # bit-equal float64
    assert np.array_equal(spikes[ok], gd.decode_spikes(ok, config))
    # the torch gather gives the same numbers
    assert torch.equal(decoding.decode_light(ok, config), torch.from_numpy(gd.decode_light(ok, config)))
    assert torch.equal(decoding.decode_spikes(ok, config), torch.from_numpy(gd.decode_spikes(ok, config)))
    # legality agrees with golden's check_words code by code (all codes on small words,
    # a random sample of illegal ones on the widest)
    illegal = codes[~legal]
    if config.word_bits > 10:
        illegal = np.random.default_rng(1).choice(illegal, min(500, illegal.size), replace=False) \
            if illegal.size else illegal
        sample = np.concatenate([illegal, ok[:: max(1, ok.size // 500)]])
    else:
        sample = codes
    for code in sample:
        assert _golden_legal(int(code), config) == bool(legal[code]), code
    assert np.array_equal(codes[legal], gd.legal_words(config))     # (which the golden sensor emits: test_golden_decode)


@pytest.mark.parametrize("config", CONFIGS[:6] + MSB_EDGE_CONFIGS[:3], ids=str)
def test_every_illegal_code_refused(config):
    _, _, legal = decoding.code_tables(config)
    for code in np.flatnonzero(~legal)[:50]:
        with pytest.raises(InputError, match=f"readout word {code} at index"):
            decoding.decode_light(np.array([[[0, code]]]), config)
    for code in (-1, 1 << config.word_bits, 1 << 40):
        with pytest.raises(InputError, match="not a legal"):
            decoding.decode_light(np.array([code], np.int64), config)


@pytest.mark.parametrize("config", CONFIGS, ids=str)
def test_decode_random_stream_equals_golden(config, rng):
    codes = gd.legal_words(config)
    words = rng.choice(codes, size=(5, 3, 4))
    assert np.array_equal(decoding.decode_light(words, config).numpy(), gd.decode_light(words, config))
    assert decoding.decode_light(words, config, dtype=torch.float32).dtype == torch.float32


def test_non_integer_words_refused():
    config = SensorConfig()
    with pytest.raises(InputError, match="not an integer"):
        decoding.decode_light(np.zeros((2, 2, 2), np.float32), config)
    with pytest.raises(InputError, match="not an integer"):
        decoding.decode_light(torch.zeros((2, 2, 2)), config)


def test_key_span_substreams_are_eq4():
    """The network's sub-streams of a key span: eq. 4 inside the stream, the last readout repeated past its end."""
    s = torch.arange(20.0).view(20, 1, 1)
    inner = substreams(s[span.key_span(20, 10, 9)][None], 3, 3, 3)[0, :, :, 0, 0]
    assert inner.tolist() == [[6, 7, 8], [9, 10, 11], [12, 13, 14]]          # the middle one centred on 10
    edge = substreams(s[span.key_span(20, 18, 9)][None], 3, 3, 3)[0, :, :, 0, 0]
    assert edge.tolist() == [[14, 15, 16], [17, 18, 19], [19, 19, 19]]
    assert span.span_inside(20, 18, 9).tolist() == [True] * 6 + [False] * 3


def test_msb_table_is_the_msb_worth():
    """ML msb (eq. 10): codes 0..B only, code j > 0 is 2^(j - 1) spikes; 9 and up are refused."""
    config = SensorConfig.preset("ml-msb")
    assert gd.legal_words(config).tolist() == list(range(9))
    assert decoding.decode_spikes(np.arange(9), config).tolist() == [0, 1, 2, 4, 8, 16, 32, 64, 128]
    with pytest.raises(InputError, match="readout word 9 at index"):
        decoding.decode_light(np.array([3, 9]), config)


@pytest.mark.parametrize("dtype", [torch.int64, torch.uint8, torch.bool, torch.complex64, np.float32, "float32"],
                         ids=str)
def test_a_dtype_that_is_no_real_torch_float_is_refused_in_one_line(dtype):
    """An integer dtype had cut the decoded light to whole numbers (0.0625 -> 0), uint8 wrapped the
    spikes, bool made every value True; a numpy dtype or a name was torch's TypeError."""
    words = np.array([1, 15, 17, 31])
    for decode in (decoding.decode_light, decoding.decode_spikes):
        with pytest.raises(InputError, match=r"^dtype = .*: must be a torch floating type"):
            decode(words, SensorConfig(), dtype=dtype)


def test_a_device_or_estimator_it_cannot_use_is_refused_in_one_line():
    """A misspelt device was torch's RuntimeError; an estimator given as a list, the "unhashable type"
    of a dictionary, in torch and in golden alike."""
    words = np.array([1, 15, 17, 31])
    with pytest.raises(InputError, match="^device = 'gpu9': not a usable torch device"):
        decoding.decode_light(words, SensorConfig(), device="gpu9")
    for decode in (decoding.decode_light, decoding.decode_spikes, gd.decode_light, gd.decode_spikes):
        with pytest.raises(InputError, match=r"^unknown estimator \['ratio'\] \(known: ratio, midpoint, residual\)$"):
            decode(words, SensorConfig(), estimator=["ratio"])


def test_golden_word_helpers_refuse_a_preset_name_in_one_line():
    """legal_words, check_words and spikes_to_light read fields of the configuration: a preset's name
    was an AttributeError, a list an "unhashable type"."""
    from tespike.golden.errors import ConfigError
    for call, what in ((lambda c: gd.legal_words(c), "legal_words"),
                       (lambda c: gd.check_words(np.zeros(3, np.uint8), c), "check_words"),
                       (lambda c: gd.spikes_to_light(np.ones(3), c), "spikes_to_light")):
        for config in ("te", ["te"]):
            with pytest.raises(ConfigError, match=f"^{what}: configuration must be a SensorConfig"):
                call(config)
    with pytest.raises(InputError, match="^spikes: must be numbers, not str$"):
        gd.spikes_to_light("abc", SensorConfig())
