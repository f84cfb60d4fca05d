"""Waveforms of the RTL co-simulation: read a VCD back, write a GTKWave save file.

:func:`waveform_words` rebuilds the readout stream from the VCD *alone*: it
finds the rising edges of the clock in the waveform, samples reset,
``frame_valid`` and ``frame`` at each edge (the last value written strictly
before the edge's time stamp, which is what a register latching on that edge
sees), takes pixel clock t = 0 as the first edge with reset low, and collects
``frame`` wherever ``frame_valid`` is high. It must equal the stream the
testbench captured live (the tests check this).

Pitfalls handled (measured on Amaranth's VCD writer and vcdvcd): the timescale is 1 fs, so time stamps
are large and vcdvcd's slice form ``sig[a:b]`` (which walks every integer time)
is never used; several changes can share one time stamp (values are looked up
with a binary search on the change times, taking the last change before the
edge); a signal is read from its own scope (``bench.top.tb_*``, the wrapper's
own copies), never from a parent's ``$N`` re-listing.
"""

from __future__ import annotations

import dataclasses
import os
import re
from pathlib import Path

import numpy as np

from tespike.golden.config import SensorConfig
from tespike.golden.atomic import atomic_output
from tespike.golden.errors import InputError, is_count
from tespike.golden.io import check_frame_shape
from tespike.golden.paths import check_input_file

from . import benchbus
from .benchbus import BENCH_SCOPE

#: Bytes of VCD per pixel per clock, a lower bound for checking the disk before a run: a VCD
#: holds changes, so it depends on the light (measured on an 8 x 8 TE array: 2.8 with no
#: light, 143 with random charge; 78 on the default demo's crop).
VCD_BYTES_PER_PIXEL_CLOCK = 2

#: VCD scope of the pixel array under the testbench wrapper.
ARRAY_SCOPE = f"{BENCH_SCOPE}.{benchbus.ARRAY_SCOPE}"


@dataclasses.dataclass
class Waveform:
    """What :func:`waveform_words` read: words and the pixel clock of each ``frame_valid``."""

    words: np.ndarray       # (K, H, W) int64
    clocks: np.ndarray      # (K,) pixel clock t (edge index after reset) of each frame
    edges: int              # rising clock edges with reset low in the waveform


def vcd_reader():
    """vcdvcd's ``VCDVCD`` class, the one way this project imports it. vcdvcd sets SIGPIPE to
    the system's default on import (for its own command line), after which any later write to a
    closed pipe (a pool or Dask worker gone, a reader of stdout that left) kills this process
    silently, with no line and no cleanup: the disposition is put back as it was."""
    import importlib
    import signal
    import sys
    import threading
    if "vcdvcd" not in sys.modules and threading.current_thread() is threading.main_thread():
        previous = signal.getsignal(signal.SIGPIPE)
        try:
            importlib.import_module("vcdvcd")
        finally:
            if previous is not None:
                signal.signal(signal.SIGPIPE, previous)
    from vcdvcd import VCDVCD     # (elsewhere than the main thread vcdvcd cannot change it either)
    return VCDVCD


def _load(path, names):
    VCDVCD = vcd_reader()
    return VCDVCD(str(waveform_file(path)), signals=list(names), store_tvs=True)


def waveform_file(path) -> Path:
    """``path``, a readable regular file, refused in one line otherwise (a folder had been an
    IsADirectoryError, None a FileNotFoundError of 'None')."""
    return check_input_file(path, "waveform")


def _check_readout(readout) -> int:
    if not is_count(readout):                           # (-1 or 2.5 had drawn a view of nothing)
        raise InputError(f"readout {readout!r}: must be an integer >= 0")
    return readout


def _signal(vcd, path, name):
    try:
        return vcd[name]
    except KeyError:
        raise InputError(f"waveform file {str(path)!r} has no signal {name!r} "
                         "(not written by cosim.rtlsim?)") from None


def _sampler(signal, edge_times: np.ndarray) -> list[str]:
    """Value of ``signal`` just before each edge time (last change with time < edge)."""
    times = np.fromiter((t for t, _ in signal.tv), np.int64, len(signal.tv))
    index = np.searchsorted(times, edge_times, side="left") - 1
    values = [v for _, v in signal.tv]
    return [values[i] if i >= 0 else "x" for i in index]


