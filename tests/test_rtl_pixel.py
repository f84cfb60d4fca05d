# amaranth: UnusedElaboratable=no
import numpy as np
import pytest
from amaranth.sim import Simulator

from tespike.golden.config import SensorConfig
from tespike.golden.errors import ConfigError
from tespike.golden.reference import step_reference
from tespike.rtl.pixel import MLPixel, TEPixel, pixel_class
from tests.configs import EDGE_CONFIGS, MSB_CONFIGS
from tests.rtl_helpers import mixed_stimulus


def run_pixel(config, charges, word_register=True):
    """Drive one pixel alone with SPEC timing computed here (no timing block).

    Returns the word sampled one edge after every ``last`` clock (at the ``last`` edge
    itself without the word register), and for every other edge whether the pixel
    still showed the previous readout's word.
    """
    dut = pixel_class(config)(config, word_register=word_register)
    L, F = config.clocks_per_readout, config.clocks_per_tick
    words, held = [], []

    async def bench(ctx):
        previous = 0
        for t in range(len(charges) + 1):
            ctx.set(dut.charge, int(charges[t]) if t < len(charges) else 0)
            ctx.set(dut.last, int(t % L == L - 1))
            if config.is_te:
                ctx.set(dut.ccc, (t % L) // F + 1)
            _, _, word = await ctx.tick().sample(dut.word)
            if not word_register:
                if t < len(charges) and t % L == L - 1:
                    words.append(word)
                continue
            if t > 0 and (t - 1) % L == L - 1:
                words.append(word)
                previous = word
            else:
                held.append(word == previous)

    sim = Simulator(dut)
    sim.add_clock(1e-6)
    sim.add_testbench(bench)
    sim.run()
    return np.array(words, np.int64), held


@pytest.mark.parametrize("config", EDGE_CONFIGS + MSB_CONFIGS, ids=str)
def test_pixel_equals_golden(config, rng):
    readouts = 4 if config.clocks_per_readout > 1 else 20
    stim = mixed_stimulus(config, rng, readouts, 1, 4)
    for col in range(4):
        words, held = run_pixel(config, stim[:, 0, col])
        assert np.array_equal(words, step_reference(config, stim[:, :, col:col + 1])[0][:, 0, 0])
        assert all(held)


@pytest.mark.parametrize("config", [EDGE_CONFIGS[0], EDGE_CONFIGS[1], EDGE_CONFIGS[4]], ids=str)
def test_pixel_without_word_register_shows_the_word_at_last(config, rng):
    stim = mixed_stimulus(config, rng, 4 if config.clocks_per_readout > 1 else 20, 1, 2)
    for col in range(2):
        words, _ = run_pixel(config, stim[:, 0, col], word_register=False)
        assert np.array_equal(words, step_reference(config, stim[:, :, col:col + 1])[0][:, 0, 0])


def test_te_pixel_edge_cases_by_hand():
    """b1 = 2, alpha = 3, F = 2, theta = 10: exact words from a hand-worked trace."""
    config = SensorConfig(b1=2, b2=2, clocks_per_tick=2, threshold=10)   # L = 6
    # interval 0: 4 spikes by clock 3 -> overflow in S_h cycle 1 -> m = 2 -> word (1<<2)|2 = 6
    # interval 1: residual 0, one spike (10) and 9 left over -> word 1
    # interval 2: residual 9 + 1 -> spike at clock 0: one spike -> word 1
    # interval 3: 65535 electrons saturate acc at 31 after the first spike; one spike per clock
    #             at clocks 0..3 -> overflow at clock 3, in S_h cycle 2 -> word 6
    charges = [20, 0, 10, 10, 0, 0,
               10, 9, 0, 0, 0, 0,
               1, 0, 0, 0, 0, 0,
               65535, 0, 0, 0, 0, 0]
    words, _ = run_pixel(config, charges)
    assert words.tolist() == [6, 1, 1, 6]
    assert step_reference(config, np.array(charges).reshape(-1, 1, 1))[0][:, 0, 0].tolist() == [6, 1, 1, 6]


def test_ml_pixel_saturates():
    config = SensorConfig(mode="ml", ml_bits=2, b1=2, b2=2, threshold=1, acc_bits=1)   # L = 12
    words, _ = run_pixel(config, [1] * 12 + [0] * 12 + [1, 1, 0] + [0] * 9)
    assert words.tolist() == [3, 0, 2]


@pytest.mark.parametrize("cls, config", [(TEPixel, SensorConfig(mode="ml")), (MLPixel, SensorConfig())])
def test_pixel_refuses_other_mode(cls, config):
    with pytest.raises(ConfigError, match="mode"):
        cls(config)


def test_pixel_ports():
    te = TEPixel(SensorConfig(b1=3, b2=6, input_bits=5))
    assert (len(te.charge), len(te.ccc), len(te.last), len(te.word)) == (5, 6, 1, 7)
    ml = MLPixel(SensorConfig(mode="ml", ml_bits=11))
    assert len(ml.word) == 11 and "ccc" not in ml.signature.members


def test_ml_msb_pixel_keeps_the_remainder_by_hand():
    """ml_bits = 3, theta = 1 (one spike per unit of charge), L = 12: the msb readout by hand.

    counts 5 -> word 3, 1 stays; 1 + 2 = 3 -> word 2, 1 stays; 1 + 12 saturates at 7 -> word 3,
    3 stays; 3 -> word 2, 1 stays; 1 -> word 1, 0 stays; 0 -> word 0.
    """
    config = SensorConfig(mode="ml", ml_readout="msb", ml_bits=3, b1=2, b2=2, threshold=1, acc_bits=1)
    charges = [1] * 5 + [0] * 7 + [1] * 2 + [0] * 10 + [1] * 12 + [0] * 36
    words, held = run_pixel(config, charges)
    assert words.tolist() == [3, 2, 3, 2, 1, 0] and all(held)
    assert step_reference(config, np.array(charges).reshape(-1, 1, 1))[0][:, 0, 0].tolist() == words.tolist()


def test_msb_pixel_word_is_the_msb_index_width():
    for bits, width in ((1, 1), (2, 2), (3, 2), (8, 4), (15, 4), (16, 5)):
        pixel = MLPixel(SensorConfig(mode="ml", ml_readout="msb", ml_bits=bits))
        assert len(pixel.word) == width
