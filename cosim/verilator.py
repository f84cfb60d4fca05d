"""Run the generated Verilog of either top in Verilator, for scale (SPEC section 6 ports only).

:func:`run_verilator` (the parallel top, ``tespike.rtl.verilog.array_verilog``) and
:func:`run_verilator_stream` (the streaming top, ``--lanes N``, up to the
400 x 250 sensor) write the top's Verilog and one C++ harness
(:func:`harness_cpp`, its output ports taken from :class:`tespike.cosim.tops.Top`) that
knows nothing but the SPEC section 6 ports: it holds ``rst`` for
:data:`~tespike.cosim.outside.RESET_CLOCKS` clocks, then applies one stimulus row (and
its ``rst``, with a reset vector) per pixel clock, samples the outputs before
every rising edge at which ``frame_valid`` / ``out_valid`` is high, and writes
what it saw to a binary file. The build (``verilator --cc --exe --build -O3``)
is cached under a hash of the Verilog, the harness, the flags and the Verilator
version, so a second run of the same array skips it.

Files between Python and the harness (little-endian):

- stimulus: T rows of ``ceil(H*W*E / 32)`` uint32 words, the ``charge`` port's
  bits exactly as Verilator stores a wide port (word 0 = bits 31..0);
- resets (optional): one byte, 0 or 1, per stimulus clock;
- captures: records of one uint64 sample clock, for the streaming top a uint32
  ``out_first``, and the word port's ``ceil(bits / 32)`` uint32 words.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

from tespike.golden.atomic import work_folder
from tespike.golden.config import SensorConfig
from tespike.golden.errors import InputError, is_count
from tespike.golden.io import atomic_output
from tespike.golden.paths import path_text

from . import children
from .outside import (RESET_CLOCKS, SimulatorBuildError, SimulatorRunError, cache_entry, content_hash,
                      default_cache_root, first_error_line, pack_rows, require_tool, words_per_row)
from .tops import RunPlan, Top, check_stream_lanes, prepare

#: Verilator options of every build. ``-O3``: Verilator's own optimisation;
#: ``--x-assign/--x-initial fast``: X is irrelevant after the synchronous reset.
VERILATOR_FLAGS = ("--cc", "--exe", "--build", "-O3", "--x-assign", "fast",
                   "--x-initial", "fast", "--noassert")

#: Lint categories waived on the command line. None are needed: Verilator's
#: default warnings are fatal, and the generated Verilog carries its own
#: ``verilator lint_off`` comments, with reasons, around the Amaranth-generated
#: modules (see rtl/verilog.py). A new warning therefore fails the build loudly.
LINT_WAIVERS: dict[str, str] = {}

#: C++ optimisation of the model's code (verilated.mk's ``OPT_FAST``; its
#: default is ``-Os``). Measured on the paper-TE 32 x 32 array in one session
#: (docs/outside-simulators.md): ``-O1`` built in 42 CPU-s and ran at about 7200
#: cycles per CPU-second; ``-O2`` built in 56 CPU-s and ran no faster; ``-O0``
#: built in 32 CPU-s but ran 2.8x slower (at 4096 pixels 7x slower, and
#: built no faster).
CXX_OPT = "-O1"

#: The C++ optimisation levels a build may ask for (``cxx_opt=``).
CXX_OPTS = ("-O0", "-O1", "-O2", "-O3", "-Os")

#: Verilator's runtime objects and precompiled verilated.h; the first build
#: makes them (about 30 s on a loaded machine), later builds reuse them.
_RUNTIME_OBJECTS = ("verilated.o", "verilated_threads.o")

#: Stimulus rows the harness reads at once.
READ_ROWS = 4096

#: Rows packed and written at once.
_WRITE_ROWS = 4096

_EXECUTABLE = "tespike_sim"


#: Verilator-only comment that keeps a pixel's ``charge`` input a variable of
#: the instance (see :func:`shared_pixel_view`).
_KEEP_PORT = "/* verilator public_flat_rd */"


def shared_pixel_view(verilog: str, pixel_module: str) -> str:
    """The same Verilog with the pixel module's ``charge`` input marked ``public_flat_rd``.

    Verilator 5.006 otherwise replaces the port by its connection
    (``charge[i*E +: E]`` of the array), so every instance gets its own copy
    of the pixel's code. Marked, the port stays a variable of the instance, the
    per-instance functions become identical and Verilator merges them into one:
    for 32 x 32 pixels 3.1 MB of C++ instead of 7.7 MB (docs/outside-simulators.md).
    A comment only: the logic, the ports and every other line are unchanged.
    Raises ``ValueError`` if the module or its one ``charge`` declaration is
    not found (the Verilog is then not the generated array).
    """
    start = re.search(rf"^module {re.escape(pixel_module)}\(.*$", verilog, re.M)
    if start is None:
        raise ValueError(f"module {pixel_module} not found in the Verilog")
    end = verilog.index("\nendmodule", start.end())
    body = verilog[start.end():end]
    body, count = re.subn(r"^(  wire (?:\[\d+:0\] )?charge);$", rf"\1 {_KEEP_PORT};", body,
                          flags=re.M)
    if count != 1:
        raise ValueError(f"module {pixel_module}: expected one 'wire charge;' declaration, "
                         f"found {count}")
    return verilog[:start.end()] + body + verilog[end:]


def c_type(bits: int) -> str:
    """The smallest unsigned C++ integer type of ``bits`` bits (1 to 64: a wider port is a ``VlWide``)."""
    if not is_count(bits, 1) or bits > 64:
        raise InputError(f"bits {bits!r}: a C++ integer holds 1 to 64")
    return "uint8_t" if bits <= 8 else "uint16_t" if bits <= 16 else "uint32_t" if bits <= 32 else "uint64_t"


def _port_io(port: str, bits: int, into: bool) -> str:
    """C++ that copies 32-bit words ``w`` into (``into``) or out of the port ``top-><port>``.

    Verilator stores a port of up to 64 bits in an integer (CData/SData/IData/
    QData) and a wider one in ``VlWide`` (32-bit words, word 0 least significant).
    """
    words = (bits + 31) // 32
    if bits > 64:
        return (f"std::memcpy(top->{port}.data(), w, sizeof(uint32_t) * {words});" if into else
                f"std::memcpy(w, top->{port}.data(), sizeof(uint32_t) * {words});")
    if bits > 32:
        return (f"top->{port} = (uint64_t)w[0] | ((uint64_t)w[1] << 32);" if into else
                f"uint64_t v = top->{port}; w[0] = (uint32_t)v; w[1] = (uint32_t)(v >> 32);")
    return f"top->{port} = ({c_type(bits)})w[0];" if into else f"w[0] = (uint32_t)top->{port};"


#: Each top's outputs as the harness sees them: (valid port, word port, whether a record
#: carries ``out_first`` as a uint32 between the clock and the words).
HARNESS_OUTPUTS = {"frame": ("frame_valid", "frame", False), "beats": ("out_valid", "out_words", True)}


def harness_cpp(top: str, charge_bits: int, output_bits: int, outputs: str = "frame") -> str:
    """C++ ``main`` driving only ``clk``, ``rst`` and ``charge`` and recording the SPEC outputs.

    ``outputs`` is ``"frame"`` (the parallel top: records of a uint64 clock and the
    ``frame`` words, one per clock with ``frame_valid`` high) or ``"beats"`` (the
    streaming top: a uint64 clock, a uint32 ``out_first`` and the ``out_words``
    words, one per clock with ``out_valid`` high). Arguments: STIMULUS CLOCKS
    EXPECTED FLUSH CAPTURES PROGRESS_EVERY [RESETS], RESETS a file of one byte
    (0 or 1) per stimulus clock, ``rst`` of that clock (:mod:`tespike.cosim.resets`);
    EXPECTED counts the records after the last reset edge.
    """
    if not isinstance(outputs, str) or outputs not in HARNESS_OUTPUTS:
        raise InputError(f"outputs {outputs!r}: must be one of {', '.join(HARNESS_OUTPUTS)}")
    valid, word_port, has_first = HARNESS_OUTPUTS[outputs]
    in_words = (charge_bits + 31) // 32
    out_words = (output_bits + 31) // 32
    record_first = (" || std::fwrite(&first, sizeof first, 1, out) != 1" if has_first else "")
    first_line = "            const uint32_t first = top->out_first;\n" if has_first else ""
    return f"""// tespike Verilator harness for {top}: SPEC section 6 ports only (generated).
