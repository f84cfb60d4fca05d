"""Port bit packing, hex rows, the capture check and the cache helpers of cosim/outside.py."""

import re

import numpy as np
import pytest

from tespike.golden.config import SensorConfig
from tespike.golden.errors import TespikeError
from tespike.cosim.outside import (SimulatorRunError, cache_entry, check_captures, content_hash,
                           first_error_line, hex_to_rows, pack_rows, rows_to_hex,
                           unpack_rows, words_per_row)


def as_int(row_words) -> int:
    return sum(int(w) << (32 * i) for i, w in enumerate(row_words))


@pytest.mark.parametrize("bits", [1, 3, 5, 8, 13, 16, 17, 31, 32])
@pytest.mark.parametrize("pixels", [1, 2, 6, 7, 33])
def test_pack_puts_pixel_i_at_bits_i_times_width(bits, pixels, rng):
    values = rng.integers(0, 1 << bits, size=(4, pixels), dtype=np.int64)
    values[0] = (1 << bits) - 1                           # all ones: any spill into a neighbour shows
    words = pack_rows(values, bits)
    assert words.dtype == np.uint32 and words.shape == (4, words_per_row(pixels, bits))
    for row, packed in zip(values, words):
        expected = sum(int(v) << (i * bits) for i, v in enumerate(row))
        assert as_int(packed) == expected                 # bits above N * width are zero too
    assert np.array_equal(unpack_rows(words, pixels, bits), values)


def test_pack_accepts_any_integer_dtype(rng):
    values = rng.integers(0, 200, size=(5, 9))
    expected = pack_rows(values.astype(np.int64), 8)
    for dtype in (np.uint8, np.int16, np.uint32, np.int64):
        assert np.array_equal(pack_rows(values.astype(dtype), 8), expected)


def test_pack_large_chunks_match_small(rng, monkeypatch):
    import tespike.cosim.outside as outside
    values = rng.integers(0, 1 << 11, size=(300, 50), dtype=np.int64)
    whole = pack_rows(values, 11)
    monkeypatch.setattr(outside, "_PACK_CHUNK_BITS", 50 * 32 * 7)   # 7 rows per chunk
    assert np.array_equal(pack_rows(values, 11), whole)


def test_pack_refuses_bad_widths():
    with pytest.raises(ValueError):
        pack_rows(np.zeros((2, 2), np.int64), 33)
    with pytest.raises(ValueError):
        unpack_rows(np.zeros((2, 5), np.uint32), 2, 16)


