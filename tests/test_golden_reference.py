"""The literal update rule against hand-worked cases of SPEC sections 3 and 4."""

import numpy as np
import pytest

from tespike.golden.config import SensorConfig
from tespike.golden.reference import step_reference


def run(config, per_clock):
    stim = np.asarray(per_clock, np.int64)[:, None, None]
    return step_reference(config, stim)[0][:, 0, 0].tolist()


def test_te_overflow_latches_ccc_of_the_overflow_cycle():
    c = SensorConfig(b1=1, b2=2, threshold=2, acc_bits=3)      # alpha 3, F 2, L 6, d 2
    # 2 electrons per clock: a spike every clock, 2nd spike (overflow) at clock 1 -> m = 1
    assert run(c, [2] * 6) == [0b100 | 1]
    # 1 per clock: spikes at clocks 1, 3 -> overflow at clock 3, S_h cycle 1 -> m = 2
    assert run(c, [1] * 6) == [0b100 | 2]
    # one spike only: flag 0, count 1
    assert run(c, [2, 0, 0, 0, 0, 0]) == [1]


def test_residual_is_kept_across_readouts_and_reset_is_subtractive():
    c = SensorConfig(b1=2, b2=1, threshold=3, acc_bits=3)      # alpha 1, F 4, L 4
    # 5 electrons in clock 0: spike, residual 2; +1 at clock 4 (next interval) -> spike there
    assert run(c, [5, 0, 0, 0, 1, 0, 0, 0]) == [1, 1]


def test_one_spike_per_clock_and_saturating_accumulator():
    c = SensorConfig(b1=3, b2=1, threshold=2, acc_bits=2)      # acc_max 3, L 8
    # 100 electrons at once: one spike per clock; acc clipped to 3 -> spikes at clocks 0 and 1 only
    # (q = 100 -> acc = min(98, 3) = 3; q = 3 -> spike, acc 1; q = 1: no spike)
    assert run(c, [100, 0, 0, 0, 0, 0, 0, 0]) == [2]


def test_ml_counter_saturates():
    c = SensorConfig(mode="ml", ml_bits=2, b1=2, b2=2, threshold=1)   # L = 12, max count 3
    assert run(c, [1] * 12) == [3]
    assert run(c, [1, 0] * 6) == [3]
    assert run(c, [0] * 11 + [1]) == [1]


def test_split_anywhere_gives_same_stream(rng):
    c = SensorConfig(b1=2, b2=2, threshold=9)
    stim = rng.integers(0, 20, size=(c.clocks_per_readout * 5, 2, 3))
    whole, _ = step_reference(c, stim)
    state, parts = None, []
    for a, b in [(0, 7), (7, 8), (8, 31), (31, stim.shape[0])]:
        words, state = step_reference(c, stim[a:b], state)
        parts.append(words)
    assert np.array_equal(np.concatenate(parts), whole)


def test_ml_msb_reads_the_top_bit_and_keeps_the_remainder():
    c = SensorConfig(mode="ml", ml_readout="msb", ml_bits=3, b1=2, b2=1, threshold=1)   # L = 4, max 7
    # 3 spikes: word 2 (2^1 leaves), remainder 1; +3 -> 4: word 3, remainder 0; then dark: 0
    assert run(c, [1, 1, 1, 0] * 2 + [0] * 4) == [2, 3, 0]
    # 4 -> word 3, remainder 0; 3 -> word 2, remainder 1, read out in the dark: word 1, then 0
    assert run(c, [1, 1, 1, 1, 1, 1, 1, 0] + [0] * 12) == [3, 2, 1, 0, 0]


def test_ml_msb_counter_saturates_with_its_remainder():
    c = SensorConfig(mode="ml", ml_readout="msb", ml_bits=2, b1=2, b2=1, threshold=1)   # L = 4, max 3
    # 4 spikes saturate at 3: word 2, remainder 1; 1 + 4 saturates again; then 1 drains
    words, state = step_reference(c, np.ones((8, 1, 1), np.int64))
    assert words[:, 0, 0].tolist() == [2, 2] and state.sfc[0, 0] == 1
    assert run(c, [1] * 8 + [0] * 8) == [2, 2, 1, 0]


def test_ml_msb_with_one_bit_is_the_count():
    for stim in ([1, 0, 0, 0] * 3, [1] * 12, [0] * 12):
        msb = SensorConfig(mode="ml", ml_readout="msb", ml_bits=1, b1=2, b2=1, threshold=1)
        assert run(msb, stim) == run(SensorConfig(mode="ml", ml_bits=1, b1=2, b2=1, threshold=1), stim)


def test_the_oracle_refuses_what_the_rule_does_not_define():
    """SPEC section 3's rule takes E-bit integer electrons: a float stimulus had been truncated, a
    negative one stepped, a preset's name an AttributeError."""
    from tespike.golden.errors import ConfigError, InputError
    with pytest.raises(ConfigError, match="^step_reference: configuration must be a SensorConfig"):
        step_reference("te", np.zeros((2, 1, 1), np.int64))
    for stimulus, refusal in ((np.full((2, 1, 1), 0.5), "^stimulus dtype float64 is not an integer type"),
                              (np.full((2, 1, 1), -1), "^stimulus value -1 is negative"),
                              (np.full((2, 1, 1), 1 << 16), "^stimulus value 65536")):
        with pytest.raises(InputError, match=refusal):
            step_reference(SensorConfig(), stimulus)


def test_the_reference_refuses_a_state_chunks_or_shape_it_cannot_step_in_one_line():
    """A state of other pixels was numpy's broadcast error and a name an AttributeError,
    ``PixelState.zeros((2, -1))`` numpy's "negative dimensions", and ``simulate(..., chunks=5)``
    Python's "not iterable"."""
    from tespike.golden.errors import InputError
    from tespike.golden.reference import PixelState, step_reference
    from tespike.golden.sensor import simulate
    config = SensorConfig()
    stimulus = np.zeros((config.clocks_per_readout, 2, 2), np.uint16)
    with pytest.raises(InputError, match=r"^state: must be a PixelState of the stimulus's 2 x 2 pixels, not one of \(3, 3\)$"):
        step_reference(config, stimulus, PixelState.zeros((3, 3)))
    with pytest.raises(InputError, match=r"^state: must be a PixelState of the stimulus's 2 x 2 pixels, not dict$"):
        step_reference(config, stimulus, {})
    for shape in ((2, -1), (2, 2.5), 3):
        with pytest.raises(InputError, match="^pixel state shape "):
            PixelState.zeros(shape)
    with pytest.raises(InputError, match=r"^chunks 5: must be an iterable of \(t, H, W\) stimulus arrays$"):
        simulate(config, stimulus, chunks=5)