#include "Varray.h"
#include "verilated.h"
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <vector>

static const size_t IN_WORDS = {in_words};
static const size_t OUT_WORDS = {out_words};
static const size_t READ_ROWS = {READ_ROWS};
static const int RESET_CLOCKS = {RESET_CLOCKS};

static inline void set_charge(Varray* top, const uint32_t* w) {{ {_port_io("charge", charge_bits, True)} }}
static inline void get_words(const Varray* top, uint32_t* w) {{ {_port_io(word_port, output_bits, False)} }}

static int fail(const char* what, const char* path) {{
    std::fprintf(stderr, "tespike_sim: %s %s\\n", what, path);
    return 3;
}}

int main(int argc, char** argv) {{
    if (argc != 7 && argc != 8) {{
        std::fprintf(stderr, "usage: %s STIMULUS CLOCKS EXPECTED FLUSH CAPTURES PROGRESS_EVERY [RESETS]\\n",
                     argv[0]);
        return 2;
    }}
    const char* stim_path = argv[1];
    const uint64_t clocks = std::strtoull(argv[2], nullptr, 10);
    const uint64_t expected = std::strtoull(argv[3], nullptr, 10);
    const uint64_t flush = std::strtoull(argv[4], nullptr, 10);
    const char* out_path = argv[5];
    const uint64_t progress = std::strtoull(argv[6], nullptr, 10);

    std::FILE* in = std::fopen(stim_path, "rb");
    if (!in) return fail("cannot open stimulus", stim_path);
    std::vector<uint8_t> resets(clocks, 0);
    if (argc == 8) {{
        std::FILE* rf = std::fopen(argv[7], "rb");
        if (!rf) return fail("cannot open resets", argv[7]);
        const size_t got = std::fread(resets.data(), 1, clocks, rf);
        std::fclose(rf);
        if (got != clocks) return fail("resets file too short:", argv[7]);
    }}
    std::FILE* out = std::fopen(out_path, "wb");
    if (!out) return fail("cannot open captures", out_path);

    const std::unique_ptr<VerilatedContext> context{{new VerilatedContext}};
    const std::unique_ptr<Varray> top{{new Varray{{context.get()}}}};
    const size_t read_rows = READ_ROWS * IN_WORDS > (1u << 24) ? 16 : READ_ROWS;   // at most ~64 MB
    std::vector<uint32_t> rows(read_rows * IN_WORDS), zero(IN_WORDS, 0), words(OUT_WORDS, 0);

    top->clk = 0;
    top->rst = 1;
    set_charge(top.get(), zero.data());
    top->eval();
    for (int i = 0; i < RESET_CLOCKS; ++i) {{
        top->clk = 1; top->eval();
        top->clk = 0; top->eval();
    }}
    top->rst = 0;

    uint64_t captured = 0;
    size_t have = 0, next = 0;
    for (uint64_t t = 0; t < clocks + flush; ++t) {{
        if (t >= clocks && captured >= expected) break;
        const uint32_t* row = zero.data();
        if (t < clocks) {{
            if (next == have) {{
                const uint64_t left = clocks - t;
                const size_t want = left < read_rows ? (size_t)left : read_rows;
                if (std::fread(rows.data(), sizeof(uint32_t) * IN_WORDS, want, in) != want)
                    return fail("stimulus file too short:", stim_path);
                have = want;
                next = 0;
            }}
            row = &rows[next++ * IN_WORDS];
        }}
        set_charge(top.get(), row);
        top->rst = t < clocks ? resets[t] : 0;
        top->clk = 0;
        top->eval();                      // inputs of clock t settle; sample before the edge
        if (top->{valid}) {{
{first_line}            get_words(top.get(), words.data());
            if (std::fwrite(&t, sizeof t, 1, out) != 1{record_first} ||
                std::fwrite(words.data(), sizeof(uint32_t), OUT_WORDS, out) != OUT_WORDS)
                return fail("cannot write captures", out_path);
            ++captured;
        }}
        if (top->rst) captured = 0;       // a reset edge: count the records after it
        top->clk = 1;
        top->eval();                      // rising edge t
        if (progress && (t + 1) % progress == 0) {{
            std::printf("%llu\\n", (unsigned long long)(t + 1));
            std::fflush(stdout);
        }}
    }}
    top->final();
    std::fclose(in);
    if (std::fclose(out) != 0) return fail("cannot write captures", out_path);
    return 0;
}}
"""


def verilator_version() -> str:
    exe = require_tool("verilator", "verilator")
    result = children.run([exe, "--version"], capture_output=True, text=True)
    return result.stdout.strip()


def build_jobs() -> int:
    """Parallel compile jobs: the cores this process may use, at most 4."""
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:
        cores = os.cpu_count() or 1
    return max(1, min(4, cores))


def check_cxx_opt(cxx_opt: str) -> str:
    """``cxx_opt`` if it is one of :data:`CXX_OPTS`, else one line (:class:`InputError`)."""
    if cxx_opt not in CXX_OPTS:
        raise InputError(f"cxx_opt {cxx_opt!r}: the C++ optimisation must be one of "
                         f"{', '.join(CXX_OPTS)}")
    return cxx_opt


def build_flags(top: str, inline: bool = False, cxx_opt: str = CXX_OPT,
                extra: tuple[str, ...] = ()) -> list[str]:
    """Verilator options of a build. By default with ``-fno-inline`` (pixel modules
    kept apart): for 1024 pixels it built in 41-49 CPU-s instead of 233 and ran as
    fast (about 7300 cycles per CPU-second either way; docs/outside-simulators.md).
    ``inline=True`` gives Verilator's default module inlining; ``cxx_opt`` is g++'s
    optimisation of the model (:data:`CXX_OPT`); ``extra`` are more Verilator
    options (the benchmark's experiments, e.g. ``-fno-dfg``), part of the cache key."""
    return [*VERILATOR_FLAGS, *([] if inline else ["-fno-inline"]), *LINT_WAIVERS,
            "--top-module", top, "--prefix", "Varray", "-o", _EXECUTABLE,
            "-MAKEFLAGS", f"OPT_FAST={check_cxx_opt(cxx_opt)}", *extra]


def _runtime_dir(root: Path, cxx_opt: str = CXX_OPT) -> Path:
    """Where the runtime objects live: in the user's cache whatever ``build_dir`` is
    (they depend only on Verilator and the flags), else beside the builds."""
    name = "runtime-" + content_hash(" ".join(VERILATOR_FLAGS), cxx_opt, verilator_version())
    shared = default_cache_root() / "verilator"
    try:
        shared.mkdir(parents=True, exist_ok=True)
        return shared / name
    except OSError:
        return root / name


def _reuse_runtime(runtime: Path, obj: Path) -> list[str]:
    """Put the cached runtime objects into ``obj``; return the Verilator flags that use them.

    The objects are copied and marked with make's ``--old-file`` (use, never
    remake: they depend on nothing the model changes). The precompiled
    verilated.h is used through ``-include`` (g++ then skips parsing the header,
    4-5 s per file on a loaded machine; it silently parses it after all if the
    flags ever differ).
    """
    if not all((runtime / name).is_file() for name in _RUNTIME_OBJECTS):
        return []
    obj.mkdir()
    flags = []
    for name in _RUNTIME_OBJECTS:
        shutil.copyfile(runtime / name, obj / name)
        flags += ["-MAKEFLAGS", f"--old-file={name}"]
    header = runtime / "pch" / "verilated.h"
    if Path(str(header) + ".gch").is_file():
        flags += ["-CFLAGS", f"-include {header}"]
    return flags


def _keep_runtime(obj: Path, runtime: Path, cxx_opt: str = CXX_OPT) -> None:
    """After the first successful build: save its runtime objects and precompile verilated.h.

    The header is compiled by make with the model's own variables (an include of
    the generated ``Varray.mk``), so its flags are those of every later compile.
    Saved atomically; a failure to precompile only costs speed.
    """
    if runtime.is_dir() or not all((obj / name).is_file() for name in _RUNTIME_OBJECTS):
        return
    with work_folder(f".{runtime.name}-", runtime.parent) as staging:   # (renamed into place whole)
        for name in _RUNTIME_OBJECTS:
            shutil.copyfile(obj / name, staging / name)
        pch_tmp = obj / "pch"
        pch_tmp.mkdir()
        (obj / "pch.mk").write_text(
            "include Varray.mk\n"
            "pch/verilated.h.gch:\n"
            "\tln -sf $(VERILATOR_ROOT)/include/verilated.h pch/verilated.h\n"
            "\t$(CXX) $(CXXFLAGS) $(CPPFLAGS) $(OPT_FAST) -x c++-header pch/verilated.h -o $@\n")
        made = children.run(["make", "-f", "pch.mk", f"OPT_FAST={cxx_opt}", "pch/verilated.h.gch"],
                            cwd=obj, capture_output=True, text=True)
        if made.returncode == 0 and (pch_tmp / "verilated.h.gch").is_file():
            shutil.move(str(pch_tmp), staging / "pch")
        try:
            os.rename(staging, runtime)
        except OSError:                          # another process saved them first (removed on leaving)
            pass


def build(verilog: str, top: str, charge_bits: int, frame_bits: int, *,
          build_dir: str | Path | None = None, progress: bool = False, inline: bool = False,
          cxx_opt: str = CXX_OPT, extra_flags: tuple[str, ...] = (), harness: str | None = None) -> Path:
    """Build (or find in the cache) the simulation executable; return its path.

    ``harness`` is the C++ ``main`` (default: :func:`harness_cpp` of the parallel
    ports; the streaming top brings its own, :func:`build_stream`).

    The cache key is a hash of the Verilog, the harness, the flags and the
    Verilator version. A build runs in a temporary directory renamed into
    place on success, under a lock, so concurrent runs never see half a build.
    """
    exe = require_tool("verilator", "verilator")
    if harness is None:
        harness = harness_cpp(top, charge_bits, frame_bits)
    flags = build_flags(top, inline, cxx_opt, tuple(extra_flags))
    root = Path(path_text(build_dir, "build_dir")) if build_dir is not None else default_cache_root() / "verilator"
    key = content_hash(verilog, harness, " ".join(flags), verilator_version())
    with cache_entry(root, key) as (final, done):
        if done:
            return final / _EXECUTABLE
        if progress:
            print(f"tespike: building the Verilator model of {top} in {final} ...", file=sys.stderr)
        # a killed build leaves no hidden folder in the cache (the janitor removes it)
        with work_folder(f".{key}.build-", root) as work:
            children.write_work_file(work / "array.v", verilog)
            children.write_work_file(work / "harness.cpp", harness)
            runtime = _runtime_dir(root, cxx_opt)
            reuse = _reuse_runtime(runtime, work / "obj")
            argv = [exe, *flags, *reuse, "-j", str(build_jobs()), "-Mdir", "obj", "array.v",
                    "harness.cpp"]
            result = children.run(argv, cwd=work, capture_output=True, text=True)
            (work / "build.log").write_text(" ".join(argv) + "\n" + result.stdout + result.stderr)
            if result.returncode != 0 or not (work / "obj" / _EXECUTABLE).is_file():
                failed_log = root / f"{key}.failed.log"
                shutil.copyfile(work / "build.log", failed_log)
                raise SimulatorBuildError(
                    f"Verilator build of {top} failed (exit {result.returncode}): "
                    f"{first_error_line(result.stderr + result.stdout)} (full log: {failed_log})"
                    f"{children.room_note(work)}")
            shutil.move(str(work / "obj" / _EXECUTABLE), work / _EXECUTABLE)
            _keep_runtime(work / "obj", runtime, cxx_opt)
            shutil.rmtree(work / "obj")
            (work / "done").write_text(key + "\n")
            if final.exists():
                shutil.rmtree(final)             # a stale entry without its "done" mark
            os.rename(work, final)
    return final / _EXECUTABLE


def write_stimulus_file(path: str | Path, stimulus: np.ndarray, bits: int) -> None:
    """(T, H, W) checked stimulus -> the harness's binary rows, written atomically in chunks."""
    T = stimulus.shape[0]
    flat = stimulus.reshape(T, -1)
    with atomic_output(path) as tmp, open(tmp, "wb") as handle:
        for a in range(0, T, _WRITE_ROWS):
            handle.write(pack_rows(flat[a:a + _WRITE_ROWS], bits).tobytes())


def write_resets_file(path: str | Path, resets: np.ndarray) -> None:
    """The reset vector as the harness reads it: one byte, 0 or 1, per stimulus clock."""
    with atomic_output(path) as tmp:
        Path(tmp).write_bytes(np.asarray(resets, np.uint8).tobytes())


def read_captures(path: str | Path, frame_words: int) -> tuple[np.ndarray, np.ndarray]:
    """The parallel harness's records -> (clocks, frame rows)."""
    record = np.dtype([("clock", "<u8"), ("frame", "<u4", (frame_words,))])
    data = np.fromfile(path, dtype=record)
    return data["clock"].astype(np.int64), data["frame"].reshape(len(data), frame_words)


def read_beat_captures(path: str | Path, lane_words: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The streaming harness's records -> (clocks, firsts, lane rows)."""
    record = np.dtype([("clock", "<u8"), ("first", "<u4"), ("lanes", "<u4", (lane_words,))])
    data = np.fromfile(path, dtype=record)
    return (data["clock"].astype(np.int64), data["first"].astype(bool),
            data["lanes"].reshape(len(data), lane_words))


def run_executable(executable: Path, stim_path: Path, cap_path: Path, clocks: int, expected: int, flush: int,
                   progress: bool = False, resets_path: Path | None = None) -> None:
    """Run a built model (either top's harness) on a stimulus file; captures go to ``cap_path``.

    ``expected``: records after the last reset edge (the run stops once the stimulus
    is over and they are in); ``resets_path``: :func:`write_resets_file`'s file.
    """
    every = max(1, min(1 << 16, clocks // 100)) if progress else 0
    argv = [str(executable), str(stim_path), str(clocks), str(expected), str(flush), str(cap_path), str(every)]
    if resets_path is not None:
        argv.append(str(resets_path))
    with children.popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) as process:
        try:
            if progress:
                from tqdm import tqdm
                with tqdm(total=clocks, unit="clk", desc="verilator", file=sys.stderr) as bar:
                    done = 0
                    for line in process.stdout:
                        clock = min(int(line), clocks)
                        bar.update(clock - done)
                        done = clock
            _, err = process.communicate()
        except BaseException:          # interrupted (Ctrl-C, SIGTERM): no simulator left running
            process.kill()
            raise
    if process.returncode != 0:
        raise SimulatorRunError(f"Verilator simulation of {executable} failed (exit {process.returncode}): "
                                f"{first_error_line(err)}")


def build_stream(config: SensorConfig, verilog: str, height: int, width: int, lanes: int, *,
                 build_dir=None, progress: bool = False, cxx_opt: str = CXX_OPT,
                 extra_flags: tuple[str, ...] = ()) -> Path:
    """Build (or find in the cache) the Verilator model of a streaming top; return the executable.

    With Verilator's module inlining: the streaming top's Verilog holds one copy of
    the pixel rule whatever the size (:mod:`tespike.rtl.verilog_stream`); ``-fno-inline``
    would only keep the timing module apart.
    """
    top = Top(config, height, width, lanes)
    return build(verilog, top.module, top.charge_bits, top.output_bits, build_dir=build_dir,
                 progress=progress, inline=True, cxx_opt=cxx_opt, extra_flags=tuple(extra_flags),
                 harness=harness_cpp(top.module, top.charge_bits, top.output_bits, outputs="beats"))


def run_verilator(config: SensorConfig, stimulus: np.ndarray, *, build_dir: str | Path | None = None,
                  progress: bool = False, verilog: str | None = None, inline: bool = False,
                  cxx_opt: str = CXX_OPT, shared: bool = True, resets=None):
    """Simulate the generated Verilog of a (T, H, W) stimulus in Verilator; return words (K, H, W).

    ``build_dir`` is the root of the build cache (default: ``$TESPIKE_CACHE`` or
    ``~/.cache/tespike``, then ``verilator/``). ``verilog`` replaces the array
    Verilog (tests use a hand-written model of the same ports); by default it
    is ``tespike.rtl.verilog.array_verilog(config, H, W)``. ``inline=True`` builds with
    Verilator's default module inlining instead of ``-fno-inline`` (see
    :func:`build_flags`); ``cxx_opt`` is g++'s optimisation of the model
    (:data:`CXX_OPT`). ``shared=True`` builds :func:`shared_pixel_view` of
    Verilog that has the ``<te|ml>_pixel`` module (the generated array; a
    hand-written model without it is built as given); ``shared=False`` builds
    the text exactly as given. The words are int64, equal bit for bit to
    ``tespike.golden.sensor.simulate`` for a correct array. ``resets`` (T booleans):
    ``rst`` of every stimulus clock (:mod:`tespike.cosim.resets`); the result is then a
    list of each segment's words ``(n, H, W)``.
    """
    config = SensorConfig.required(config, "run_verilator")
    def build_parallel(text: str, top) -> Path:
        pixel = top.module.replace("_array", "")
        if shared and re.search(rf"^module {pixel}\(", text, re.M):
            text = shared_pixel_view(text, pixel)
        return build(text, top.module, top.charge_bits, top.output_bits, build_dir=build_dir,
                     progress=progress, inline=inline, cxx_opt=cxx_opt)

    return _run(prepare(config, stimulus, None, resets), verilog, cxx_opt, build_parallel, progress)


def run_verilator_stream(config: SensorConfig, stimulus: np.ndarray, lanes: int, *,
                         build_dir=None, progress: bool = False, verilog: str | None = None,
                         cxx_opt: str = CXX_OPT, resets=None):
    """Simulate the streaming top on a (T, H, W) stimulus in Verilator; return beats (K, B, N).

    Equal to ``tespike.golden.beats.beats(golden words, N)`` for a correct array; the beat
    timing is held to SPEC section 6 (:func:`tespike.cosim.stream_ports.check_beats`).
    ``verilog`` replaces ``tespike.rtl.verilog_stream.stream_array_verilog(config, H, W, N)``.
    ``resets`` (T booleans): ``rst`` of every stimulus clock (:mod:`tespike.cosim.resets`); the
    result is then a list of each segment's beats ``(n, N)``.
    """
    config = SensorConfig.required(config, "run_verilator_stream")
    check_stream_lanes(lanes, "run_verilator_stream")

    def build_streaming(text: str, top) -> Path:
        return build_stream(config, text, top.height, top.width, lanes, build_dir=build_dir,
                            progress=progress, cxx_opt=cxx_opt)

    return _run(prepare(config, stimulus, lanes, resets), verilog, cxx_opt, build_streaming, progress)


def _run(run: RunPlan, verilog: str | None, cxx_opt: str, build_model, progress: bool):
    """Build ``verilog`` (default: the top's generated text) with ``build_model(text, top)`` and
    run it on ``run``, either top; its words, beats, or each segment's (nothing is built for an
    idle run)."""
    check_cxx_opt(cxx_opt)
    if verilog is not None and not isinstance(verilog, str):   # (a TypeError in the build)
        raise InputError(f"verilog: must be the Verilog text to simulate, not {type(verilog).__name__}")
    top = run.top
    if run.idle:
        return top.empty()
    executable = build_model(top.verilog() if verilog is None else verilog, top)
    with work_folder("tespike-verilator-") as scratch:
        stim_path, cap_path = Path(scratch) / "stimulus.bin", Path(scratch) / "captures.bin"
        write_stimulus_file(stim_path, run.stimulus, top.config.input_bits)
        resets_path = None
        if run.resets is not None:
            resets_path = Path(scratch) / "resets.bin"
            write_resets_file(resets_path, run.resets)
        run_executable(executable, stim_path, cap_path, run.stimulus.shape[0], run.expected, top.flush,
                       progress, resets_path)
        words = words_per_row(top.word_values, top.config.word_bits)
        if top.streaming:
            clocks, firsts, rows = read_beat_captures(cap_path, words)
        else:
            (clocks, rows), firsts = read_captures(cap_path, words), []
    return top.result(run, clocks, firsts, rows, top.describe("Verilator"))
