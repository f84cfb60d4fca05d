"""``stream-pixel-rule``: the streaming Verilog top's own text of the pixel rule
(:mod:`tespike.rtl.verilog_stream`) against the Amaranth pixel, both cut at the registers, proved
combinationally by Yosys ``miter`` + ``sat`` (:func:`prove_equivalence`)."""

from __future__ import annotations

import re
import time
from pathlib import Path

from tespike.golden.atomic import work_folder
from tespike.golden.config import SensorConfig

from .. import children
from .smtbmc import ProofToolError, ProofResult, keep_trace, run_tool

# -- the streaming Verilog top's pixel rule ---------------------------------------------------
class Equivalence:
    """The streaming Verilog top's pixel rule (:func:`tespike.rtl.verilog_stream.stream_pixel_rule_verilog`)
    beside the pixel of :mod:`tespike.rtl.pixel`, to be proved combinationally equivalent."""

    def __init__(self, config: SensorConfig, pixel_factory):
        self.config, self.pixel_factory = config, pixel_factory

    def registers(self) -> dict[str, int]:
        c = self.config
        return {"acc": c.acc_bits, **({"sfc": c.b1, "ovf": 1, "m": c.b2} if c.is_te
                                      else {"count": c.ml_bits})}


def stream_rule_equivalence(config: SensorConfig, pixel_factory=None) -> Equivalence:
    """The streaming top's one-pixel rule == the pixel proved against SPEC (``rule``), for every
    current state and input: next ``acc``, ``sfc``/``ovf``/``m`` or ``count``, the word, and the
    second buffer's entry (loaded with the word while ``frame_valid``)."""
    if pixel_factory is None:
        from tespike.rtl.pixel import pixel_class
        pixel_factory = pixel_class(config)
    return Equivalence(config, pixel_factory)


def _pixel_wrapper(config: SensorConfig, registers: dict[str, int]) -> str:
    """``gold``: the Amaranth pixel cut at its registers (``<reg>_q`` in, ``<reg>_d`` out, made
    by ``expose -evert-dff``) with the ports of the Verilog rule module; ``held_d`` is what the
    array's second buffer takes (the word while ``frame_valid``, else what it held)."""
    c, wd = config, config.word_bits
    ports = ([f"input [{c.input_bits - 1}:0] charge"] + ([f"input [{c.b2 - 1}:0] ccc"] if c.is_te else [])
             + ["input last", "input frame_valid", "input clear"]
             + [f"input [{w - 1}:0] {r}_q" for r, w in registers.items()] + [f"input [{wd - 1}:0] held_q"]
             + [f"output [{w - 1}:0] {r}_d" for r, w in registers.items()]
             + [f"output [{wd - 1}:0] held_d", f"output [{wd - 1}:0] word_now"])
    pins = ([".charge(charge)"] + ([".ccc(ccc)"] if c.is_te else [])
            + [".last(last)", ".clear(clear)", ".clk(1'b0)", ".rst(1'b0)", ".word(word_now)"]
            + [f".{r}_{x}({r}_{x})" for r in registers for x in "qd"])
    return (f"module gold ({', '.join(ports)});\n"
            f"  pixel u ({', '.join(pins)});\n"
            f"  assign held_d = frame_valid ? word_now : held_q;\n"
            f"endmodule\n")


_SAT_ROW = re.compile(r"^\s+\\(in|gold|gate)_(\S+)\s+(\S+)\s+\S+\s+\S+\s*$")


def _counterexample(log: str) -> str:
    """``sat -show-ports``'s table -> 'inputs ...; differ: out gold/gate ...' in one line."""
    values = {}
    for line in log.splitlines():
        found = _SAT_ROW.match(line)
        if found:
            values[(found.group(1), found.group(2))] = found.group(3)
    inputs = [f"{n}={v}" for (side, n), v in values.items() if side == "in"]
    differ = [f"{n} {v} (pixel) vs {values.get(('gate', n))} (stream rule)"
              for (side, n), v in values.items() if side == "gold" and values.get(("gate", n)) != v]
    return f"{', '.join(differ) or 'outputs differ'} at {' '.join(inputs)}"


def prove_equivalence(name: str, eq: Equivalence, trace_dir: Path) -> ProofResult:
    """Yosys ``miter -equiv`` + ``sat -prove-asserts``: the rule module of the streaming top
    against the Amaranth pixel (built without its word register, as the arrays use it) cut at
    its registers. Purely combinational, so one SAT call is the proof (no induction)."""
    from amaranth.back import rtlil

    from tespike.rtl.verilog_stream import stream_pixel_rule_verilog

    start = time.perf_counter()
    config, registers = eq.config, eq.registers()
    with work_folder("tespike-prove-") as tmp:
        work = Path(tmp)
        children.write_work_file(work / "pixel.il", rtlil.convert(eq.pixel_factory(config, word_register=False),
                                                                  name="pixel"))
        children.write_work_file(work / "gold.v", _pixel_wrapper(config, registers))
        rule = stream_pixel_rule_verilog(config)
        children.write_work_file(work / "rule.v", rule)
        rule_name = re.search(r"^module (\w+)", rule, re.M).group(1)
        script = "; ".join([
            "read_rtlil pixel.il", "hierarchy -top pixel", "proc", "flatten", "opt_clean",
            # each pixel register becomes an input (its value) and an output (its next value)
            "expose -evert-dff -sep _ t:$dff", "opt_clean",
            "select -assert-none t:$*ff* t:$*latch* t:$mem*",
            f"select -assert-count {len(registers)} pixel/i:*_q",
            "read_verilog gold.v", "hierarchy -check -top gold",   # refuses a port gold lacks
            "read_verilog rule.v", "proc", "opt_clean",
            "select -assert-none t:$*ff* t:$*latch* t:$mem*", f"rename {rule_name} gate",
            "miter -equiv -flatten -make_assert -make_outputs gold gate miter", "hierarchy -top miter",
            "sat -prove-asserts -show-ports -dump_vcd trace.vcd miter"])
        done = run_tool(["yosys", "-p", script], work)
        log = done.stdout + done.stderr
        if done.returncode == 0 and "SAT proof finished - no model found: SUCCESS!" in log:
            return ProofResult(name, True, time.perf_counter() - start)
        if "SAT proof finished - model found: FAIL!" not in log:
            errors = [line for line in log.splitlines() if "ERROR" in line] or log.strip().splitlines()[-1:]
            raise ProofToolError(f"{name}: yosys failed: {errors[0] if errors else children.ended(done.returncode)}"
                                 f"{children.room_note(work)}")
        trace = keep_trace(work / "trace.vcd", trace_dir, name) if (work / "trace.vcd").exists() else None
        return ProofResult(name, False, time.perf_counter() - start,
                      f"equivalence check: {_counterexample(log)}", trace)