def rising_edges(signal) -> np.ndarray:
    """Time stamps at which a 1-bit signal goes from 0 to 1 (final value per time stamp)."""
    final = {}
    for t, v in signal.tv:          # several changes may share a time stamp: keep the last
        final[t] = v
    edges, previous = [], None
    for t in sorted(final):
        v = final[t]
        if v == "1" and previous == "0":
            edges.append(t)
        previous = v
    return np.asarray(edges, np.int64)


def waveform_words(vcd_path, config: SensorConfig, shape: tuple[int, int]) -> Waveform:
    """Rebuild the readout stream of an ``rtl_words(..., vcd_path=...)`` run from its VCD."""
    config = SensorConfig.required(config, "waveform_words")
    H, W = check_frame_shape(shape, "waveform shape")
    names = {key: f"{BENCH_SCOPE}.tb_{key}" for key in ("clk", "rst", "frame_valid", "frame")}
    vcd = _load(vcd_path, names.values())
    sig = {key: _signal(vcd, vcd_path, name) for key, name in names.items()}
    width = int(sig["frame"].size)
    if width != H * W * config.word_bits:
        raise InputError(f"waveform {str(vcd_path)!r}: frame is {width} bits, not H * W * word_bits = "
                         f"{H} * {W} * {config.word_bits}")
    grid = pixel_grid(_var_sizes(vcd_path))
    if grid is not None and grid != (H, W):
        raise InputError(f"waveform {str(vcd_path)!r} is of a {grid[0]} x {grid[1]} pixel array, "
                         f"not the {H} x {W} asked for")
    edge_times = rising_edges(sig["clk"])
    rst = _sampler(sig["rst"], edge_times)
    low = [i for i, v in enumerate(rst) if v == "0"]
    if not low:
        return Waveform(np.zeros((0, H, W), np.int64), np.zeros(0, np.int64), 0)
    edge_times = edge_times[low[0]:]            # pixel clock t = 0: first edge with reset low
    valid = _sampler(sig["frame_valid"], edge_times)
    frame = _sampler(sig["frame"], edge_times)
    clocks = [t for t, v in enumerate(valid) if v == "1"]
    bad = [t for t in clocks if set(frame[t]) - {"0", "1"}]
    if bad:
        raise InputError(f"waveform {str(vcd_path)!r}: frame is undefined ({frame[bad[0]]!r}) "
                         f"at pixel clock {bad[0]} while frame_valid is high")
    words = benchbus.unpack_frames([int(frame[t], 2) for t in clocks], H * W, config.word_bits)
    return Waveform(words.reshape(len(clocks), H, W), np.asarray(clocks, np.int64), len(edge_times))


# -- GTKWave save file -------------------------------------------------------

#: Signals of rtl.timing.ReadoutTiming worth showing: S_h divider and tick, CCC, S_r strobe.
TIMING_SIGNALS = ("divider", "tick", "ccc", "at_alpha", "last", "frame_valid")

#: Signals of rtl.pixel.TEPixel / MLPixel worth showing (TE: SFC, flag, latched m; ML: count).
PIXEL_SIGNALS = ("charge", "acc", "spike", "sfc", "ovf", "m", "count", "last", "word")


def _var_sizes(vcd_path) -> dict[str, int]:
    """Every variable of the VCD header: full name -> width (vcdvcd drops ``[n:0]``)."""
    VCDVCD = vcd_reader()
    header = VCDVCD(str(waveform_file(vcd_path)), only_sigs=True)
    return {ref: int(header.data[code].size) for ref, code in header.references_to_ids.items()}


def _scope_vars(sizes, scope):
    """Variables declared directly in ``scope`` (not in a child), without ``$N`` re-listings."""
    prefix = scope + "."
    return [name for name in sizes
            if name.startswith(prefix) and "." not in name[len(prefix):] and "$" not in name[len(prefix):]]


def _child_scopes(sizes, scope):
    prefix = scope + "."
    return sorted({name[len(prefix):].split(".")[0] for name in sizes
                   if name.startswith(prefix) and "." in name[len(prefix):]})


def first_pixel_scope(sizes, scope=ARRAY_SCOPE) -> str | None:
    """The scope of pixel (0, 0): the child scope whose name holds only zero indices."""
    for child in _child_scopes(sizes, scope):
        digits = re.findall(r"\d+", child)
        if digits and all(int(d) == 0 for d in digits):
            return f"{scope}.{child}"
    return None


