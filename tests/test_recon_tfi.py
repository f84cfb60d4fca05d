"""recon.tfi: spike-interval light, with hand-worked streams and the documented edge rules."""

import pytest
import torch

from golden.config import DESIGN_ELECTRONS, SensorConfig
from recon.stream import decode_light
from recon.tfi import tfi

TE = SensorConfig()                 # theta 175, d = 4
ML = SensorConfig(mode="ml")        # theta 328


def run(words, config, search="stream", radius=4):
    w = torch.tensor(words, dtype=torch.int64).view(-1, 1)
    light = decode_light(w, config)
    return tfi(light, w != 0, config.threshold / DESIGN_ELECTRONS, radius, search)[:, 0]


def approx(values, unit):
    return pytest.approx([v * unit for v in values], rel=1e-12)


def test_te_counts_and_tail():
    u = TE.threshold / DESIGN_ELECTRONS
    out = run([0, 0, 3, 0, 0, 0, 1, 0, 0], TE)
    # k 0..2: 3 spikes since the stream start; k 3..6: 1 spike over 4 readouts;
    # tail: min(previous segment u/4, bound u / 2)
    assert out.tolist() == approx([1, 1, 1, 1 / 4, 1 / 4, 1 / 4, 1 / 4, 1 / 4, 1 / 4], u)


def test_te_overflow_codes_are_their_decoded_level():
    u = TE.threshold / DESIGN_ELECTRONS
    ovf2 = (1 << TE.d) | 2                         # 16 * 15 / 2 = 120 spikes
    out = run([ovf2, ovf2, 0, 5], TE)
    assert out.tolist() == approx([120, 120, 5 / 2, 5 / 2], u)


def test_tail_bound_below_previous_segment():
    u = TE.threshold / DESIGN_ELECTRONS
    out = run([4, 0, 0, 0, 0, 0, 0, 0], TE)
    assert out.tolist() == approx([4] + [1 / 7] * 7, u)


def test_all_zero_gives_documented_floor():
    for config in (TE, ML):
        u = config.threshold / DESIGN_ELECTRONS
        assert run([0] * 5, config).tolist() == approx([1 / 5] * 5, u)


def test_ml_hand_worked():
    u = ML.threshold / DESIGN_ELECTRONS
    assert run([0, 0, 2, 0, 5], ML).tolist() == approx([2 / 3] * 3 + [5 / 2] * 2, u)
    assert run([255] * 3, ML).tolist() == approx([255] * 3, u)


def test_window_search():
    u = TE.threshold / DESIGN_ELECTRONS
    out = run([0, 0, 0, 0, 0, 0, 2, 0, 0, 0, 0], TE, search="window", radius=1)
    # k=0: no code in [0, 1], p = -1 (stream start): bound u / 2; k=1..4: p = window start - 1,
    # no n in the window: u / 3 (one spike over the window); k=5: p = 3, n = 6 -> 2u / 3;
    # k=6: p = 4 -> u; k=7: min(value at 6 = u, u / 2); k=8, 9: u / 3; k=10: end = 10, p = 8: u / 2
    assert out.tolist() == approx([1 / 2, 1 / 3, 1 / 3, 1 / 3, 1 / 3, 2 / 3, 1, 1 / 2, 1 / 3, 1 / 3, 1 / 2], u)
    # the whole-stream search sees the long interval instead; tail: min(2u/7, u/4)
    assert run([0, 0, 0, 0, 0, 0, 2, 0, 0, 0, 0], TE).tolist() == approx([2 / 7] * 7 + [1 / 4] * 4, u)


def test_stream_mean_is_decoded_mean_when_stream_ends_on_a_code(rng):
    codes = torch.tensor(rng.choice([0, 0, 0, 1, 2, 7, (1 << TE.d) | 3], size=(40, 6)))
    codes[-1] = 1
    light = decode_light(codes, TE)
    out = tfi(light, codes != 0, TE.threshold / DESIGN_ELECTRONS, 4)
    assert torch.allclose(out.mean(0), light.mean(0), rtol=1e-12)


def test_bad_search():
    with pytest.raises(ValueError, match="search"):
        tfi(torch.zeros(3, 1), torch.zeros(3, 1, dtype=torch.bool), 1.0, 1, "both")
