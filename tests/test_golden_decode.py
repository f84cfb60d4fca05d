import numpy as np
import pytest

from tespike.golden.config import SensorConfig
from tespike.golden.decode import check_words, decode_light, decode_spikes, legal_words
from tespike.golden.sensor import simulate
from tespike.golden.errors import InputError


def test_te_decode_every_legal_word():
    c = SensorConfig()
    words = np.array(list(range(16)) + [(1 << 4) | m for m in range(1, 16)])
    r = decode_spikes(words, c)
    assert np.array_equal(r[:16], np.arange(16))
    assert np.allclose(r[16:], 16 * 15 / np.arange(1, 16))
    assert decode_light(np.array([(1 << 4) | 1]), c)[0] == pytest.approx(240 * 175 / 42000)


@pytest.mark.parametrize("word", [16, 32, (1 << 4) | 0])
def test_te_illegal_words_refused(word):
    with pytest.raises(InputError, match="not a legal TE word"):
        decode_spikes(np.array([word]), SensorConfig())


def test_a_refusal_names_the_index_in_the_array_a_tile_came_from(monkeypatch):
    """The index is the word's own (readout, row, column), across the slices the check runs in,
    and, with ``origin``, where the tile lies in its frame."""
    import tespike.golden.decode as decode
    monkeypatch.setattr(decode, "CHECK_CHUNK_WORDS", 20)               # slices of one readout
    words = np.zeros((4, 3, 5), np.uint8)
    words[2, 1, 3] = 16
    with pytest.raises(InputError, match=r"at index \(2, 1, 3\)"):
        check_words(words, SensorConfig())
    with pytest.raises(InputError, match=r"at index \(2, 9, 43\)"):
        check_words(words, SensorConfig(), origin=(0, 8, 40))


def test_ml_decode_and_refusal():
    c = SensorConfig(mode="ml")
    assert np.array_equal(decode_spikes(np.arange(256), c), np.arange(256))
    with pytest.raises(InputError, match=r"readout word 256 .*not a legal ML word.*its words are 0\.\.255"):
        decode_spikes(np.array([256]), c)