@pytest.mark.parametrize("bits", [1, 4, 30, 32, 33, 96, 97])
def test_hex_round_trip_matches_verilog_h_format(bits, rng):
    nw = (bits + 31) // 32
    rows = rng.integers(0, 1 << 32, size=(3, nw), dtype=np.uint64).astype(np.uint32)
    if bits % 32:
        rows[:, -1] &= (1 << (bits % 32)) - 1
    text = rows_to_hex(rows, bits)
    for row, line in zip(rows, text):
        assert line == format(as_int(row), "x").rjust((bits + 3) // 4, "0")   # as $fwrite("%h") prints
    assert np.array_equal(hex_to_rows(text, bits), rows)


def test_check_captures_accepts_a_fixed_latency():
    c = SensorConfig(b1=2, b2=2)                          # L = 12
    for latency in (0, 1, 12):
        clocks = np.arange(4) * 12 + 11 + latency
        assert check_captures(clocks, c, 4, "x") == latency


@pytest.mark.parametrize("clocks, words", [
    ([12, 24], "2 times"),                                # one missing
    ([12, 24, 36, 40], "4 times"),                        # one extra
    ([12, 25, 36], "not fixed"),                          # jitter
    ([24, 36, 48], "outside 0..L"),                       # latency 13 > L
    ([10, 22, 34], "outside 0..L"),                       # before the interval ended
])
def test_check_captures_refuses_broken_contracts(clocks, words):
    with pytest.raises(SimulatorRunError, match=words):
        check_captures(np.array(clocks), SensorConfig(b1=2, b2=2), 3, "run")
    assert issubclass(SimulatorRunError, TespikeError)


def test_first_error_line_prefers_error_lines():
    text = "%Warning-WIDTH: a.v:3: meh\n%Error: a.v:7:3: syntax error, unexpected IDENTIFIER\nmore"
    assert first_error_line(text) == "%Error: a.v:7:3: syntax error, unexpected IDENTIFIER"
    assert first_error_line("x\n\nlast words\n") == "last words"
    assert first_error_line("") == "(no output)"


def test_content_hash_separates_parts():
    assert content_hash("ab", "c") != content_hash("a", "bc")
    assert content_hash("ab", "c") == content_hash(b"ab", "c")


def test_cache_entry_reports_done(tmp_path):
    with cache_entry(tmp_path, "k") as (final, done):
        assert final == tmp_path / "k" and not done
        final.mkdir()
        (final / "done").write_text("k")
    with cache_entry(tmp_path, "k") as (_, done):
        assert done


def test_every_harness_names_spec_sections_tops():
    """SPEC section 6's top names, written once (tespike.rtl.names) and read by every harness."""
    from tespike.cosim.tops import Top
    for mode, top in (("te", "te_pixel_array"), ("ml", "ml_pixel_array")):
        config = SensorConfig(mode=mode)
        assert Top(config, 2, 2).module == top
        assert Top(config, 2, 2, lanes=1).module == top + "_stream"


def test_the_row_packers_refuse_values_bits_and_hex_they_cannot_hold_in_one_line():
    """pack_rows wrapped -1 and 64 into a 5-bit field ([[64, -1]] came back [[0, 31]]) and truncated
    floats; bad bits, counts and hex were plain ValueErrors or wrong sizes."""
    from tespike.golden.errors import InputError
    with pytest.raises(InputError, match=r"^pack_rows: value -1 does not fit 5 bits \(0\.\.31\)$"):
        pack_rows(np.array([[64, -1]]), 5)
    with pytest.raises(InputError, match=r"^pack_rows: value 64 does not fit 5 bits \(0\.\.31\)$"):
        pack_rows(np.array([[64, 1]]), 5)
    with pytest.raises(InputError, match="^pack_rows packs integers, not float64 values$"):
        pack_rows(np.array([[1.5, 2.0]]), 5)
    for bits in (0, 33, 2.5):
        with pytest.raises(InputError, match=f"^pack_rows handles 1..32 bits per value, not {bits!r}$"):
            pack_rows(np.zeros((1, 2), np.int64), bits)
        with pytest.raises(InputError, match=f"^unpack_rows handles 1..32 bits per value, not {bits!r}$"):
            unpack_rows(np.zeros((1, 1), np.uint32), 2, bits)
    with pytest.raises(InputError, match="^words_per_row: pixels -1 must be an integer >= 0$"):
        words_per_row(-1, 5)
    with pytest.raises(InputError, match="^line 1 'zz' is no 5-bit hex value$"):
        hex_to_rows(["zz"], 5)


def test_the_outside_runs_refuse_lanes_frames_and_configurations_that_are_none_in_one_line():
    """``run_icarus_stream(config, stimulus, None)`` had run the parallel top and returned its words
    where beats were asked for; frame integers that are numpy's, floats, -1 or past the bus were
    AttributeErrors or OverflowErrors; ``prepare('te', ...)`` an AttributeError."""
    from tespike.cosim.benchbus import unpack_frames
    from tespike.cosim.icarus import run_icarus_stream
    from tespike.cosim.tops import prepare
    from tespike.cosim.verilator import run_verilator_stream
    from tespike.golden.errors import ConfigError, InputError
    config = SensorConfig(b1=1, b2=1, alpha=1, clocks_per_tick=1, threshold=1, acc_bits=1, input_bits=1)
    stimulus = np.ones((1, 1, 2), np.uint8)
    for run, what in ((run_icarus_stream, "run_icarus_stream"), (run_verilator_stream, "run_verilator_stream")):
        for lanes in (None, 0, 1.5):
            with pytest.raises(InputError, match=f"^{what}: lanes {lanes!r} must be an integer >= 1"):
                run(config, stimulus, lanes)
    for frame in (-1, 1 << 40, "5", 5.0):
        with pytest.raises(InputError, match=rf"^frame_rows: port value {re.escape(repr(frame))} is no integer of 0 \.\. 2\^8 - 1$"):
            unpack_frames([frame], 2, 4)
    assert unpack_frames([np.int64(5), 255], 2, 4).tolist() == [[5, 0], [15, 15]]
    with pytest.raises(ConfigError, match="^prepare: configuration must be a SensorConfig"):
        prepare("te", stimulus)


def test_an_icarus_run_refuses_its_outputs_and_sources_before_it_simulates(tmp_path):
    """A waveform path that was a folder or in a missing folder was shutil's error after the whole
    simulation (or the file moved into the folder), Verilog text given as a number a TypeError, and a
    missing work folder a simulator error."""
    from tespike.cosim.icarus import run_icarus
    from tespike.golden.errors import InputError
    config = SensorConfig(b1=1, b2=1, alpha=1, clocks_per_tick=1, threshold=1, acc_bits=1, input_bits=1)
    stimulus = np.ones((1, 1, 2), np.uint8)
    with pytest.raises(InputError, match=f"^cannot write vcd_path '{tmp_path}': it is a directory"):
        run_icarus(config, stimulus, vcd_path=tmp_path)
    with pytest.raises(InputError, match="^cannot write vcd_path .*: directory .* does not exist$"):
        run_icarus(config, stimulus, vcd_path=tmp_path / "missing" / "w.vcd")
    with pytest.raises(InputError, match="^verilog: must be the Verilog text to simulate, not int$"):
        run_icarus(config, stimulus, verilog=5)
    with pytest.raises(InputError, match="^work_dir .* is not an existing directory$"):
        run_icarus(config, stimulus, work_dir=tmp_path / "missing")
    assert not list(tmp_path.iterdir())
