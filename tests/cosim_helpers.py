"""Helpers of the co-simulation tests: stimuli, and the RTL-vs-golden check with waveforms on demand.

Waveforms are slow, so they are opt-in: ``TESPIKE_VCD=1`` makes every
conformance check dump a VCD (and read it back, which must give the same
stream). A failing check always re-runs once with a VCD and keeps it under
``tests/vcd/`` (or ``$TESPIKE_VCD_DIR``), printing the path in the failure.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from tespike.golden.config import DESIGN_ELECTRONS, SensorConfig
from tespike.golden.reference import step_reference

VCD_DIR = Path(os.environ.get("TESPIKE_VCD_DIR", Path(__file__).resolve().parent / "vcd"))


def vcd_wanted() -> bool:
    return os.environ.get("TESPIKE_VCD", "") not in ("", "0")


def vcd_path_for(name: str) -> Path:
    VCD_DIR.mkdir(parents=True, exist_ok=True)
    return VCD_DIR / (re.sub(r"[^A-Za-z0-9_.-]+", "_", name)[:150] + ".vcd")


def light_stimulus(config: SensorConfig, rng, readouts: int, height: int, width: int,
                   light=None, dtype=np.int64) -> np.ndarray:
    """Poisson electrons per pixel clock; pixel i gets light ``light[i % len(light)]`` (I = 1: design).

    The default light spans twelve decades around the design point (1e-7 .. 1e5),
    so one array holds dark, mid, overflowing and input-saturating pixels.
    Electrons above 2^E - 1 saturate, as SPEC section 6 says a full photodiode does.
    """
    if light is None:
        light = [0.0, 1e-7, 1e-3, 0.05, 0.3, 1.0, 3.0, 1e3, 1e5, 1e-2, 0.6, 30.0]
    L = config.clocks_per_readout
    n = height * width
    levels = np.resize(np.asarray(light, np.float64), n).reshape(height, width)
    mean = DESIGN_ELECTRONS * levels / L
    electrons = rng.poisson(np.broadcast_to(mean, (readouts * L, height, width)))
    return np.minimum(electrons, config.input_max).astype(dtype)


def threshold_stimulus(config: SensorConfig, rng, readouts: int, height: int, width: int) -> np.ndarray:
    """Electrons scaled to the threshold (not to the design light), so small custom thresholds
    still see pixels below, near and far above overflow or saturation, plus bursts of 2^E - 1."""
    L = config.clocks_per_readout
    top = config.p_max * config.alpha if config.is_te else config.ml_max
    spikes = np.array([0, 0.2, 0.7, 1.0, 1.3, 4.0, 50.0]) * top          # spikes per readout
    levels = np.resize(spikes, height * width).reshape(height, width)
    mean = levels * config.threshold / L
    stim = np.minimum(rng.poisson(np.broadcast_to(mean, (readouts * L, height, width))), config.input_max)
    burst = rng.random(stim.shape) < 0.05
    stim[burst] = config.input_max
    return stim.astype(np.int64)


def golden_words(config: SensorConfig, stimulus: np.ndarray) -> np.ndarray:
    """The oracle: SPEC section 3 written literally (golden.reference.step_reference)."""
    words, state = step_reference(config, stimulus)
    assert state.clock == stimulus.shape[0]
    return words


def first_difference(expected: np.ndarray, got: np.ndarray) -> str:
    from tespike.cosim.compare import first_difference as first
    if expected.shape != got.shape:
        return f"shape {got.shape} != golden {expected.shape}"
    return first(got, expected).text()


def assert_rtl_matches_golden(config: SensorConfig, stimulus: np.ndarray, name: str, **kwargs) -> np.ndarray:
    """RTL == golden bit for bit; with TESPIKE_VCD=1 also VCD stream == live stream.

    On a mismatch the run is repeated with a waveform, kept for inspection, and
    its path is part of the failure message.
    """
    from tespike.cosim.rtlsim import rtl_run
    from tespike.cosim.vcd import waveform_words

    expected = golden_words(config, stimulus)
    vcd = vcd_path_for(name) if vcd_wanted() else None
    run = rtl_run(config, stimulus, vcd_path=vcd, gtkw_path=vcd and vcd.with_suffix(".gtkw"), **kwargs)
    if np.array_equal(run.words, expected):
        if vcd is not None:
            wave = waveform_words(vcd, config, stimulus.shape[1:])
            assert np.array_equal(wave.words, run.words) and np.array_equal(wave.clocks, run.clocks), \
                f"stream read back from {vcd} differs from the live stream"
            vcd.unlink()
            vcd.with_suffix(".gtkw").unlink()
        return run.words
    if vcd is None:
        vcd = vcd_path_for(name)
        rtl_run(config, stimulus, vcd_path=vcd, gtkw_path=vcd.with_suffix(".gtkw"), **kwargs)
    np.save(vcd.with_suffix(".stimulus.npy"), stimulus)
    raise AssertionError(f"RTL != golden for {config}: {first_difference(expected, run.words)}; "
                         f"waveform kept: gtkwave {vcd} {vcd.with_suffix('.gtkw')} "
                         f"(stimulus {vcd.with_suffix('.stimulus.npy')})")
