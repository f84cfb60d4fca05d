"""Proofs of the design (``tespike prove``), one module per idea.

* :mod:`tespike.cosim.formal.pixel`: Amaranth harnesses of the pixel against SPEC sections 3-4
  (``rule``, ``rule-registered-word``, ``bounds``) and of the Amaranth streaming top
  (``stream``), proved by k-induction in :mod:`tespike.cosim.formal.smtbmc` (Yosys + yosys-smtbmc);
* :mod:`tespike.cosim.formal.rule_equivalence`: the streaming Verilog top's own pixel-rule text
  against the pixel (``stream-pixel-rule``, Yosys miter + sat);
* :mod:`tespike.cosim.formal.reference` and :mod:`tespike.cosim.formal.tops`: the generated Verilog tops,
  read from the text ``tespike verilog`` writes, against a SPEC reference written
  independently of rtl/, and the timing block's phase, proved by ABC
  (:mod:`tespike.cosim.formal.abc`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

from tespike.golden.config import SensorConfig
from tespike.golden.errors import InputError, is_count
from tespike.golden.paths import path_text

from .pixel import (STREAM_ARRAY, bounds_harness, corners, rule_harness, amaranth_stream_harness,
                    stream_lanes)
from .rule_equivalence import Equivalence, prove_equivalence, stream_rule_equivalence
from .smtbmc import SOLVERS, TOOLS, TOP_TOOLS, ProofToolError, ProofResult, require_tools
from .smtbmc import prove as _prove_harness

__all__ = ["SOLVERS", "TOOLS", "TOP_TOOLS", "ProofToolError", "ProofResult", "corners", "properties", "prove",
           "require_tools", "rule_harness", "bounds_harness", "amaranth_stream_harness",
           "stream_rule_equivalence", "STREAM_ARRAY", "stream_lanes"]


def prove(name: str, harness, *, depth: int, solver: str, trace_dir: Path) -> ProofResult:
    """Prove one pixel property: a harness by k-induction (base case and induction step, both
    ``depth`` long); a ``stream-pixel-rule`` equivalence by one SAT call. A depth that is no count
    >= 1, a solver not in :data:`SOLVERS` or a ``trace_dir`` that is no path is refused in one line
    (depth 0 had reported a proved property as failing, with a counterexample of nothing)."""
    if not is_count(depth, 1):
        raise InputError(f"depth {depth!r}: must be an integer >= 1 (clocks of the base case and the "
                         "induction step)")
    if not (isinstance(solver, str) and solver in SOLVERS):
        raise InputError(f"solver {solver!r}: must be one of {', '.join(SOLVERS)}")
    trace_dir = Path(path_text(trace_dir, "trace_dir"))
    if isinstance(harness, Equivalence):
        return prove_equivalence(name, harness, trace_dir)
    return _prove_harness(name, harness, depth=depth, solver=solver, trace_dir=trace_dir)


def properties(config: SensorConfig, pixel_factory=None) -> dict[str, Callable[[], object]]:
    """The properties of one configuration, name -> harness builder."""
    config = SensorConfig.required(config, "properties")
    if pixel_factory is None:
        from tespike.rtl.pixel import pixel_class
        pixel_factory = pixel_class(config)
    return {
        "rule": lambda: rule_harness(config, pixel_factory, word_register=False),
        "rule-registered-word": lambda: rule_harness(config, pixel_factory, word_register=True),
        "bounds": lambda: bounds_harness(config, pixel_factory),
        **({} if config.is_msb else {"stream": lambda: amaranth_stream_harness(config, *STREAM_ARRAY,
                                                                      stream_lanes(config))}),
        "stream-pixel-rule": lambda: stream_rule_equivalence(config, pixel_factory),
    }

