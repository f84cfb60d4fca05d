"""Run the cocotb testbench (:mod:`tespike.cosim.cocotb_bench`) under Icarus, Verilator or another simulator.

:func:`run_cocotb` writes the array Verilog (``tespike.rtl.verilog.array_verilog``, or
a file the caller names: a designer's own Verilog with the SPEC section 6
ports), builds it with cocotb's runner (``cocotb.runner.get_runner``) and runs
the test module in the simulator. The build is cached under a hash of the
Verilog, the simulator, its version and cocotb's version
(``<cache>/cocotb/``), so a second run of the same array only simulates.
``tespike cocotb`` is the command line of it.

Simulators: whatever cocotb's runner knows (``icarus``, ``verilator``,
``questa``, ``xcelium``, ``vcs``, ``riviera``, ...); the project tests Icarus
(Debian's 11) and Verilator (Debian's 5.006) with cocotb 1.9 (cocotb 2 wants
Verilator 5.036 or newer). Icarus is built with ``-g2005`` after cocotb's own
``-g2012``: the generated Verilog is Verilog-2005 (docs/rtl.md).
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import os
import re
import shutil
import sys
import types
from pathlib import Path

from tespike.golden.atomic import work_folder
from tespike.golden.errors import InputError

from .cocotb_bench import Settings
from . import children
from .outside import (SimulatorBuildError, SimulatorMissingError, cache_entry, content_hash,
                      default_cache_root, first_error_line)
from .tops import Top

#: The test module cocotb loads in the simulator.
TEST_MODULE = "tespike.cosim.cocotb_bench"

#: Simulators the project runs in its own tests, with the executables each needs.
TESTED_SIMULATORS = {"icarus": ("iverilog", "vvp"), "verilator": ("verilator",)}

#: Extra build options per simulator (see the module docstring).
BUILD_ARGS = {"icarus": ["-g2005"], "verilator": []}

#: Where this package's root is, so the simulator's embedded Python imports ``cosim`` and ``golden``.
_ROOT = str(Path(__file__).resolve().parent.parent)


@dataclasses.dataclass
class CocotbResult:
    """One simulator's verdict."""

    simulator: str
    passed: bool
    message: str            # one line: the failure, or a summary of the pass
    log: Path               # the simulation log (kept)


def cocotb_version() -> str:
    try:
        import cocotb
    except ImportError:
        raise SimulatorMissingError("cocotb is not installed (pip install 'cocotb>=1.8,<2')") from None
    return cocotb.__version__


def _simulator_version(simulator: str) -> str:
    tools = TESTED_SIMULATORS.get(simulator)
    if tools is None:
        return ""
    for tool in tools:
        if shutil.which(tool) is None:
            package = "iverilog" if simulator == "icarus" else simulator
            raise SimulatorMissingError(f"{tool!r} is not on PATH; install it (Debian/Ubuntu: "
                                        f"apt-get install {package})")
    flag = "-V" if simulator == "icarus" else "--version"
    result = children.run([tools[0], flag], capture_output=True, text=True)
    return (result.stdout or result.stderr).splitlines()[0] if (result.stdout or result.stderr) else ""


@contextlib.contextmanager
def _quiet(path: Path):
    """The runner's own ``print``s (the commands it runs) go to ``path``, not to our stdout."""
    buffer = io.StringIO()
    try:
        with contextlib.redirect_stdout(buffer):
            yield
    finally:
        with open(path, "a") as handle:
            handle.write(buffer.getvalue())


@contextlib.contextmanager
def _outside_pytest():
    """cocotb's runner changes its result handling when it sees ``PYTEST_CURRENT_TEST``
    (it raises on failure and refuses a results file name); this module reads the
    results itself the same way under pytest and on the command line."""
    saved = os.environ.pop("PYTEST_CURRENT_TEST", None)
    try:
        yield
    finally:
        if saved is not None:
            os.environ["PYTEST_CURRENT_TEST"] = saved


@contextlib.contextmanager
def _children_end_with_us():
    """cocotb's runner starts the compiler, make and the simulator with ``subprocess.run``;
    within this block they run through :func:`tespike.cosim.children.run_group` instead, so that
    a command killed outright or interrupted leaves no simulator or compiler running."""
    import warnings
    with warnings.catch_warnings():      # "Python runners ... are an experimental feature" (as _runner)
        warnings.simplefilter("ignore", UserWarning)
        import cocotb.runner as module
    real = module.subprocess
    module.subprocess = types.SimpleNamespace(**{name: getattr(real, name) for name in dir(real)
                                                 if not name.startswith("__")})
    module.subprocess.run = children.run_group
    try:
        yield
    finally:
        module.subprocess = real


