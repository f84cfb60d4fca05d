"""tespike.golden.toggles: the words are the golden model's, the toggles those of the RTL's VCD."""

import numpy as np
import pytest
from amaranth.hdl import Module
from amaranth.sim import Simulator

from tespike.cosim.vcd import bit_toggles
from tespike.golden.config import SensorConfig
from tespike.golden.sensor import simulate
from tespike.golden.toggles import count_toggles
from tespike.rtl.pixel import pixel_class

CONFIGS = [SensorConfig(mode="te", b1=2, b2=2, threshold=5, acc_bits=4, input_bits=3),
           SensorConfig(mode="ml", b1=2, b2=2, ml_bits=3, threshold=4, acc_bits=4, input_bits=3),
           SensorConfig(mode="ml", b1=2, b2=2, ml_bits=3, ml_readout="msb", threshold=3,
                        acc_bits=3, input_bits=3)]


def _electrons(config, readouts, n, seed):
    rng = np.random.default_rng(seed)
    rate = np.linspace(0, config.input_max, n)            # dark to saturating
    return np.minimum(rng.poisson(rate, (readouts * config.clocks_per_readout, n)), config.input_max)


@pytest.mark.parametrize("config", CONFIGS, ids=str)
def test_words_are_the_golden_models(config):
    e = _electrons(config, 6, 9, 1)
    toggles = count_toggles(config, e)
    assert np.array_equal(toggles.words, simulate(config, e[:, None, :])[:, 0, :])
    assert toggles.intervals == 6 and (toggles.flops > 0).any()


@pytest.mark.parametrize("config", CONFIGS, ids=str)
def test_toggles_equal_a_vcd_count_of_the_rtl(config, tmp_path):
    n, readouts = 4, 5
    e = _electrons(config, readouts, n, 2)
    top = Module()
    pixels = [pixel_class(config)(config) for _ in range(n)]
    for i, pixel in enumerate(pixels):
        top.submodules[f"pixel{i}"] = pixel
    L, F = config.clocks_per_readout, config.clocks_per_tick

    async def bench(ctx):
        for t in range(e.shape[0]):                 # the last edge loads the last word
            for i, pixel in enumerate(pixels):
                ctx.set(pixel.charge, int(e[t, i]))
                ctx.set(pixel.last, int(t % L == L - 1))
                if config.is_te:
                    ctx.set(pixel.ccc, (t % L) // F + 1)
            await ctx.tick()

    sim = Simulator(top)
    sim.add_clock(1e-6)
    sim.add_testbench(bench)
    vcd = tmp_path / "pixels.vcd"
    with sim.write_vcd(str(vcd)):
        sim.run()
    expected = count_toggles(config, e)
    registers = tuple(expected.registers) + ("word_reg",)
    found = bit_toggles(vcd, registers)
    for i in range(n):
        for name in registers:
            (key,) = [k for k in found if k.endswith(f".pixel{i}.{name}")]
            want = expected.word[i] if name == "word_reg" else expected.registers[name][i]
            assert found[key] == want, (i, name, found[key], want)


def test_a_partial_interval_is_refused():
    config = CONFIGS[0]
    with pytest.raises(ValueError, match="whole number"):
        count_toggles(config, np.zeros((config.clocks_per_readout + 1, 2), np.int64))