#: A pixel site's name in the array: its scope ``px_R_C`` (hierarchy kept) or its signals ``px_R_C_*`` (flat).
_PIXEL_NAME = re.compile(r"px_(\d+)_(\d+)(?:_|$)")


def pixel_grid(sizes, scope=ARRAY_SCOPE) -> tuple[int, int] | None:
    """(rows, columns) of the pixel array whose sites the waveform names under ``scope``, from
    the largest site indices; None where it names none. The frame's width alone is ``H * W *
    word_bits``, which a 2 x 1 run shares with a 1 x 2 one."""
    prefix = scope + "."
    sites = [_PIXEL_NAME.match(name[len(prefix):].split(".")[0]) for name in sizes if name.startswith(prefix)]
    sites = [(int(site[1]), int(site[2])) for site in sites if site]
    if not sites:
        return None
    return max(r for r, _ in sites) + 1, max(c for _, c in sites) + 1


def timing_scope(sizes, scope=ARRAY_SCOPE) -> str | None:
    for child in _child_scopes(sizes, scope):
        if "timing" in child:
            return f"{scope}.{child}"
    return None


#: Window size written into the save file, and the pixels of it the waveform pane gets
#: (the signal-name panes take the rest): the zoom is computed for this width.
GTKW_WINDOW = (1400, 800)
GTKW_WAVE_PIXELS = 1000
#: GTKWave's zoom: one 200-pixel "frame" spans zoombase^-zoom time units (zoombase 2 by default).
GTKW_PIXELS_PER_FRAME = 200


def gtkw_view(vcd_path, config: SensorConfig, readout: int = 0) -> tuple[int, int, float]:
    """(start time, marker time, zoom) that show one readout interval of the waveform.

    The view starts one clock before pixel clock ``readout * L`` (the interval's
    first clock edge, found in the VCD: the first rising clock edge with reset
    low is t = 0) and spans L + 4 clocks, so the readout strobe and the
    ``frame_valid`` that follows it are in view; the marker sits on the edge of
    the interval's last clock, t = readout * L + L - 1.
    """
    import math
    config = SensorConfig.required(config, "gtkw_view")
    _check_readout(readout)
    names = [f"{BENCH_SCOPE}.tb_clk", f"{BENCH_SCOPE}.tb_rst"]
    vcd = _load(vcd_path, names)
    edges = rising_edges(_signal(vcd, vcd_path, names[0]))
    period = int(np.median(np.diff(edges))) if len(edges) > 1 else benchbus.CLOCK_PERIOD_FS
    rst = _sampler(_signal(vcd, vcd_path, names[1]), edges)
    low = [i for i, v in enumerate(rst) if v == "0"]
    first = int(edges[low[0]]) if low else 0
    L = config.clocks_per_readout
    start = max(0, first + (readout * L - 1) * period)
    marker = first + (readout * L + L - 1) * period
    span = (L + 4) * period
    zoom = -math.log2(span * GTKW_PIXELS_PER_FRAME / GTKW_WAVE_PIXELS)
    return start, marker, zoom


def dump_path(vcd_path, gtkw_path) -> str:
    """The VCD's path as a save file records it: relative to the save file's folder, so the
    pair can be moved or shared together (GTKWave reads it relative to the save file)."""
    return os.path.relpath(Path(vcd_path).resolve(), Path(gtkw_path).resolve().parent)


def write_gtkw(gtkw_path, vcd_path, config: SensorConfig, *, dumpfile=None,
               readout: int = 0) -> list[str]:
    """Write a GTKWave save file for ``vcd_path`` showing the signals worth looking at.

    Groups: testbench (clock, reset, charge), timing (the S_h tick and S_r / last
    strobes and the CCC), pixel (0, 0) (accumulator, SFC, overflow flag, latched
    m, word), output (frame_valid, frame). It opens on readout interval
    ``readout`` (:func:`gtkw_view`: one interval wide, marker on its last clock).
    Returns the trace names written. ``dumpfile`` is the VCD path recorded in
    the save file (default: :func:`dump_path`, ``vcd_path`` relative to the save file).
    Written atomically (:func:`tespike.golden.atomic.atomic_output`: a folder, a missing
    folder or a full disk is one line, and no half-written file is left).
    """
    dumpfile = dumpfile if dumpfile is not None else dump_path(vcd_path, gtkw_path)
    with atomic_output(gtkw_path, "GTKWave save file") as tmp, open(tmp, "w") as handle:
        return write_gtkw_to(handle, vcd_path, config, dumpfile=dumpfile, readout=readout)