def check_simulator(simulator: str) -> None:
    """Refuse, in one line, a simulator cocotb's runner does not know or cannot find."""
    _runner(simulator)


def _runner(simulator: str):
    import warnings
    with warnings.catch_warnings():      # "Python runners ... are an experimental feature"
        warnings.simplefilter("ignore", UserWarning)
        from cocotb.runner import get_runner
    try:
        return get_runner(simulator)
    except (ValueError, SystemExit) as exc:
        if "not found" in str(exc):     # a simulator cocotb knows, not installed here
            raise InputError(f"simulator {simulator!r} is not installed ({exc})") from None
        raise InputError(f"simulator {simulator!r}: cocotb's runner does not know it ({exc})") from None


def _failure_line(log: Path) -> str:
    """The failure cocotb logged: the test's AssertionError or error line, else the log's last line."""
    text = log.read_text(errors="replace") if log.is_file() else ""
    errors = re.findall(r"^\s*(\w*(?:Error|Exception): .+)$", text, re.M)
    return errors[-1].strip() if errors else first_error_line(text)


def build(verilog_path: Path, top: str, simulator: str, cache_root: Path | None = None) -> Path:
    """Build (or find in the cache) the simulation of ``verilog_path``; return its build directory."""
    text = verilog_path.read_text()
    key = content_hash(text, top, simulator, _simulator_version(simulator), cocotb_version(),
                       " ".join(BUILD_ARGS.get(simulator, [])))
    root = (cache_root or default_cache_root()) / "cocotb"
    with cache_entry(root, key) as (final, done):
        if done:
            return final
        # built in a hidden folder of the cache renamed into place once done: a stop or a kill mid-build
        # leaves no half-built entry (the folder goes with the run, by the janitor if it is killed)
        try:
            with work_folder(f".{key}.build-", root) as work:
                log = work / "build.log"
                source = work / "array.v"
                try:
                    children.write_work_file(source, text)
                    with _outside_pytest(), _quiet(work / "commands.txt"), _children_end_with_us():
                        _runner(simulator).build(verilog_sources=[source], hdl_toplevel=top, build_dir=work,
                                                 build_args=BUILD_ARGS.get(simulator, []), always=True,
                                                 log_file=log)
                    (work / "done").write_text(key + "\n")
                except SystemExit:
                    failed = root / f"{key}.failed.log"
                    shutil.copyfile(log, failed)
                    line = first_error_line(failed.read_text(errors="replace"))   # about the cache's copy: the user's file
                    raise SimulatorBuildError(f"cocotb {simulator} build of {top} failed: "
                                              f"{line.replace(str(source), str(verilog_path))} "
                                              f"(full log: {failed})") from None
                if final.exists():
                    shutil.rmtree(final)         # a stale entry without its "done" mark
                os.rename(work, final)
        except OSError as exc:                  # (a full disk under the cache named no file)
            if exc.filename is not None and not str(exc.filename).startswith(str(root)):
                raise
            raise InputError(f"cannot write the {simulator} build {str(final)!r} (the build cache: $TESPIKE_CACHE, "
                             f"else ~/.cache/tespike): {exc.strerror or exc}") from None
    return final


def check_ports(verilog_path: Path, top: Top) -> str | None:
    """Refuse (one line) a Verilog file whose top lacks a port of SPEC section 6, or has one of
    another direction or width: the testbench reaches signals by name, and an internal net of a
    port's name would pass for it (a top whose ``frame_valid`` was renamed passed, exit 0). Read by
    Yosys's parser (``write_json``); -> a note where Yosys is missing or cannot parse the file (the
    simulator still checks the widths it sees), None where the ports were checked."""
    from .synthesis import SynthesisError, yosys_missing, yosys_run
    missing = yosys_missing()
    if missing:
        return f"ports not checked before the run ({missing})"
    try:
        with yosys_run(verilog_path.read_text(), [f"hierarchy -top {top.module}", "proc", "write_json ports.json"],
                       f"yosys could not read {top.module}", prefix="tespike-ports-") as (work, _):
            ports = json.loads((work / "ports.json").read_text())["modules"][top.module]["ports"]
    except (SynthesisError, KeyError, ValueError) as exc:
        return f"ports not checked before the run (Yosys could not read the file: {exc})"
    for name, (direction, bits) in top.ports.items():
        port = ports.get(name)
        found = "no such port" if port is None else f"an {port['direction']} of {len(port['bits'])} bit(s)"
        if port is None or port["direction"] != direction or len(port["bits"]) != bits:
            raise InputError(f"Verilog file {str(verilog_path)!r}: module {top.module} port {name}: {found}; "
                             f"SPEC section 6 wants an {direction} of {bits} bit(s) for {top.height} x "
                             f"{top.width} pixels{f' and {top.lanes} lanes' if top.streaming else ''}")
    return None


