"""tespike.recon.tfi: spike-interval light, with hand-worked streams and the documented edge rules."""

import numpy as np
import pytest
import torch

from tespike.golden.config import DESIGN_ELECTRONS, SensorConfig
from tespike.recon.decoding import decode_light
from tespike.recon.tfi import tfi

TE = SensorConfig()                 # theta 175, d = 4
ML = SensorConfig(mode="ml")        # theta 328
MSB = SensorConfig.preset("ml-msb")  # theta 328, words 0..8 (2^(word - 1) spikes)


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
    for config in (TE, ML, MSB):
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


def test_tail_takes_the_lower_previous_segment_in_both_searches():
    u = TE.threshold / DESIGN_ELECTRONS
    # k 1..4: one spike over 4 readouts; k 5 (tail): min(u / 4, one spike over 1 readout)
    assert run([1, 0, 0, 0, 1, 0], TE).tolist() == approx([1, 1 / 4, 1 / 4, 1 / 4, 1 / 4, 1 / 4], u)
    out = run([1, 0, 0, 0, 1, 0], TE, search="window", radius=3)
    assert out.tolist() == approx([1, 1 / 4, 1 / 4, 1 / 4, 1 / 4, 1 / 4], u)
    # window radius 1: k 5 sees p = 4, whose own window gives u / 2 (p >= 4 - 2)
    out = run([1, 0, 0, 0, 1, 0], TE, search="window", radius=1)
    assert out[5].item() == pytest.approx(u / 2, rel=1e-12)


def reference_tfi(light, nonzero, u, radius, search):
    """The rule of recon.tfi written as plain loops over one pixel's readouts."""
    K = len(light)
    out = []
    for k in range(K):
        lo = k - radius - 1 if search == "window" else -1
        end = min(k + radius, K - 1) if search == "window" else K - 1
        p = max([j for j in range(k) if nonzero[j]] + [-1, lo])
        n = next((j for j in range(k, end + 1) if nonzero[j]), None)
        if n is not None:
            out.append(light[n] / (n - p))
            continue
        bound = u / (end - p)
        if p >= 0 and (search == "stream" or p >= k - radius):
            lo_p = p - radius - 1 if search == "window" else -1
            pp = max([j for j in range(p) if nonzero[j]] + [-1, lo_p])
            bound = min(bound, light[p] / (p - pp))
        out.append(bound)
    return out


@pytest.mark.parametrize("search", ["stream", "window"])
@pytest.mark.parametrize("K,radius,density", [(1, 4, 0.5), (2, 0, 0.5), (30, 2, 0.2), (30, 4, 0.05),
                                              (25, 40, 0.1), (40000, 4, 0.3)])
def test_equals_plain_loop_reference(search, K, radius, density, rng):
    pixels = 1 if K > 1000 else 5
    nonzero = rng.random((K, pixels)) < density
    light = np.where(nonzero, rng.uniform(0.01, 2.0, (K, pixels)), 0.0)
    out = tfi(torch.from_numpy(light), torch.from_numpy(nonzero), 0.004, radius, search).numpy()
    for j in range(pixels):
        ref = reference_tfi(light[:, j], nonzero[:, j], 0.004, radius, search) if K <= 1000 else None
        if ref is None:      # long stream (int32 indices): check a stretch against the reference
            ref = reference_tfi(light[-300:, j], nonzero[-300:, j], 0.004, radius, search)[100:]
            got = out[-200:, j]
        else:
            got = out[:, j]
        assert np.allclose(got, ref, rtol=1e-12, atol=0), (j, got, ref)


def test_running_scans_equal_torch_cumulative(rng):
    from tespike.recon.tfi import running_max, running_min_reversed
    x = torch.from_numpy(rng.integers(-5, 100, (37, 4)))
    assert torch.equal(running_max(x), x.cummax(0).values)
    assert torch.equal(running_min_reversed(x), x.flip(0).cummin(0).values.flip(0))


def test_msb_hand_worked():
    u = MSB.threshold / DESIGN_ELECTRONS
    # word 3 = 4 spikes since the stream start, word 1 = 1 spike over 2 readouts, then dense codes
    assert run([0, 0, 3, 0, 1, 8, 7], MSB).tolist() == approx([4 / 3] * 3 + [1 / 2] * 2 + [128, 64], u)


def test_msb_zero_word_means_no_spike_fired_in_its_interval(rng):
    """TFI reads a 0 code as "no spike in this interval" and a segment ending at a
    non-zero code n after zeros as spikes fired in p+1..n. With the msb readout a
    zero word means the counter is empty at readout: no remainder was left and no
    spike fired, so both hold; a non-zero word may carry spikes of earlier
    intervals only when the previous word was non-zero too (dense codes). Checked
    against the spike counts of the same stimulus (the count readout, 16 bits)."""
    from tespike.golden.sensor import simulate
    msb = SensorConfig(mode="ml", ml_readout="msb", ml_bits=16, b1=2, b2=2, threshold=6)
    count = SensorConfig(mode="ml", ml_bits=16, b1=2, b2=2, threshold=6)
    L = msb.clocks_per_readout
    lam = np.exp(rng.uniform(np.log(0.05), np.log(20.0), (1, 8, 8))) * 6 / L   # 0.05..20 spikes per readout
    stim = rng.poisson(np.broadcast_to(lam, (L * 60, 8, 8)))
    words, spikes = simulate(msb, stim), simulate(count, stim)
    assert (spikes[words == 0] == 0).all()
    after_zero = np.zeros_like(words, bool)
    after_zero[0] = True
    after_zero[1:] = words[:-1] == 0
    hit = (words > 0) & after_zero                       # remainder 0 before: all its spikes are new
    assert hit.sum() > 100
    read = np.where(words > 0, 1 << np.maximum(words - 1, 0), 0)
    assert (read[hit] <= spikes[hit]).all() and (spikes[hit] < 2 * read[hit]).all()
    # nothing is lost: every spike is read out but the remainder left in the counter,
    # below the last word's 2^(word - 1) (none after a 0 word)
    left = spikes.sum(0) - read.sum(0)
    assert (left >= 0).all() and (left < (1 << np.maximum(words[-1] - 1, 0))).all() and left.any()


def test_msb_equals_count_where_no_readout_holds_two_spikes():
    """Dim light (at most one spike per interval): msb words are the counts, so TFI agrees."""
    u = MSB.threshold / DESIGN_ELECTRONS
    words = [0, 1, 0, 0, 1, 0, 0, 0, 1, 0]
    assert run(words, MSB).tolist() == run(words, ML).tolist() == approx(
        [1 / 2] * 2 + [1 / 3] * 3 + [1 / 4] * 4 + [1 / 4], u)
