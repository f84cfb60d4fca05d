"""Solver driving for the proofs of the generated tops: Yosys to an AIGER model, ABC to a verdict.

The harness (:mod:`tespike.cosim.formal.tops`) goes through Yosys to gates (``prep -flatten``,
memories to registers, undefined bits made free inputs, ``techmap``, ``aigmap``) and to an
AIGER file whose bad-state outputs are the harness's assertions. ABC (``yosys-abc``, shipped
with Yosys) then runs:

* ``dprove``: sequential equivalence by signal correspondence (registers of the design
  found equal to the reference's are proved so by k-induction) and interpolation. Its
  "equivalent" is a proof for every input sequence of any length, from the initial state
  (``method`` ``unbounded``). This is what made the tops provable at all: yosys-smtbmc with
  z3 4.8 and ABC's plain BMC did not finish the first readout of a 2 x 3 array (92,000
  conflicts at frame 12), because an unrolled equivalence of two different structures gives a
  SAT solver no internal match to lean on; ``dprove`` finds the match.
* where ``dprove`` gives up (its frame or time limit), ``bmc3 -F bound``: every input
  sequence of ``bound`` clocks (``method`` ``BMC <bound>``).

A failed assertion is named by proving each assertion alone up to the failing frame
(:func:`prove_harness`); the verdict lines of ABC are kept in ``detail``.
"""

from __future__ import annotations

import re
import subprocess
import tempfile
import time
from dataclasses import dataclass, replace
from pathlib import Path

from .tops import Harness

#: Yosys passes from the harness's Verilog to an AIGER model with the assertions as bad states.
TO_AIGER = ("prep -flatten -top proof_top; memory_map; opt -fast; "
            "setundef -undriven -anyseq; setundef -anyseq; techmap; opt -fast; "
            "async2sync; dffunmap; aigmap; opt_clean")


#: Seconds ``dprove`` gets before the bounded check takes over (it proves most tops in a few
#: seconds; the ones it does not finish, it rarely finishes at all).
DPROVE_SECONDS = 30.0


@dataclass
class TopResult:
    name: str
    proved: bool
    seconds: float
    method: str          # "unbounded (dprove)", "BMC <n>", or what was tried on a failure
    detail: str = ""     # failure: frame and assertion; undecided: why


class AbcError(RuntimeError):
    """Yosys or ABC failed on a harness (not a verdict)."""


def _aiger(harness: Harness, work: Path, name: str) -> Path:
    (work / f"{name}.v").write_text(harness.text)
    done = subprocess.run(["yosys", "-q", "-p", f"read_verilog -formal {name}.v; {TO_AIGER}; "
                           f"write_aiger -zinit {name}.aig"], cwd=work, capture_output=True, text=True)
    if done.returncode != 0:
        lines = [line for line in (done.stderr + done.stdout).splitlines() if "ERROR" in line]
        raise AbcError(f"yosys failed on the harness: {(lines or ['no message'])[0].strip()}")
    return work / f"{name}.aig"


def _abc(aig: Path, commands: str, timeout: float) -> tuple[str, bool]:
    """(ABC's output, whether it finished within ``timeout`` seconds)."""
    try:
        done = subprocess.run(["yosys-abc", "-c", f"read_aiger {aig.name}; strash; {commands}"],
                              cwd=aig.parent, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return "", False
    return done.stdout + done.stderr, True


_FAILED = re.compile(r"Output (\d+) of miter \S+ was asserted in frame (\d+)")


def _verdict(log: str) -> tuple[str, int | None]:
    """``("proved" | "failed" | "undecided", frame of the failure)`` from ABC's output."""
    found = _FAILED.search(log)
    if found:
        return "failed", int(found.group(2))
    if re.search(r"Networks are equivalent|Property proved", log):
        return "proved", None
    if re.search(r"No output failed in (\d+) frames", log):
        return "undecided", None
    return "undecided", None


def _bmc_passed(log: str, bound: int) -> bool:
    found = re.search(r"No output (?:failed|asserted) in (\d+) frames", log)
    return bool(found) and int(found.group(1)) >= bound


def prove_harness(name: str, harness: Harness, *, timeout: float = 300.0) -> TopResult:
    """Prove one harness: ``dprove`` (unbounded), else BMC to the harness's bound."""
    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="tespike-prove-") as tmp:
        work = Path(tmp)
        aig = _aiger(harness, work, "top")
        log, finished = _abc(aig, "dprove", min(DPROVE_SECONDS, timeout))
        verdict, frame = _verdict(log) if finished else ("undecided", None)
        method = "unbounded (dprove)"
        if verdict == "undecided":
            method = f"BMC {harness.steps}"
            left = max(10.0, timeout - (time.perf_counter() - start))
            log, finished = _abc(aig, f"bmc3 -F {harness.steps}", left)
            found = _FAILED.search(log)
            if found:
                verdict, frame = "failed", int(found.group(2))
            elif finished and _bmc_passed(log, harness.steps):
                verdict = "proved"
            else:
                return TopResult(name, False, time.perf_counter() - start, method,
                                 f"undecided: neither dprove nor BMC {harness.steps} finished in {timeout:.0f} s")
        if verdict == "proved":
            return TopResult(name, True, time.perf_counter() - start, method)
        which = _name_failure(harness, work, frame)
        return TopResult(name, False, time.perf_counter() - start, method,
                         f"clock {frame}: {which}")


def _name_failure(harness: Harness, work: Path, frame: int) -> str:
    """The message of the first assertion that fails alone within ``frame`` + 1 clocks."""
    lines = harness.text.splitlines()
    for number, message in sorted(harness.messages.items()):
        alone = [line if k + 1 == number or k + 1 not in harness.messages else "" for k, line in enumerate(lines)]
        single = replace(harness, text="\n".join(alone) + "\n")
        try:
            aig = _aiger(single, work, f"alone{number}")
        except AbcError:
            continue
        log, _ = _abc(aig, f"bmc3 -F {frame + 1}", 60)
        if _FAILED.search(log):
            return message
    return "an assertion (not named: none fails alone)"