def run_cocotb(settings: Settings, simulator: str = "icarus", *, verilog_path: str | Path | None = None,
               work_dir: str | Path | None = None, cache_root: Path | None = None) -> CocotbResult:
    """Run :func:`tespike.cosim.cocotb_bench.spec_ports_equal_golden` on one simulator.

    ``verilog_path``: the Verilog to test (default: the generated array of
    ``settings``); ``work_dir``: where the run's log and results go (default: a
    temporary directory, the log copied to ``<cache>/cocotb/last-<simulator>.log``).
    """
    cocotb_version()
    _runner(simulator)                     # refuse an unknown simulator,
    if settings.lanes is not None:
        from tespike.golden.beats import check_lanes
        check_lanes(settings.config, settings.height, settings.width, settings.lanes)
    design = Top(settings.config, settings.height, settings.width, settings.lanes)
    top = design.module
    settings.inputs()                      # and a bad stimulus or reset vector, before building anything
    given = verilog_path is not None
    with work_folder("tespike-cocotb-") as scratch:
        if verilog_path is None:
            verilog_path = Path(scratch) / "array.v"
            if settings.lanes is None:
                from tespike.rtl.verilog import array_verilog
                text = array_verilog(settings.config, settings.height, settings.width)
            else:
                from tespike.rtl.verilog_stream import stream_array_verilog
                text = stream_array_verilog(settings.config, settings.height, settings.width, settings.lanes)
            verilog_path.write_text(text)
        verilog_path = Path(verilog_path)
        if given:                       # (a folder, a FIFO or a link loop: named as what it is)
            from tespike.golden.paths import check_input_file
            check_input_file(verilog_path, "--verilog")
        note = check_ports(verilog_path, design) if given else None
        build_dir = build(verilog_path, top, simulator, cache_root)
        if note is not None:            # (after the build: a file it refuses gets its one line alone)
            print(f"cocotb: {verilog_path}: {note}", file=sys.stderr)
        # absolute: the simulator runs in test_dir and reads the results file's path from there
        test_dir = Path(work_dir).resolve() if work_dir is not None else Path(scratch) / "run"
        test_dir.mkdir(parents=True, exist_ok=True)
        log, results = test_dir / f"{simulator}.log", test_dir / f"{simulator}-results.xml"
        if _ROOT not in sys.path:
            sys.path.insert(0, _ROOT)      # the runner passes sys.path on as PYTHONPATH
        runner = _runner(simulator)
        from cocotb.runner import get_results
        try:
            with _outside_pytest(), _quiet(test_dir / f"{simulator}-commands.txt"), _children_end_with_us():
                runner.test(test_module=TEST_MODULE, hdl_toplevel=top, hdl_toplevel_lang="verilog",
                            build_dir=build_dir,
                            test_dir=test_dir, results_xml=str(results), extra_env=settings.to_env(),
                            log_file=log)
            tests, failed = get_results(results)
        except SystemExit:
            tests, failed = 0, 1
        passed = tests >= 1 and failed == 0
        text = log.read_text(errors="replace") if log.is_file() else ""
        summary = re.search(r"RTL == golden model (\{.*\})", text)
        if passed and summary and json.loads(summary.group(1)).get("golden_outputs") == 0:
            raise InputError(f"{simulator}: nothing was compared: no stretch of the stimulus between resets "
                             "holds a whole readout interval (no output words, RTL's or the golden model's)")
        message = (f"RTL == golden model {summary.group(1)}" if passed and summary else
                   "passed" if passed else _failure_line(log))
        if work_dir is None:
            kept = (cache_root or default_cache_root()) / "cocotb" / f"last-{simulator}.log"
            kept.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(log, kept) if log.is_file() else kept.write_text("(no log)\n")
            log = kept
        return CocotbResult(simulator, passed, message, log)
