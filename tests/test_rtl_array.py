# amaranth: UnusedElaboratable=no
import numpy as np
import pytest

from tespike.golden.config import SensorConfig
from tespike.golden.errors import ConfigError
from tespike.golden.reference import step_reference
from tespike.rtl.array import PixelArray
from tests.configs import EDGE_CONFIGS, MSB_CONFIGS
from tests.rtl_helpers import mixed_stimulus, rtl_array_words


@pytest.mark.parametrize("config", EDGE_CONFIGS + MSB_CONFIGS, ids=str)
def test_array_equals_golden(config, rng):
    readouts = 3 if config.clocks_per_readout > 1 else 12
    stim = mixed_stimulus(config, rng, readouts, 2, 3)
    words, times = rtl_array_words(config, stim)
    golden = step_reference(config, stim)[0]
    assert np.array_equal(words, golden)
    L = config.clocks_per_readout
    # frame_valid is sampled high one clock after the last clock of each interval, only then
    assert times == [(k + 1) * L for k in range(readouts)]


@pytest.mark.parametrize("config", EDGE_CONFIGS + MSB_CONFIGS, ids=str)
def test_flat_array_equals_golden(config, rng):
    """The flat form (unnamed intermediates, one module) is the same logic."""
    stim = mixed_stimulus(config, rng, 2 if config.clocks_per_readout > 1 else 10, 3, 2)
    words, _ = rtl_array_words(config, stim, flat=True)
    assert np.array_equal(words, step_reference(config, stim)[0])


def test_array_stimulus_is_not_trivial(rng):
    """The mixed stimulus reaches flag 0, flag 1 and several CCC values (else the test proves little)."""
    config = SensorConfig()
    stim = mixed_stimulus(config, rng, 3, 4, 4)
    words = step_reference(config, stim)[0]
    flagged = words >> config.d
    assert flagged.any() and not flagged.all()
    assert len(np.unique(words)) >= 5


@pytest.mark.parametrize("height, width", [(0, 1), (1, 0), (-2, 3), (2.0, 2), (True, 2)])
def test_array_refuses_bad_size(height, width):
    with pytest.raises(ConfigError, match="height|width"):
        PixelArray(SensorConfig(), height, width)


def test_array_ports_follow_spec():
    config = SensorConfig(b1=3, b2=5, input_bits=7)
    dut = PixelArray(config, 2, 3)
    assert len(dut.charge) == 2 * 3 * 7
    assert len(dut.frame) == 2 * 3 * (5 + 1)
    assert len(dut.frame_valid) == 1
    assert dut.word_slice(1, 2).start == (1 * 3 + 2) * 6


def test_array_refuses_non_config():
    with pytest.raises(ConfigError, match="SensorConfig"):
        PixelArray({"mode": "te"}, 2, 2)


def test_array_widest_datapath_equals_golden(rng):
    """A = 62 and E = 32 (q is 63 bits): no wrap anywhere, against the reference."""
    config = SensorConfig(b1=2, b2=2, acc_bits=62, threshold=(1 << 33) + 5, input_bits=32)
    stim = rng.integers(0, 1 << 32, size=(config.clocks_per_readout * 3, 1, 3), dtype=np.int64)
    stim[:, 0, 2] = (1 << 32) - 1
    words, _ = rtl_array_words(config, stim)
    golden = step_reference(config, stim)[0]
    assert np.array_equal(words, golden) and golden.any()


def test_every_block_refuses_a_configuration_that_is_no_sensor_config():
    """One check (``SensorConfig.checked``) for every block and writer that builds from a configuration,
    each naming itself."""
    from tespike.rtl.array import PixelArray
    from tespike.rtl.pixel import TEPixel
    from tespike.rtl.stream import StreamingPixelArray
    from tespike.rtl.timing import ReadoutTiming
    from tespike.rtl.verilog import array_verilog
    not_config = {"mode": "te"}
    for build, name in ((lambda: PixelArray(not_config, 1, 1), "PixelArray"),
                        (lambda: StreamingPixelArray(not_config, 1, 1, 1), "StreamingPixelArray"),
                        (lambda: ReadoutTiming(not_config), "ReadoutTiming"),
                        (lambda: TEPixel(not_config), "TEPixel"),
                        (lambda: array_verilog(not_config, 1, 1), "Verilog")):
        with pytest.raises(ConfigError, match=f"^{name}: configuration must be a SensorConfig .*, not dict$"):
            build()
