"""The RTL simulators a stimulus can run on, and the check every backend's words must pass.

``amaranth`` runs the Amaranth design in Python (:mod:`tespike.cosim.rtlsim`, the only one
writing a VCD); ``verilator`` and ``icarus`` run the generated Verilog. Both
``tespike rtl-sim`` and ``tespike demo`` offer :data:`NAMES` and call
:func:`backend` / :func:`checked_words`.
"""

from __future__ import annotations

import importlib

import numpy as np

from tespike.golden.errors import InputError, TespikeError

#: backend -> (module, function(config, stimulus) -> words) for the Verilog simulators;
#: imported only when chosen.
VERILOG_BACKENDS = {
    "verilator": ("tespike.cosim.verilator", "run_verilator"),
    "icarus": ("tespike.cosim.icarus", "run_icarus"),
}
#: Every backend, the default first.
NAMES = ("amaranth", *VERILOG_BACKENDS)


def backend(name: str):
    """The function ``(config, stimulus) -> words`` of a Verilog backend; one line when the
    name is unknown or the backend is not installed."""
    if name not in VERILOG_BACKENDS:
        raise InputError(f"--backend {name!r}: one of {', '.join(VERILOG_BACKENDS)} runs the Verilog")
    module, function = VERILOG_BACKENDS[name]
    try:
        return getattr(importlib.import_module(module), function)
    except ModuleNotFoundError as exc:
        if exc.name != module:
            raise
        raise TespikeError(f"backend {name!r} is not available in this installation "
                           f"(module {module} is missing)") from None


def checked_words(words, config, stimulus, name: str) -> np.ndarray:
    """A backend must return integer words (T / L, H, W) that SPEC section 4 allows."""
    from tespike.golden.decode import check_words
    T, H, W = stimulus.shape
    expected = (T // config.clocks_per_readout, H, W)
    words = np.asarray(words)
    if words.shape != expected or words.dtype.kind not in "iu":
        raise TespikeError(f"backend {name!r} returned {words.dtype} words of shape {words.shape}, "
                           f"not integer words of shape {expected}")
    check_words(words, config)
    return words
