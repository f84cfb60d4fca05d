"""The two generated tops as every simulator harness sees them: one description of their ports.

SPEC section 6 has two tops with the same inputs (``clk``, ``rst``, ``charge``)
and different outputs: the parallel top ``<mode>_pixel_array`` shows every
word of an interval at once (``frame_valid``, ``frame``), the streaming top
``<mode>_pixel_array_stream`` sends them as B beats of N lanes (``out_valid``,
``out_first``, ``out_words``). Each simulator module (:mod:`tespike.cosim.rtlsim`,
:mod:`tespike.cosim.icarus`, :mod:`tespike.cosim.verilator`, :mod:`tespike.cosim.cocotb_bench`) serves
both through :class:`Top`: which output ports to sample, how wide they are, how
many captures an interval makes, how long to run past the stimulus, and which
check turns the captures into words (:func:`tespike.cosim.outside.check_captures`) or
beats (:func:`tespike.cosim.stream_ports.check_beats`), or, with a reset vector, into
each segment's (:mod:`tespike.cosim.resets`). :func:`prepare` is the run prologue they
share: the stimulus, lane count and reset vector checked before anything is built.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from tespike.golden.config import SensorConfig
from tespike.golden.errors import InputError, is_count
from tespike.golden.io import check_stimulus
from tespike.golden.beats import beat_count, check_lanes

from tespike.rtl.names import module_names, stream_module_names

from .outside import check_captures, unpack_rows
from .resets import beat_segments, check_resets, frame_segments, segments
from .stream_ports import check_beats, flush_clocks


@dataclasses.dataclass(frozen=True)
class Top:
    """The parallel top (``lanes`` None) or the streaming top with ``lanes`` N, of an H x W array."""

    config: SensorConfig
    height: int
    width: int
    lanes: int | None = None

    @property
    def streaming(self) -> bool:
        return self.lanes is not None

    @property
    def module(self) -> str:
        """The Verilog module name SPEC section 6 gives it (:mod:`tespike.rtl.names`)."""
        return (stream_module_names if self.streaming else module_names)(self.config)["top"]

    @property
    def outputs(self) -> str:
        """``"beats"`` or ``"frame"``: the key of each harness's output template."""
        return "beats" if self.streaming else "frame"

    @property
    def valid_port(self) -> str:
        return "out_valid" if self.streaming else "frame_valid"

    @property
    def word_port(self) -> str:
        return "out_words" if self.streaming else "frame"

    @property
    def word_values(self) -> int:
        """Words on the word port: N lanes, or H W pixels."""
        return self.lanes if self.streaming else self.height * self.width

    @property
    def charge_bits(self) -> int:
        return self.height * self.width * self.config.input_bits

    @property
    def output_bits(self) -> int:
        return self.word_values * self.config.word_bits

    @property
    def ports(self) -> dict[str, tuple[str, int]]:
        """SPEC section 6's ports of the top: name -> (direction, bits)."""
        ports = {"clk": ("input", 1), "rst": ("input", 1), "charge": ("input", self.charge_bits),
                 self.valid_port: ("output", 1)}
        if self.streaming:
            ports["out_first"] = ("output", 1)
        ports[self.word_port] = ("output", self.output_bits)
        return ports

    @property
    def beats(self) -> int:
        """Captures per readout interval: B beats, or 1 frame."""
        return beat_count(self.height * self.width, self.lanes) if self.streaming else 1

    @property
    def flush(self) -> int:
        """Clocks of zero charge a harness may run after the stimulus (the latency bound, and one)."""
        return flush_clocks(self.config) if self.streaming else self.config.clocks_per_readout + 1

    def describe(self, simulator: str) -> str:
        """``"<simulator> run of <module> (H x W[, N lanes])"``, the start of every error message."""
        lanes = f", {self.lanes} lanes" if self.streaming else ""
        return f"{simulator} run of {self.module} ({self.height} x {self.width}{lanes})"

    def verilog(self) -> str:
        """The generated Verilog of this top (``tespike verilog [--lanes N]``)."""
        if self.streaming:
            from tespike.rtl.verilog_stream import stream_array_verilog
            return stream_array_verilog(self.config, self.height, self.width, self.lanes)
        from tespike.rtl.verilog import array_verilog
        return array_verilog(self.config, self.height, self.width)

    def empty(self) -> np.ndarray:
        """The result of a run without a readout interval."""
        if self.streaming:
            return np.zeros((0, self.beats, self.lanes), np.int64)
        return np.zeros((0, self.height, self.width), np.int64)

    def result(self, run: "RunPlan", clocks, firsts, rows, what: str):
        """Captures -> words ``(K, H, W)`` / beats ``(K, B, N)``, held to SPEC section 6; with resets,
        each segment's words ``(n, H, W)`` / beats ``(n, N)`` (:mod:`tespike.cosim.resets`)."""
        H, W, T = self.height, self.width, run.stimulus.shape[0]
        clocks = np.asarray(clocks, np.int64)
        if run.resets is not None:
            if self.streaming:
                return beat_segments(clocks, firsts, rows, self.config, H, W, self.lanes, run.resets, T, what)
            return frame_segments(clocks, rows, self.config, H, W, run.resets, T, what)
        if self.streaming:
            return check_beats(clocks, firsts, rows, self.config, H, W, self.lanes, run.readouts, what)[0]
        K = run.readouts
        check_captures(clocks, self.config, K, what)
        rows = np.asarray(rows, np.uint32)[:K]
        return unpack_rows(rows.reshape(K, -1), H * W, self.config.word_bits).reshape(K, H, W)


@dataclasses.dataclass(frozen=True)
class RunPlan:
    """A run's checked plan, made before anything runs: its top, stimulus, reset vector (or None)
    and readouts after the last reset."""

    top: Top
    stimulus: np.ndarray
    resets: np.ndarray | None
    readouts: int

    @property
    def expected(self) -> int:
        """Captures the harness waits for after the last reset edge."""
        return self.readouts * self.top.beats

    @property
    def idle(self) -> bool:
        """Nothing to simulate: no readout interval and no reset vector."""
        return self.readouts == 0 and self.resets is None


def check_stream_lanes(lanes, what: str) -> int:
    """The lane count of a run of the streaming top, an integer >= 1 (None had run the parallel top
    and returned its words where beats were asked for)."""
    if not is_count(lanes, 1):
        raise InputError(f"{what}: lanes {lanes!r} must be an integer >= 1 (the streaming top's lanes)")
    return lanes


def prepare(config: SensorConfig, stimulus: np.ndarray, lanes: int | None = None, resets=None) -> RunPlan:
    """The run prologue every harness shares: check the stimulus, the lane count and the resets."""
    config = SensorConfig.required(config, "prepare")
    check_stimulus(stimulus, config)
    T, H, W = stimulus.shape
    if lanes is not None:
        check_lanes(config, H, W, lanes)
    resets = check_resets(resets, T)
    L = config.clocks_per_readout
    readouts = T // L if resets is None else segments(resets)[-1].readouts(T, L)
    return RunPlan(Top(config, H, W, lanes), stimulus, resets, readouts)
