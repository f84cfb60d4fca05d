"""Waveforms of the co-simulation: the stream rebuilt from the VCD alone equals the live one."""

import numpy as np
import pytest

from tespike.cosim.benchbus import CLOCK_PERIOD_FS
from tespike.cosim.outside import RESET_CLOCKS
from tespike.cosim.rtlsim import RTLProtocolError, rtl_run
from tespike.cosim.vcd import rising_edges, waveform_words, write_gtkw
from tespike.golden.config import SensorConfig
from tespike.golden.errors import InputError
from tests.cosim_helpers import golden_words, threshold_stimulus


def _files(directory):
    return sorted(p.name for p in directory.iterdir())


@pytest.mark.parametrize("config", [SensorConfig(b1=2, b2=2, threshold=20),
                                    SensorConfig(mode="ml", b1=2, b2=2, threshold=9, ml_bits=3),
                                    SensorConfig(b1=2, alpha=1, clocks_per_tick=1, threshold=3)], ids=str)
def test_vcd_round_trip_gives_the_live_stream(config, rng, tmp_path):
    stim = threshold_stimulus(config, rng, 6, 2, 3)
    vcd, gtkw = tmp_path / "w.vcd", tmp_path / "w.gtkw"
    run = rtl_run(config, stim, vcd_path=vcd, gtkw_path=gtkw)
    assert np.array_equal(run.words, golden_words(config, stim))
    wave = waveform_words(vcd, config, (2, 3))
    assert np.array_equal(wave.words, run.words)
    assert np.array_equal(wave.clocks, run.clocks)      # sampled at the same edges, not one late
    assert wave.edges >= stim.shape[0]
    assert _files(tmp_path) == ["w.gtkw", "w.vcd"]       # no temporary files left


def test_gtkw_shows_clock_strobes_ccc_and_pixel_00(rng, tmp_path):
    config = SensorConfig(b1=2, b2=2, threshold=20)
    vcd, gtkw = tmp_path / "w.vcd", tmp_path / "w.gtkw"
    rtl_run(config, threshold_stimulus(config, rng, 1, 2, 2), vcd_path=vcd, gtkw_path=gtkw)
    text = gtkw.read_text()
    assert '[dumpfile] "w.vcd"' in text        # the final file, relative to the save file (not the temporary)
    (tmp_path / "views").mkdir()
    rtl_run(config, threshold_stimulus(config, rng, 1, 2, 2), vcd_path=vcd, gtkw_path=tmp_path / "views" / "w.gtkw")
    assert '[dumpfile] "../w.vcd"' in (tmp_path / "views" / "w.gtkw").read_text()
    traces = {line.split("[")[0] for line in text.splitlines() if line.startswith("bench.")}
    for name in ["bench.top.tb_clk", "bench.top.tb_rst", "bench.top.tb_frame_valid", "bench.top.tb_frame",
                 "bench.top.array.timing.tick", "bench.top.array.timing.last", "bench.top.array.timing.ccc",
                 "bench.top.array.px_0_0.acc", "bench.top.array.px_0_0.sfc", "bench.top.array.px_0_0.ovf",
                 "bench.top.array.px_0_0.m", "bench.top.array.px_0_0.word"]:
        assert name in traces, name
    assert not any(".px_0_1." in name or ".px_1_0." in name for name in traces)
    # it opens on one readout interval: GTKWave's view spans 200 px per 2^-zoom fs
    start = int(next(line for line in text.splitlines() if line.startswith("[timestart]")).split()[1])
    zoom, marker = next(line for line in text.splitlines() if line.startswith("*"))[1:].split()[:2]
    period, L = CLOCK_PERIOD_FS, config.clocks_per_readout
    span = 2.0 ** -float(zoom) * 1000 / 200
    assert (L + 2) * period < span < (L + 8) * period
    edges = rising_edges(__import__("vcdvcd").VCDVCD(str(vcd), signals=["bench.top.tb_clk"],
                                                      store_tvs=True)["bench.top.tb_clk"])
    t0 = edges[RESET_CLOCKS]                                # the reset clocks, then pixel clock 0
    assert start == t0 - period and int(marker) == t0 + (L - 1) * period


def test_failed_run_leaves_no_waveform(monkeypatch, rng, tmp_path):
    import tespike.rtl.array
    from tespike import rtl
    from tests.test_cosim_rtlsim import _delayed_array
    config = SensorConfig(b1=2, b2=2, threshold=20)
    monkeypatch.setattr(rtl.array, "PixelArray", _delayed_array(3, double=True))
    with pytest.raises(RTLProtocolError):
        rtl_run(config, threshold_stimulus(config, rng, 2, 1, 1), vcd_path=tmp_path / "w.vcd",
                gtkw_path=tmp_path / "w.gtkw")
    assert _files(tmp_path) == []


