"""Solver driving for the proofs of the generated tops: Yosys to an AIGER model, ABC to a verdict.

The harness (:mod:`tespike.cosim.formal.tops`) goes through Yosys to gates (``prep -flatten``,
memories to registers, undefined bits made free inputs, ``techmap``, ``aigmap``) and to an
AIGER file whose bad-state outputs are the harness's assertions. ABC (``yosys-abc``, shipped
with Yosys) then runs:

* ``scorr; pdr``: signal correspondence (registers and nodes of the design proved equal to
  the reference's by k-induction from the initial state, then merged), then property-directed
  reachability (IC3) on what is left. A pass is a proof for every input sequence of any
  length from the initial state (``method`` ``unbounded (scorr + pdr)``). This is what proves
  the ML tops: ``dprove`` alone stalled on them (the ML count 1 x 1 top at small clocks, 28
  registers and 210 AND gates, was undecided after 30 s in ``dprove``'s first reduction, and the 2 x 3
  top then needed more than 90 s of BMC), while after ``scorr`` nothing of the ML miter is
  left for ``pdr`` (0.01 s), and the TE tops at small clocks take 0.1-4 s.
* where that does not finish (:data:`PDR_SECONDS`), ``scorr; dprove``: the same
  correspondence, then ``dprove``'s retiming, induction and interpolation
  (``unbounded (scorr + dprove)``). It proves the TE streaming tops at the presets' own
  clocks (L = 240), where ``pdr`` does not finish in 120 s (the reference clears ``m`` at
  readout and the design keeps it, an equality that holds only while the flag is set, which
  signal correspondence cannot state and IC3 must learn over 240-clock intervals; the
  registered parallel top at those clocks ``pdr`` proves in about 1.5 s).
  Why not yosys-smtbmc and z3 here: z3 4.8 and ABC's plain BMC did not finish the first
  readout of a 2 x 3 array (92,000 conflicts at frame 12), because an unrolled equivalence
  of two different structures gives a SAT solver no internal match to lean on; signal
  correspondence finds the match.
* where neither finishes, ``bmc3 -F bound``: every input sequence of ``bound`` clocks
  (``method`` ``BMC <bound>``, at least three readout intervals and the drain).

A failed assertion is named by proving each assertion alone up to the failing frame
(:func:`prove_harness`); the verdict lines of ABC are kept in ``detail``.
"""

from __future__ import annotations

import re
import subprocess
import time
from dataclasses import replace
from pathlib import Path

from tespike.golden.atomic import work_folder
from tespike.golden.errors import InputError, is_positive_number

from .. import children
from .smtbmc import ProofResult
from .tops import Harness

#: Yosys passes from the harness's Verilog to an AIGER model with the assertions as bad states.
TO_AIGER = ("prep -flatten -top proof_top; memory_map; opt -fast; "
            "setundef -undriven -anyseq; setundef -anyseq; techmap; opt -fast; "
            "async2sync; dffunmap; aigmap; opt_clean")


#: Seconds ``scorr; pdr`` gets (every top at small clocks took under 5 s, the ML tops at the
#: presets' own clocks under 1 s; the TE streaming tops at their own clocks did not finish in 120 s).
PDR_SECONDS = 20.0

#: Seconds BMC always gets, however little of a harness's time is left (below it ABC barely
#: starts): the least time a top property may be given.
MIN_BMC_SECONDS = 10.0

#: Seconds ``scorr; dprove`` gets before the bounded check takes over (the TE 1 x 1 streaming
#: tops at the presets' own clocks took 12-41 s in it on 2 loaded cores).
DPROVE_SECONDS = 150.0

#: The unbounded attempts in order: (method, ABC commands after ``strash``, seconds at most).
UNBOUNDED = (("unbounded (scorr + pdr)", "scorr; pdr", PDR_SECONDS),
             ("unbounded (scorr + dprove)", "scorr; dprove", DPROVE_SECONDS))


class AbcError(RuntimeError):
    """Yosys or ABC failed on a harness (not a verdict)."""


