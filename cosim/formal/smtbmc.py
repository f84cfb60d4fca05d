"""Tools and solver driving for the pixel proofs: Yosys (RTLIL to SMT-LIB2) and yosys-smtbmc.

An Amaranth harness (:mod:`tespike.cosim.formal.pixel`) goes to RTLIL, Yosys (``prep``,
``write_smt2``) and ``yosys-smtbmc``, which proves it by k-induction: a base case (no
assertion fails in the first k clocks from the initial state) and an induction step (k
clocks in a row where every assertion holds, from *any* state, imply the next one holds
too). Both passing is a proof for every input sequence of any length.

Amaranth 0.5 writes its assertions as ``$check`` cells, which Yosys 0.23 (Debian's)
predates; :func:`_yosys_checks` rewrites each combinational check into the ``$assert`` /
``$assume`` cell that Yosys 0.23 reads (the same condition and enable).
"""

from __future__ import annotations

import contextlib
import re
import shutil
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path

from tespike.golden.atomic import atomic_output, work_folder
from tespike.golden.errors import TespikeError

from .. import children

SOLVERS = {"z3": "z3"}
#: Tools the proofs need: executable -> Debian package; the tops' proofs (ABC) need TOP_TOOLS alone.
TOOLS = {"yosys": "yosys", "yosys-smtbmc": "yosys", "yosys-abc": "yosys"}
TOP_TOOLS = {"yosys": "yosys", "yosys-abc": "yosys"}


class ProofToolError(TespikeError, RuntimeError):
    """A tool the proof needs is missing or failed (one line: which and how to install)."""


def require_tools(solver: str | None, tools: dict = TOOLS) -> None:
    """Refuse in one line when one of ``tools`` or the SMT ``solver`` is not on PATH (``solver``
    None: no solver, for the tops' proofs alone, which run ABC)."""
    if solver is not None and (not isinstance(solver, str) or solver not in SOLVERS):
        raise ProofToolError(f"--solver {solver!r}: must be one of {', '.join(SOLVERS)}")
    for tool, package in {**tools, **({} if solver is None else {solver: SOLVERS[solver]})}.items():
        if shutil.which(tool) is None:
            raise ProofToolError(f"{tool!r} is not on PATH; the proof needs it "
                                 f"(Debian/Ubuntu: apt-get install {package})")


# -- Yosys and yosys-smtbmc ----------------------------------------------------------------
_CHECK = re.compile(r"cell \$check (\S+)\n(.*?)\n  end\n", re.S)


def _yosys_checks(text: str) -> tuple[str, dict[str, str]]:
    """Amaranth 0.5's combinational ``$check`` cells -> Yosys 0.23's ``$assert``/``$assume``;
    also returns each cell's message (the ``Assert``'s text), by cell name."""
    messages = {}

    def rewrite(match):
        body = match.group(2)
        flavor = re.search(r'parameter \\FLAVOR "(\w+)"', body).group(1)
        if re.search(r"parameter \\TRG_ENABLE 1", body) or flavor not in ("assert", "assume"):
            raise ProofToolError(f"only combinational Assert/Assume are supported here (got {flavor})")
        message = re.search(r'parameter \\FORMAT "(.*)"', body)
        messages[match.group(1)] = message.group(1) if message else ""
        a = re.search(r"connect \\A (.*)", body).group(1)
        en = re.search(r"connect \\EN (.*)", body).group(1)
        return f"cell ${flavor} {match.group(1)}\n    connect \\A {a}\n    connect \\EN {en}\n  end\n"
    return _CHECK.sub(rewrite, text), messages


@dataclass
class ProofResult:
    """One property's verdict, whichever engine proved it (yosys-smtbmc here, ABC for the tops:
    :func:`tespike.cosim.formal.abc.prove_harness`)."""

    name: str
    proved: bool
    seconds: float
    detail: str = ""           # failure: which step or frame and assertion; undecided: why
    trace: Path | None = None  # failure (yosys-smtbmc): the counterexample VCD
    method: str = ""           # ABC: "unbounded (scorr + pdr)", "unbounded (scorr + dprove)", "BMC <n>"


