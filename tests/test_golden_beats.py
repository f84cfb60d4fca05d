import numpy as np
import pytest

from tespike.golden.config import SensorConfig
from tespike.golden.errors import ConfigError
from tespike.golden.beats import beat_count, beats, check_lanes, min_lanes, unbeat


def test_beats_are_raster_order_with_zero_padding():
    words = np.arange(1, 2 * 2 * 3 + 1).reshape(2, 2, 3)       # K = 2 intervals of 2 x 3 pixels
    got = beats(words, 4)                                      # B = 2 beats, lanes 6 and 7 padded
    assert got.shape == (2, 2, 4)
    assert got[0].tolist() == [[1, 2, 3, 4], [5, 6, 0, 0]]
    assert got[1].tolist() == [[7, 8, 9, 10], [11, 12, 0, 0]]
    assert np.array_equal(unbeat(got, 2, 3), words)


@pytest.mark.parametrize("lanes", [1, 5, 6, 7, 64])
def test_beat_j_lane_i_is_pixel_j_n_plus_i(lanes, rng):
    words = rng.integers(0, 32, size=(3, 2, 3))
    got = beats(words, lanes)
    B = beat_count(6, lanes)
    assert got.shape == (3, B, lanes)
    for j in range(B):
        for i in range(lanes):
            p = j * lanes + i
            want = words[:, p // 3, p % 3] if p < 6 else np.zeros(3, words.dtype)
            assert np.array_equal(got[:, j, i], want)


def test_smallest_lane_count_and_refusal_naming_it():
    config = SensorConfig()                                    # L = 240
    assert min_lanes(config, 400, 250) == 417                  # ceil(100000 / 240)
    assert check_lanes(config, 400, 250, 417) == 417
    with pytest.raises(ConfigError) as err:
        check_lanes(config, 400, 250, 416)
    message = str(err.value)
    assert "\n" not in message and "416" in message and "the smallest N is 417" in message
    one = SensorConfig(alpha=1, clocks_per_tick=1)             # L = 1: one beat per interval
    assert min_lanes(one, 2, 3) == 6
    with pytest.raises(ConfigError, match="smallest N is 6"):
        check_lanes(one, 2, 3, 5)
    assert check_lanes(one, 2, 3, 9) == 9                      # N > H*W: lanes past the last pixel carry 0


@pytest.mark.parametrize("lanes", [0, -1, 2.0, True])
def test_lane_count_must_be_a_positive_integer(lanes):
    with pytest.raises(ConfigError, match="lanes"):
        check_lanes(SensorConfig(), 2, 3, lanes)


def test_output_bandwidth_at_the_paper_settings():
    """400 x 250 TE pixels at 40 kHz readout (pixel clock 9.6 MHz): 5-bit words, 20 Gbit/s, 417 lanes."""
    from tespike.golden.beats import output_bandwidth
    config = SensorConfig()
    b = output_bandwidth(config, 400, 250, 40e3 * 240)
    assert b["readout_hz"] == 40e3 and b["word_bits"] == 5
    assert b["bits_per_s"] == 400 * 250 * 5 * 40e3 == 20e9
    assert b["min_lanes"] == 417 and b["pins"] == 417 * 5
    assert b["port_bits_per_s"] >= b["bits_per_s"]
    msb = output_bandwidth(SensorConfig.preset("ml-msb"), 400, 250, 9.6e6)
    assert msb["word_bits"] == 4 and msb["bits_per_s"] == 16e9


def test_lane_count_above_the_limit_is_refused_in_one_line():
    """N past MAX_LANES is refused (an out_words port of N Wd bits no simulator holds; the
    generator wrote a [499999999999999999994:0] port for N = 10^20 before); N = H W + 1 still works."""
    from tespike.golden.beats import MAX_LANES
    assert check_lanes(SensorConfig(), 2, 3, 7) == 7
    assert check_lanes(SensorConfig(), 2, 3, MAX_LANES) == MAX_LANES
    with pytest.raises(ConfigError, match=f"at most {MAX_LANES} lanes") as info:
        check_lanes(SensorConfig(), 2, 3, MAX_LANES + 1)
    assert "\n" not in str(info.value)


def test_the_lane_helpers_refuse_what_they_cannot_pack_in_one_line():
    """(A float word had been packed as a float, unbeat of too few beats was numpy's reshape error,
    0 lanes a ZeroDivisionError.)"""
    from tespike.golden.errors import InputError
    words = np.zeros((2, 2, 3), np.uint8)
    with pytest.raises(InputError, match="^readout words dtype float64 is not an integer type$"):
        beats(words.astype(float), 2)
    for shape in ((2, 3, 2), (1, 3, 2)):          # too few beats for 5 x 5; more than 1 x 1 needs (dropped)
        size = 5 if shape[0] == 2 else 1
        with pytest.raises(InputError, match=rf"^unbeat: beats of shape \({shape[0]}, 3, 2\) are not those of "
                                             rf"{size} x {size} pixels"):
            unbeat(np.zeros(shape, np.uint8), size, size)
    with pytest.raises(InputError, match="^unbeat: height 'x' and width 3 must be integers >= 1$"):
        unbeat(np.zeros((2, 3, 2), np.uint8), "x", 3)
    for pixels, lanes in ((4, 0), (-1, 2), (4, 1.5)):
        with pytest.raises(InputError, match=f"^beat count of {pixels} pixels on {lanes} lanes"):
            beat_count(pixels, lanes)
    assert np.array_equal(unbeat(beats(words + 3, 4), 2, 3), words + 3)


def test_the_bandwidth_and_lane_counts_refuse_sizes_and_clocks_that_are_none_in_one_line():
    """Two negative sizes passed as a positive pixel count, 0 rows needed 0 lanes, a negative or NaN
    pixel clock gave negative or NaN bits a second, and a preset's name an AttributeError."""
    from tespike.golden.beats import check_lanes, min_lanes, output_bandwidth
    from tespike.golden.errors import ConfigError, InputError
    te = SensorConfig()
    for height, width in ((-2, -3), (0, 3), (2.5, 2)):
        for call in (lambda: check_lanes(te, height, width, 2), lambda: min_lanes(te, height, width),
                     lambda: output_bandwidth(te, height, width, 1e6)):
            with pytest.raises(ConfigError, match=rf"^array of {height!r} x {width!r} pixels: the rows and columns"):
                call()
    for clock in (-1e6, 0, float("nan"), "1e6"):
        with pytest.raises(InputError, match=f"^pixel clock {clock!r} Hz: must be a finite number > 0$"):
            output_bandwidth(te, 2, 3, clock)
    for call, what in ((lambda: check_lanes("te", 2, 3, 2), "check_lanes"), (lambda: min_lanes("te", 2, 3), "min_lanes"),
                       (lambda: output_bandwidth("te", 2, 3, 1e6), "output_bandwidth")):
        with pytest.raises(ConfigError, match=f"^{what}: configuration must be a SensorConfig"):
            call()