def _hand_vcd(path, frames_before_edge):
    """A VCD as Amaranth writes it (1 fs, bench.top.tb_*) with several changes per time stamp.

    ``frames_before_edge[n]`` = (valid, frame) held before rising edge n; at every edge the
    values first glitch to something else and then settle on the next pair, at the same stamp.
    """
    from vcd import VCDWriter
    half = CLOCK_PERIOD_FS // 2
    with open(path, "w") as handle, VCDWriter(handle, timescale="1 fs") as writer:
        clk = writer.register_var("bench.top", "tb_clk", "wire", size=1, init=0)
        rst = writer.register_var("bench.top", "tb_rst", "wire", size=1, init=1)
        valid = writer.register_var("bench.top", "tb_frame_valid", "wire", size=1,
                                    init=frames_before_edge[0][0])
        frame = writer.register_var("bench.top", "tb_frame", "wire", size=4, init=frames_before_edge[0][1])
        writer.register_var("bench.top.array", "frame_valid", "wire", size=1, init=1)   # decoy scope
        for n, (v, f) in enumerate(frames_before_edge):
            time = half + n * CLOCK_PERIOD_FS
            writer.change(clk, time, 1)
            writer.change(valid, time, 1 - v)                   # glitch at the edge's stamp ...
            writer.change(frame, time, 15 - f)
            if n + 1 < len(frames_before_edge):
                writer.change(valid, time, frames_before_edge[n + 1][0])   # ... then settle
                writer.change(frame, time, frames_before_edge[n + 1][1])
            if n == 0:
                writer.change(rst, time + half // 2, 0)         # released between edges 0 and 1
            writer.change(clk, time + half, 0)


def test_reader_samples_the_last_value_before_each_edge(tmp_path):
    config = SensorConfig(mode="ml", b1=1, b2=1, clocks_per_tick=1, threshold=1, ml_bits=2)   # Wd = 2
    # edge 0: reset still high; then t = 0.. with (valid, frame) before each edge
    pairs = [(1, 9), (0, 3), (1, 6), (1, 5), (0, 0), (1, 12)]
    _hand_vcd(tmp_path / "h.vcd", pairs)
    wave = waveform_words(tmp_path / "h.vcd", config, (1, 2))
    # edge 0 had reset high (sampled before the edge), so t = 0 is edge 1
    assert list(wave.clocks) == [1, 2, 4]
    assert wave.words.tolist() == [[[2, 1]], [[1, 1]], [[0, 3]]]        # 6, 5, 12 as two 2-bit words


def test_rising_edges_ignore_same_stamp_glitches():
    class Sig:
        tv = [(0, "0"), (10, "1"), (20, "0"), (30, "1"), (30, "0"), (40, "0"), (50, "1"), (50, "1")]
    assert list(rising_edges(Sig)) == [10, 50]


def test_reader_refuses_a_foreign_vcd(tmp_path):
    from vcd import VCDWriter
    with open(tmp_path / "f.vcd", "w") as handle, VCDWriter(handle, timescale="1 ns") as writer:
        writer.register_var("top", "clk", "wire", size=1, init=0)
    with pytest.raises(InputError, match="tb_"):
        waveform_words(tmp_path / "f.vcd", SensorConfig(), (1, 1))
    with pytest.raises(InputError, match="does not exist"):
        waveform_words(tmp_path / "missing.vcd", SensorConfig(), (1, 1))


def test_reader_refuses_a_wrong_shape(rng, tmp_path):
    config = SensorConfig(b1=2, b2=2, threshold=20)
    rtl_run(config, threshold_stimulus(config, rng, 1, 2, 2), vcd_path=tmp_path / "w.vcd")
    with pytest.raises(InputError, match="frame is 12 bits"):
        waveform_words(tmp_path / "w.vcd", config, (1, 2))


@pytest.mark.parametrize("flat", [False, True], ids=["hierarchy", "flat"])
def test_reader_refuses_the_transposed_shape_of_the_same_width(flat, rng, tmp_path):
    # a 2 x 1 frame is as wide as a 1 x 2 one: the pixel sites the waveform names tell them apart
    config = SensorConfig(b1=2, b2=2, threshold=20)
    run = rtl_run(config, threshold_stimulus(config, rng, 1, 2, 1), vcd_path=tmp_path / "w.vcd", flat=flat)
    assert np.array_equal(waveform_words(tmp_path / "w.vcd", config, (2, 1)).words, run.words)
    with pytest.raises(InputError, match=r"of a 2 x 1 pixel array, not the 1 x 2 asked for"):
        waveform_words(tmp_path / "w.vcd", config, (1, 2))


def test_reset_is_held_before_clock_zero(rng, tmp_path):
    from tespike.cosim.vcd import vcd_reader
    VCDVCD = vcd_reader()
    config = SensorConfig(b1=2, b2=2, threshold=20)
    rtl_run(config, threshold_stimulus(config, rng, 1, 1, 1), vcd_path=tmp_path / "w.vcd")
    vcd = VCDVCD(str(tmp_path / "w.vcd"))
    edges = rising_edges(vcd["bench.top.tb_clk"])
    assert edges[0] == CLOCK_PERIOD_FS // 2                # first rising edge at half a period
    rst = vcd["bench.top.tb_rst"].tv
    released = [t for t, v in rst if v == "0"][0]
    assert edges[RESET_CLOCKS - 1] <= released < edges[RESET_CLOCKS]


def test_gtkw_of_the_flat_array_shows_pixel_00(rng, tmp_path):
    config = SensorConfig(b1=2, b2=2, threshold=20)
    stim = threshold_stimulus(config, rng, 2, 2, 2)
    run = rtl_run(config, stim, vcd_path=tmp_path / "w.vcd", gtkw_path=tmp_path / "w.gtkw", flat=True)
    assert np.array_equal(waveform_words(tmp_path / "w.vcd", config, (2, 2)).words, run.words)
    text = (tmp_path / "w.gtkw").read_text()
    for name in ("px_0_0_acc", "px_0_0_sfc", "px_0_0_ovf", "px_0_0_m[", "px_0_0_word"):
        assert f"bench.top.array.{name}" in text, name
    assert "px_1_1_" not in text


def test_reading_a_waveform_leaves_sigpipe_as_it_was():
    """vcdvcd sets SIGPIPE to the system's default on import; the one import of it
    (:func:`tespike.cosim.vcd.vcd_reader`) puts it back, so a closed pipe stays an error the
    command reports, not a silent death (a fresh interpreter: this one may have imported it)."""
    import subprocess
    import sys
    code = ("import signal; from tespike.cosim.vcd import vcd_reader; vcd_reader(); "
            "print(signal.getsignal(signal.SIGPIPE) == signal.SIG_IGN)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert done.stdout.strip() == "True", done.stderr
    plain = subprocess.run([sys.executable, "-c", "import signal, vcdvcd; "
                            "print(signal.getsignal(signal.SIGPIPE) == signal.SIG_DFL)"],
                           capture_output=True, text=True, timeout=60)
    assert plain.stdout.strip() == "True"                       # (the premise: vcdvcd alone changes it)


def test_the_waveform_readers_and_writer_refuse_what_they_cannot_use_in_one_line(tmp_path):
    """A folder was an IsADirectoryError and None a FileNotFoundError of 'None'; a preset's name, a
    shape that is none and a readout of -1 or 'x' were tracebacks or a view of nothing; write_gtkw into
    a folder was an IsADirectoryError and could leave a half-written file (it is atomic now)."""
    from tespike.cosim.vcd import bit_toggles, gtkw_view
    config = SensorConfig()
    vcd = tmp_path / "w.vcd"
    rtl_run(config, np.zeros((config.clocks_per_readout, 1, 2), np.uint16), vcd_path=vcd)
    for call in (lambda p: bit_toggles(p, ("acc",)), lambda p: waveform_words(p, config, (1, 2)),
                 lambda p: gtkw_view(p, config)):
        with pytest.raises(InputError, match=f"^waveform file '{tmp_path}' is a directory, not a regular file$"):
            call(tmp_path)
        with pytest.raises(InputError, match="^waveform: a path must be a str or an os.PathLike, not NoneType$"):
            call(None)
    with pytest.raises(InputError, match="^suffixes 'acc': must be a sequence of signal names"):
        bit_toggles(vcd, "acc")
    for shape in (3, (-1, -2), (0.5, 4)):
        with pytest.raises(InputError, match="^waveform shape "):
            waveform_words(vcd, config, shape)
    for readout in (-1, 2.5, "x"):
        with pytest.raises(InputError, match=f"^readout {readout!r}: must be an integer >= 0$"):
            gtkw_view(vcd, config, readout)
        with pytest.raises(InputError, match=f"^readout {readout!r}: must be an integer >= 0$"):
            write_gtkw(tmp_path / "w.gtkw", vcd, config, readout=readout)
    with pytest.raises(InputError, match=f"^cannot write GTKWave save file '{tmp_path}': it is a directory"):
        write_gtkw(tmp_path, vcd, config)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["w.vcd"]
    assert write_gtkw(tmp_path / "w.gtkw", vcd, config)