def write_gtkw_to(handle, vcd_path, config: SensorConfig, *, dumpfile, readout: int = 0) -> list[str]:
    """:func:`write_gtkw` into an open text ``handle`` (a caller that holds its own temporary:
    :func:`tespike.cosim.rtlsim.rtl_run` commits the save file with its waveform)."""
    from vcd.gtkw import GTKWSave

    config = SensorConfig.required(config, "write_gtkw")
    waveform_file(vcd_path)                          # (a missing one had been a FileNotFoundError traceback)
    _check_readout(readout)
    sizes = _var_sizes(vcd_path)
    start, marker, zoom = gtkw_view(vcd_path, config, readout)

    def pick(scope, preferred):
        """The scope's signals named in ``preferred``, in that order (all of them if none match)."""
        own = {name.rsplit(".", 1)[1]: name for name in _scope_vars(sizes, scope)}
        chosen = [own[key] for key in preferred if key in own]
        return chosen or [name for key, name in own.items() if key not in ("clk", "rst")]

    groups = {"testbench": [f"{BENCH_SCOPE}.tb_{k}" for k in ("clk", "rst", "charge")]}
    timing = timing_scope(sizes)
    if timing:
        groups["timing"] = pick(timing, TIMING_SIGNALS)
    pixel = first_pixel_scope(sizes)
    if pixel:
        groups["pixel (0,0)"] = pick(pixel, PIXEL_SIGNALS)
    else:                   # flat array: pixel (0, 0)'s signals are px_0_0_<name> in the array scope
        own = set(_scope_vars(sizes, ARRAY_SCOPE))
        flat = [f"{ARRAY_SCOPE}.px_0_0_{key}" for key in PIXEL_SIGNALS]
        groups["pixel (0,0)"] = [name for name in flat if name in own]
    groups["output"] = [f"{BENCH_SCOPE}.tb_{k}" for k in ("frame_valid", "frame")]

    written = []
    save = GTKWSave(handle)
    save.dumpfile(str(dumpfile), abspath=False)
    save.size(*GTKW_WINDOW)
    save.timestart(start)
    save.treeopen(ARRAY_SCOPE)
    save.zoom_markers(zoom, marker)
    for group, traces in groups.items():
        with save.group(group, closed=False):
            for name in traces:
                if name not in sizes:
                    continue
                size = sizes[name]
                full = name + (f"[{size - 1}:0]" if size > 1 else "")
                save.trace(full, datafmt="dec" if size > 1 else "hex")
                written.append(full)
    return written


def bit_toggles(vcd_path, suffixes: tuple[str, ...]) -> dict[str, int]:
    """Bit changes of every signal whose name ends in ``.<suffix>``, by full name.

    Each value change counts the bits that differ from the previous value (a value
    with x or z bits counts nothing, and nor does the first value: the initial state).
    The golden model's :func:`tespike.golden.toggles.count_toggles` is checked against this.
    """
    VCDVCD = vcd_reader()
    if isinstance(suffixes, str) or not all(isinstance(s, str) for s in suffixes):
        raise InputError(f"suffixes {suffixes!r}: must be a sequence of signal names (strings)")
    sizes = _var_sizes(vcd_path)
    names = [name for name in sizes if any(name.endswith("." + s) for s in suffixes)]
    if not names:
        raise InputError(f"waveform file {str(vcd_path)!r} has no signal ending in "
                         + ", ".join(f"'.{s}'" for s in suffixes))
    vcd = VCDVCD(str(vcd_path), signals=names, store_tvs=True)
    counts = {}
    for name in names:
        total, previous = 0, None
        for _, value in vcd[name].tv:
            number = int(value, 2) if set(value) <= {"0", "1"} else None
            if previous is not None and number is not None:
                total += (previous ^ number).bit_count()
            previous = number
        counts[name] = total
    return counts
