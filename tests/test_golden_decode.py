import numpy as np
import pytest

from golden.config import SensorConfig
from golden.decode import decode_light, decode_spikes
from golden.errors import InputError


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


def test_ml_decode_and_refusal():
    c = SensorConfig(mode="ml")
    assert np.array_equal(decode_spikes(np.arange(256), c), np.arange(256))
    with pytest.raises(InputError):
        decode_spikes(np.array([256]), c)