def run_tool(cmd: list[str], cwd: Path) -> subprocess.CompletedProcess:
    return children.run(cmd, cwd=cwd, capture_output=True, text=True)


def _failed_assertion(log: str, messages: dict[str, str]) -> str:
    """The first failed assertion's message (``Assert failed in top: src (cell)`` in the log)."""
    for line in log.splitlines():
        if "Assumptions are unsatisfiable" in line:
            return "the assumptions are unsatisfiable"
        found = re.search(r"Assert failed in \S+ (.*)\((\S+)\)", line)
        if found:
            return messages.get(found.group(2)) or found.group(1).strip()
    return "no failed assertion named in the log"


def keep_trace(vcd: Path, trace_dir: Path, name: str) -> Path:
    """A solver's counterexample ``vcd`` kept as ``trace_dir/NAME.vcd``: whole, or the earlier file
    untouched, and a write that fails (a full disk) names the trace, not the solver's temporary
    (``shutil.copyfile`` named its source); a ``trace_dir`` made here and left empty goes."""
    made = not trace_dir.exists()
    trace_dir.mkdir(parents=True, exist_ok=True)
    trace = trace_dir / f"{name}.vcd"
    try:
        with atomic_output(trace, "counterexample trace") as part, open(vcd, "rb") as source, \
                open(part, "wb") as target:
            shutil.copyfileobj(source, target)
    except BaseException:
        if made:
            with contextlib.suppress(OSError):
                trace_dir.rmdir()
        raise
    return trace


def prove(name: str, harness, *, depth: int, solver: str, trace_dir: Path) -> ProofResult:
    """Prove one harness by k-induction with yosys-smtbmc (base case and induction step, both
    ``depth`` long); :func:`tespike.cosim.formal.prove` sends an equivalence elsewhere first."""
    from amaranth.back import rtlil

    start = time.perf_counter()
    with work_folder("tespike-prove-") as tmp:
        work = Path(tmp)
        text = rtlil.convert(harness.m, ports=harness.inputs, name="top")
        text, messages = _yosys_checks(text)
        children.write_work_file(work / "top.il", text)
        # The streaming harness goes to gates (techmap): its word_select becomes a $shift by a
        # $mul, which z3 4.8 does not finish as words. The pixel harnesses solve faster as words.
        gates = "techmap; opt -fast; " if getattr(harness, "gate_level", False) else ""
        script = (f"read_rtlil top.il; prep -flatten -top top; {gates}async2sync; "
                  "dffunmap; write_smt2 -wires top.smt2")
        done = run_tool(["yosys", "-q", "-p", script], work)
        if done.returncode != 0:
            said = (done.stderr or done.stdout).strip().splitlines()[-1:]      # (nothing said: how it ended)
            raise ProofToolError(f"{name}: yosys failed: {said[0] if said else children.ended(done.returncode)}"
                                 f"{children.room_note(work)}")
        for step, extra in (("base case", []), ("induction step", ["-i"])):
            vcd = work / "trace.vcd"
            done = run_tool(["yosys-smtbmc", "-s", solver, *extra, "-t", str(depth),
                         "--dump-vcd", str(vcd), "top.smt2"], work)
            if "Status: PASSED" in done.stdout:
                continue
            if "Status: FAILED" not in done.stdout:
                said = (done.stdout.strip().splitlines() or done.stderr.strip().splitlines())[-1:]
                raise ProofToolError(f"{name}: yosys-smtbmc ({solver}) gave no verdict: "
                                     f"{said[0] if said else children.ended(done.returncode)}{children.room_note(work)}")
            trace = keep_trace(vcd, trace_dir, name) if vcd.exists() else None
            return ProofResult(name, False, time.perf_counter() - start,
                          f"{step}: {_failed_assertion(done.stdout, messages)}", trace)
    return ProofResult(name, True, time.perf_counter() - start)