def _reachable(config):
    """The words one pixel can emit, by hand: at most one spike a pixel clock (SPEC section 3), so
    a TE count is at most L and an overflow at CCC m needs 2^b1 spikes within m * F clocks; an ML
    count is at most L; the msb counter keeps count - 2^(bit_length - 1) and gains at most L an
    interval, up to the fixed point of its largest remainder."""
    L = config.clocks_per_readout
    if config.is_te:
        earliest = (config.p_max - 1) // config.clocks_per_tick + 1
        return list(range(min(config.p_max - 1, L) + 1)) + \
            [(1 << config.d) | m for m in range(earliest, config.alpha + 1)]
    if not config.is_msb:
        return list(range(min(config.ml_max, L) + 1))
    rest = 0
    while True:
        count = min(config.ml_max, rest + L)
        half = 1 << (count.bit_length() - 1)
        largest = max(count - half, half // 2 - 1)
        if largest <= rest:
            return list(range(count.bit_length() + 1))
        rest = largest


@pytest.mark.parametrize("config", [
    SensorConfig(b1=2, b2=2), SensorConfig(b1=3, b2=2, clocks_per_tick=2), SensorConfig(b1=3, b2=3, clocks_per_tick=1),
    SensorConfig(mode="ml", b1=2, b2=2, ml_bits=3), SensorConfig(mode="ml", b1=2, b2=2, ml_bits=5),
    SensorConfig(mode="ml", b1=2, b2=2, ml_bits=5, ml_readout="msb"),
    SensorConfig(mode="ml", b1=2, b2=2, ml_bits=8, ml_readout="msb"),
    SensorConfig(mode="ml", b1=1, b2=2, clocks_per_tick=5, ml_bits=8, ml_readout="msb"),
], ids=str)
def test_the_golden_sensor_emits_legal_words_and_all_it_can_reach(config):
    """Pixels firing with every probability a clock (0 to 1, sustained for the msb counter's carry)
    emit exactly the words one spike a clock allows: all legal (SPEC section 4's set), which is
    wider where L is short (counts above L, overflows earlier than 2^b1 clocks allow)."""
    rng = np.random.default_rng(7)
    L, K = config.clocks_per_readout, 40
    fires = rng.random((K * L, 8, 64)) < np.linspace(0.0, 1.0, 64)
    words = simulate(config, np.where(fires, config.threshold, 0).astype(np.int64))
    assert np.unique(words).tolist() == _reachable(config)
    assert set(_reachable(config)) <= set(legal_words(config).tolist())


def test_estimators_on_hand_worked_words():
    """TE b1 = b2 = 4 (alpha 15, F 16, L 240): flag-1 words decode by the centred rules."""
    from tespike.golden.decode import ESTIMATORS
    c = SensorConfig()
    words = np.array([0, 7, 15, 16 | 1, 16 | 2, 16 | 3, 16 | 15])
    assert list(ESTIMATORS)[0] == "ratio"
    assert np.allclose(decode_spikes(words, c, "ratio"), [0, 7, 15, 240, 120, 80, 16])
    # midpoint: 16 * 15 / (m - 1/2), at most L = 240
    assert np.allclose(decode_spikes(words, c, "midpoint"), [0, 7, 15, 240, 160, 96, 240 / 14.5])
    # residual: 15.5 * 15 / (m - 1/2), at most 240
    assert np.allclose(decode_spikes(words, c, "residual"), [0, 7, 15, 240, 155, 93, 232.5 / 14.5])
    # a clock divider longer than 2^b1 lets m = 1 go beyond 2^b1 alpha, still capped at L
    wide = SensorConfig(b1=2, b2=2, clocks_per_tick=16)                # alpha 3, L 48
    assert decode_spikes(np.array([4 | 1]), wide, "midpoint")[0] == 24.0
    assert decode_spikes(np.array([4 | 1]), wide, "ratio")[0] == 12.0
    ml = SensorConfig(mode="ml")
    for name in ("ratio", "midpoint", "residual"):
        assert np.array_equal(decode_spikes(np.arange(256), ml, name), np.arange(256))


def test_unknown_estimator_refused():
    with pytest.raises(InputError, match="unknown estimator 'best'"):
        decode_spikes(np.array([1]), SensorConfig(), "best")


def test_residual_estimator_less_biased_than_ratio_on_constant_light():
    """Seeded constant Poisson light over the TE overflow range, through the cycle-exact engine."""
    from tespike.golden.dynamic_range import estimator_error
    c = SensorConfig()
    light = np.logspace(np.log10(16 * 175 / 42000), 0, 25)      # 2^b1 .. 2^b1 alpha spikes per readout
    ratio_bias, _ = estimator_error(c, "ratio", light, readouts=30, replicas=2, seed=3)
    residual_bias, _ = estimator_error(c, "residual", light, readouts=30, replicas=2, seed=3)
    assert np.abs(residual_bias).mean() < 0.8 * np.abs(ratio_bias).mean()
    assert (ratio_bias < 0.01).all()          # the paper's rule reads every overflow code low


def test_a_refused_word_is_named_as_stored():
    """A uint64 word above 2^63 is named with its own value (the int64 view read -1)."""
    from tespike.golden.decode import check_words
    for value in (2 ** 64 - 1, 2 ** 63 + 17):
        with pytest.raises(InputError, match=f"readout word {value} at index \\(0, 0, 1\\)"):
            check_words(np.array([[[0, value]]], np.uint64), SensorConfig())


@pytest.mark.parametrize("config", [SensorConfig(), SensorConfig(b1=2, b2=4, alpha=9), SensorConfig(b1=1, b2=1, alpha=1),
                                    SensorConfig.preset("ml"), SensorConfig.preset("ml-msb"),
                                    SensorConfig(mode="ml", ml_readout="msb", ml_bits=3)])
def test_every_illegal_word_is_refused_where_the_block_is_otherwise_legal(config):
    """check_words' quick test (the block's smallest and largest word, then each hole between them)
    decides nothing it should not: each word of the word width that is not legal, placed once among
    legal words spanning the whole set, is refused at its index; all-legal blocks pass."""
    from tespike.golden.decode import check_words, legal_words
    legal = legal_words(config)
    block = np.resize(legal, 3 * 7 * 11).reshape(3, 7, 11).astype(np.uint16)
    check_words(block, config)
    for bad in sorted(set(range(1 << (config.word_bits + 1))) - set(legal.tolist())):
        words = block.copy()
        words[2, 5, 3] = bad
        with pytest.raises(InputError, match=f"readout word {bad} at index \\(2, 5, 3\\)"):
            check_words(words, config)
