# amaranth: UnusedElaboratable=no
"""The Amaranth streaming array (rtl/stream.py) against the golden beats, and the beat check itself."""

import numpy as np
import pytest
from amaranth.lib import stream, wiring

from tespike.cosim.outside import SimulatorRunError, pack_rows
from tespike.cosim.rtlsim import rtl_stream_beats, rtl_stream_run
from tespike.cosim.stream_ports import check_beats
from tespike.golden.config import SensorConfig
from tespike.golden.errors import ConfigError
from tespike.golden.reference import step_reference
from tespike.golden.beats import beat_count, beats
from tespike.rtl.stream import StreamingPixelArray
from tests.configs import EDGE_CONFIGS, MSB_CONFIGS
from tests.rtl_helpers import mixed_stimulus
from tests.stream_helpers import STREAM_SHAPE, lane_counts

CONFIGS = [EDGE_CONFIGS[i] for i in (0, 1, 3, 4, 5, 9)] + [MSB_CONFIGS[0], MSB_CONFIGS[3]]


@pytest.mark.parametrize("config", CONFIGS, ids=str)
def test_stream_equals_golden_beats(config, rng):
    """Every legal kind of lane count: the smallest, one not dividing H*W, H*W, more than H*W."""
    readouts = 3 if config.clocks_per_readout > 1 else 8
    stim = mixed_stimulus(config, rng, readouts, *STREAM_SHAPE)
    words = step_reference(config, stim)[0]
    for lanes in lane_counts(config):
        assert np.array_equal(rtl_stream_beats(config, stim, lanes), beats(words, lanes)), lanes


def test_stream_of_one_pixel_and_one_lane(rng):
    config = SensorConfig(b1=2, b2=2)                          # L = 12: B = 1 beat of 1 lane
    stim = mixed_stimulus(config, rng, 4, 1, 1)
    got = rtl_stream_beats(config, stim, 1, flat=False)        # the pixels as submodules
    assert np.array_equal(got, beats(step_reference(config, stim)[0], 1))


def test_component_signature_and_refusal():
    config = SensorConfig()
    dut = StreamingPixelArray(config, 2, 3, 4)
    assert dut.beats == 2
    out = dut.signature.members["out"]
    assert out.flow == wiring.Out and isinstance(out.signature, stream.Signature)
    assert out.signature.always_ready and not out.signature.always_valid
    assert len(dut.out.p.words) == 4 * config.word_bits and len(dut.charge) == 6 * config.input_bits
    with pytest.raises(ConfigError, match="smallest N is 6"):
        StreamingPixelArray(SensorConfig(alpha=1, clocks_per_tick=1), 2, 3, 5)


def _captures(config, H, W, N, K, delay=0, first_on=None):
    """Beat captures of K intervals as a correct design sends them, the last beat ``delay`` later."""
    L, B = config.clocks_per_readout, beat_count(H * W, N)
    clocks, firsts = [], []
    for k in range(K):
        for j in range(B):
            clocks.append((k + 1) * L + 1 + j + (delay if j == B - 1 else 0))
            firsts.append(j == 0 if first_on is None else j == first_on)
    rows = pack_rows(np.arange(K * B * N).reshape(K * B, N) % (1 << config.word_bits), config.word_bits)
    return clocks, firsts, rows


def test_beat_check_latency_bound_and_first_flag():
    """The last beat of interval k may leave at most 2L clocks after its last clock; out_first marks beat 0."""
    config = SensorConfig(b1=2, b2=2)                          # L = 12
    H, W, N, K = 2, 3, 1, 3                                    # B = 6 beats
    got, latency = check_beats(*_captures(config, H, W, N, K), config, H, W, N, K, "ok")
    assert latency == 7 and got.shape == (K, 6, 1)             # beat j at 2 + j clocks after the end
    ok = check_beats(*_captures(config, H, W, N, K, delay=2 * 12 - 7), config, H, W, N, K, "edge")
    assert ok[1] == 2 * 12
    with pytest.raises(SimulatorRunError, match="at most 2L = 24"):
        check_beats(*_captures(config, H, W, N, K, delay=2 * 12 - 6), config, H, W, N, K, "late")
    with pytest.raises(SimulatorRunError, match="out_first"):
        check_beats(*_captures(config, H, W, N, K, first_on=1), config, H, W, N, K, "first")
    clocks, firsts, rows = _captures(config, H, W, N, K)
    with pytest.raises(SimulatorRunError, match="expected 18"):
        check_beats(clocks[:-1], firsts[:-1], rows[:-1], config, H, W, N, K, "missing")


def test_latency_of_the_rtl_is_b_plus_one(rng):
    """The generated design's last beat leaves B + 1 <= L + 1 <= 2L clocks after its interval."""
    config = SensorConfig(b1=1, b2=2)                          # L = 6: N = 1 gives B = 6 = L
    stim = mixed_stimulus(config, rng, 3, *STREAM_SHAPE)
    got, latency = rtl_stream_run(config, stim, 1)
    assert np.array_equal(got, beats(step_reference(config, stim)[0], 1))
    assert latency == 6 + 1 <= 2 * config.clocks_per_readout
    got, latency = rtl_stream_run(config, stim, 4)             # B = 2
    assert latency == 3 and np.array_equal(got, beats(step_reference(config, stim)[0], 4))