def _aiger(harness: Harness, work: Path, name: str) -> Path:
    children.write_work_file(work / f"{name}.v", harness.text)
    done = children.run(["yosys", "-q", "-p", f"read_verilog -formal {name}.v; {TO_AIGER}; "
                         f"write_aiger -zinit {name}.aig"], cwd=work, capture_output=True, text=True)
    if done.returncode != 0:
        lines = [line for line in (done.stderr + done.stdout).splitlines() if "ERROR" in line]
        raise AbcError(f"yosys failed on the harness: {lines[0].strip() if lines else children.ended(done.returncode)}"
                       f"{children.room_note(work)}")
    return work / f"{name}.aig"


def _abc(aig: Path, commands: str, timeout: float) -> tuple[str, bool]:
    """(ABC's output, whether it finished within ``timeout`` seconds)."""
    try:
        done = children.run(["yosys-abc", "-c", f"read_aiger {aig.name}; strash; {commands}"],
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


def prove_harness(name: str, harness: Harness, *, timeout: float = 300.0) -> ProofResult:
    """Prove one harness: the :data:`UNBOUNDED` attempts in order, else BMC to the harness's bound,
    all within ``timeout`` seconds (a number of at least :data:`MIN_BMC_SECONDS`: BMC gets that much
    whatever is left, so less would be overrun, and text had failed at the first subtraction)."""
    if not (is_positive_number(timeout) and timeout >= MIN_BMC_SECONDS):
        raise InputError(f"timeout {timeout!r}: must be a number of seconds of at least {MIN_BMC_SECONDS:g}")
    start = time.perf_counter()

    def left() -> float:
        return timeout - (time.perf_counter() - start)

    with work_folder("tespike-prove-") as tmp:
        work = Path(tmp)
        aig = _aiger(harness, work, "top")
        verdict, frame = "undecided", None
        for method, commands, seconds in UNBOUNDED:
            if left() <= 1.0:
                break
            log, finished = _abc(aig, commands, min(seconds, left()))
            verdict, frame = _verdict(log) if finished else ("undecided", None)
            if verdict != "undecided":
                break
        if verdict == "undecided":
            method = f"BMC {harness.steps}"
            log, finished = _abc(aig, f"bmc3 -F {harness.steps}", max(MIN_BMC_SECONDS, left()))
            found = _FAILED.search(log)
            if found:
                verdict, frame = "failed", int(found.group(2))
            elif finished and _bmc_passed(log, harness.steps):
                verdict = "proved"
            else:
                return ProofResult(name, False, time.perf_counter() - start, method=method,
                                   detail=f"undecided: neither an unbounded proof nor BMC {harness.steps} "
                                          f"finished in {timeout:.3g} s")
        if verdict == "proved":
            return ProofResult(name, True, time.perf_counter() - start, method=method)
        which = _name_failure(harness, work, frame)
        return ProofResult(name, False, time.perf_counter() - start, method=method,
                           detail=f"clock {frame}: {which}")


def _name_failure(harness: Harness, work: Path, frame: int) -> str:
    """The message of the first assertion (in the harness's order) that fails alone: by
    ``scorr; pdr`` (a few seconds where BMC of an equivalence to the failing clock takes tens),
    else by BMC within ``frame`` + 1 clocks."""
    lines = harness.text.splitlines()
    for number, message in sorted(harness.messages.items()):
        alone = [line if k + 1 == number or k + 1 not in harness.messages else "" for k, line in enumerate(lines)]
        single = replace(harness, text="\n".join(alone) + "\n")
        try:
            aig = _aiger(single, work, f"alone{number}")
        except AbcError:
            continue
        for commands, seconds in (("scorr; pdr", PDR_SECONDS), (f"bmc3 -F {frame + 1}", 60)):
            log, finished = _abc(aig, commands, seconds)
            verdict = _verdict(log)[0] if finished else "undecided"
            if verdict == "failed":
                return message
            if verdict == "proved" and commands.endswith("pdr"):
                break                      # holds for every input sequence: not this one
    return "an assertion (not named: none fails alone)"
