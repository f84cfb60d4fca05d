"""The ``tespike`` command (SPEC section 6).

Each sub-command lives in its own module under :mod:`tespike.cosim.commands` with
``HELP``, ``add_arguments(parser)`` and ``run(args) -> int``. Modules import
their heavy dependencies (amaranth, torch) inside ``run`` so that ``tespike
golden`` and ``tespike simulate`` start in numpy time. Every refusal of bad
input is one line on stderr and a non-zero exit, never a traceback.
"""

from __future__ import annotations

import argparse
import errno
import importlib
import os
import sys

from tespike.cosim.console import (StandardOutputError, closed_at_start, closed_pipe, drop_standard_output,
                                   name_standard_output)
from tespike.golden.errors import TespikeError, one_line
from tespike.golden.resources import address_space_text


#: sub-command -> module under cosim.commands
COMMANDS = {
    "golden": "golden_cmd",
    "simulate": "simulate_cmd",
    "stimulus": "stimulus_cmd",
    "rtl-sim": "rtl_sim_cmd",
    "verilog": "verilog_cmd",
    "synthesize": "synthesize_cmd",
    "cocotb": "cocotb_cmd",
    "calibrate": "calibrate_cmd",
    "reconstruct": "reconstruct_cmd",
    "evaluate": "evaluate_cmd",
    "score": "score_cmd",
    "demo": "demo_cmd",
    "scene": "scene_cmd",
    "view": "view_cmd",
    "train": "train_cmd",
    "dataset": "dataset_cmd",
    "prove": "prove_cmd",
}

EXIT_BAD_INPUT = 2
#: Signals that end a run like Ctrl-C does: temporaries are removed on the way out.
CLEANUP_SIGNALS = ("SIGTERM", "SIGHUP")


class Terminated(BaseException):
    """Raised in the main thread by SIGTERM / SIGHUP so ``finally`` blocks clean up."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


class Parser(argparse.ArgumentParser):
    """argparse with one-line errors: ``tespike CMD: error: argument --x: ... (see tespike CMD --help)``,
    and ``type=int`` / ``type=float`` options read as typed (:func:`tespike.cosim.commands.common.decimal`,
    :func:`tespike.cosim.commands.common.number`)."""

    def __init__(self, *args, **kwargs):
        from tespike.cosim.commands.common import decimal, number
        super().__init__(*args, **kwargs)
        self.register("type", int, decimal)
        self.register("type", float, number)

    def parse_known_args(self, args=None, namespace=None):
        self._tokens = list(sys.argv[1:] if args is None else args)     # (for error's hint)
        return super().parse_known_args(args, namespace)

    def error(self, message):
        text = " ".join(message.split()) + self._dash_hint(message)
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {text} (see {self.prog} --help)\n")

    def _dash_hint(self, message: str) -> str:
        """argparse reads a value that starts with '-' (``--frames -1:``) as an option and
        says the option lacks its value: name the value, and the form that passes it."""
        import re
        missing = re.match(r"argument ([^:]+): expected one argument", message)
        if not missing:
            return ""
        spellings = missing.group(1).split("/")
        tokens = getattr(self, "_tokens", [])
        for option, value in zip(tokens, tokens[1:]):
            if option in spellings and value.startswith("-"):
                return f" ({value!r} was read as an option: give {option}={value})"
        return ""


def version() -> str:
    """The installed package's version, or the checkout's when not installed."""
    from importlib import metadata
    try:
        return metadata.version("tespike")
    except metadata.PackageNotFoundError:
        return "0.1.0+checkout"


def _available_commands(only: str | None = None) -> dict[str, object]:
    modules = {}
    for name, module in COMMANDS.items():
        if only is not None and name != only:
            continue
        try:
            modules[name] = importlib.import_module(f"tespike.cosim.commands.{module}")
        except ModuleNotFoundError as exc:
            if exc.name != f"tespike.cosim.commands.{module}":
                raise
    return modules


class _VersionAction(argparse.Action):
    """``--version``: looks the version up only when asked (the package metadata lookup
    costs about 30 ms, measured, which every run paid when the parser was built)."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS,
                 help="show the version and exit"):
        super().__init__(option_strings, dest, nargs=0, default=default, help=help)

    def __call__(self, parser, namespace, values, option_string=None):
        print(f"tespike {version()}")
        parser.exit()


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The whole command line; with ``only`` (a sub-command's name) just that
    sub-command's part, which spares a run importing and building the others (about 30 ms
    of a ``tespike simulate`` that may take 0.5 s)."""
    parser = Parser(
        prog="tespike",
        description="Time-encoding spike camera: golden model, RTL, co-simulation and reconstruction.",
        epilog="Run 'tespike COMMAND --help' for a command's flags. Bare 'tespike' prints this help.")
    parser.add_argument("--version", action=_VersionAction)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, module in _available_commands(only).items():
        command = sub.add_parser(name, help=module.HELP, description=module.HELP)
        module.add_arguments(command)
        _add_common_arguments(command, getattr(module, "PROGRESS", False))
        command.set_defaults(run=module.run, command_parser=command)
    return parser


def _add_common_arguments(command: argparse.ArgumentParser, progress: bool) -> None:
    """--quiet on every sub-command (unless it defines its own, as demo does), and --progress on
    those that draw progress (a command's ``PROGRESS``: elsewhere the flag would do nothing)."""
    if "--quiet" not in command._option_string_actions:
        command.add_argument("--quiet", "-q", action="store_true",
                             help="print nothing on stdout on success (errors still go to stderr)")
    if not progress:
        return
    command.add_argument("--progress", choices=("auto", "on", "off"), default="auto",
                         help="progress bars on stderr: auto (only when stderr is a terminal; evaluate prints "
                              "plain progress lines to a log file instead), on, off")


def _raise_terminated(signum, frame):
    from tespike.golden.atomic import note_stop
    note_stop(signum)
    raise Terminated(signum)


def _raise_interrupted(signum, frame):
    from tespike.golden.atomic import note_stop
    note_stop(signum)
    raise KeyboardInterrupt


def _install_signal_handlers() -> dict:
    """SIGTERM / SIGHUP raise :class:`Terminated`, Ctrl-C KeyboardInterrupt as Python's own handler
    does (if nobody else handles them), each recorded (:func:`tespike.golden.atomic.note_stop`: one
    that Python drops in a finalizer is raised again before an output is renamed into place and when
    the command returns); returns the previous handlers for :func:`_restore_signal_handlers`."""
    import signal
    import threading
    previous = {}
    if threading.current_thread() is not threading.main_thread():
        return previous
    for name in ("SIGINT", *CLEANUP_SIGNALS):
        number = getattr(signal, name, None)
        if number is None:
            continue
        handler = signal.getsignal(number)
        if number == signal.SIGINT:
            if handler is signal.default_int_handler:
                previous[number] = signal.signal(number, _raise_interrupted)
        # (the entry point's own, tespike.entry, holds the signals while numpy loads)
        elif handler in (signal.SIG_DFL, None) or getattr(handler, "tespike_early", False):
            previous[number] = signal.signal(number, _raise_terminated)
    return previous


def _restore_signal_handlers(previous: dict) -> None:
    import signal
    for number, handler in previous.items():
        signal.signal(number, handler if handler is not None else signal.SIG_DFL)


def _end_quietly(code: int) -> None:
    """Once the command has ended (its line printed, its outputs whole), Ctrl-C, SIGTERM or SIGHUP
    during the interpreter's exit (torch's and Dask's exit handlers take up to a second) ends the
    process at once with the command's own exit status ``code``: not a KeyboardInterrupt traceback
    from an exit handler, nor a death by the signal with no line (exit -2, what a run stopped
    part-way looks like, where this one had ended and said so)."""
    import signal

    from tespike.entry import end_process
    for name in ("SIGINT", *CLEANUP_SIGNALS):
        number = getattr(signal, name, None)
        if number is not None and signal.getsignal(number) is not signal.SIG_IGN:    # nohup's stays
            signal.signal(number, lambda signum, frame: end_process(code))


#: What a RuntimeError (torch's allocator) or an ImportError (a shared library that could not be
#: mapped) says when memory, not the program, was at fault.
OUT_OF_MEMORY = ("can't allocate memory", "not enough memory", "Cannot allocate memory",
                 "failed to map segment from shared object")
#: ... and what counts so only under an address-space limit (oneDNN's words for a failed allocation).
OUT_OF_MEMORY_UNDER_LIMIT = ("could not create a primitive", "could not execute a primitive")


def _notes(exc: BaseException) -> str:
    """What the interrupted command noted on the exception (e.g. the checkpoint it saved), one line."""
    notes = getattr(exc, "__notes__", ())
    return " " + one_line("; ".join(notes), 300) if notes else ""


def _written(since: int, exc: BaseException) -> list[str]:
    """A failed or interrupted command's outputs that were already complete (a fault after the
    last one was moved into place: the user must know the file is whole and new), less those
    its own message or note names (train's "checkpoint ... saved", "wrote the weights to ...")."""
    from tespike.golden.atomic import finished_outputs
    said = str(exc) + " ".join(getattr(exc, "__notes__", ()))
    # each file once, where it was first written (train rewrites best.pt and curves.png at every validation)
    return [path for path in dict.fromkeys(finished_outputs(since)) if repr(path) not in said]


def _after(since: int, exc: BaseException) -> str:
    """`` after writing 'S.npz' whole`` for an interrupted command's line ('' if nothing was)."""
    done = _written(since, exc)
    return f" after writing {one_line(', '.join(repr(p) for p in done))} whole" if done else ""


def _before(since: int, exc: BaseException) -> str:
    """`` (after writing 'T.pt' whole)`` for a failed command's line ('' if nothing was)."""
    after = _after(since, exc)
    return f" ({after.strip()})" if after else ""


def main(argv: list[str] | None = None) -> int:
    whole_process = argv is None
    argv = sys.argv[1:] if argv is None else list(argv)
    if whole_process:
        name_standard_output()
    try:
        args = _parse(argv)
    except SystemExit as exc:         # help, --version, usage errors: what argparse printed, written out
        if whole_process:
            _write_out_standard_output("tespike")
        raise exc
    except StandardOutputError:       # (--version's line)
        _write_out_standard_output("tespike")
        raise
    if args is None:
        return _write_out_standard_output("tespike") if whole_process else 0
    if whole_process and closed_at_start() and not getattr(args, "quiet", False):
        # refused before the run, not after its work was done (it had written its files, then failed to say so)
        print(f"tespike {args.command}: error: standard output: closed (the command started without one): "
              "give --quiet, or an open standard output", file=sys.stderr)
        return EXIT_BAD_INPUT
    args.argv = argv                  # the command line as given (a run records how it was made)
    previous = _install_signal_handlers()

    def prepare():                    # (in _run: a stop while preparing ends in its one line too)
        from .library_room import guard_imports
        guard_imports()               # torch loads with the stops held (and, under ulimit -v, is tried in a child first)
        if whole_process:             # removes the run's temporaries should it be killed outright
            from tespike.golden.atomic import run_temporaries, start_janitor
            start_janitor(report_faults=True, name=f"tespike {args.command}")
            run_temporaries()         # (the tools' and libraries' temporaries too: all in one held folder)
    import warnings
    code, ok = 1, False   # (what the finally below ends with, should _run itself be stopped)
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            code, ok = _run(args, prepare, lambda code: (_restore_signal_handlers(previous),
                                                         whole_process and _end_quietly(code)))
    finally:              # main() called in-process (tests) leaves the caller's handlers as they were
        _restore_signal_handlers(previous)
        from tespike.golden.atomic import forget_stops
        forget_stops()    # (the next command, in this process too, starts with no stop recorded)
        if whole_process:
            _end_quietly(code)
    if ok:            # only a run that succeeded shows its warnings; a refusal stays one line
        for warning in caught:
            warnings.showwarning(warning.message, warning.category, warning.filename, warning.lineno)
    elif whole_process:   # ... also at interpreter exit (e.g. a coroutine the interruption left)
        warnings.simplefilter("ignore")
    return code


def _parse(argv: list[str]):
    """The command line's arguments, or None where there is no command (the help is printed)."""
    parser = build_parser(argv[0] if argv and argv[0] in COMMANDS else None)
    if not argv:
        parser.print_help()
        return None
    if len(argv) > 1 and argv[0].startswith("--v") and "--version".startswith(argv[0]):
        parser.error(f"--version takes nothing else (given: {' '.join(argv[1:])})")   # (argparse exits at it)
    args, unknown = parser.parse_known_args(argv)
    if unknown:       # named by the sub-command's parser: "tespike train: ... (see tespike train --help)"
        getattr(args, "command_parser", parser).error(f"unrecognized arguments: {' '.join(unknown)}")
    empty = _empty_text(getattr(args, "command_parser", parser), args)
    if empty:         # '' reads as "not given" where a command tests the value's truth
        getattr(args, "command_parser", parser).error(f"{empty} '': an empty value (give one)")
    repeated = _repeated_option(getattr(args, "command_parser", parser), argv)
    if repeated:      # argparse keeps the last value and drops the others without a word
        getattr(args, "command_parser", parser).error(f"{repeated} is given more than once: give it once")
    if args.command is None:          # only top-level options, e.g. "tespike -q"
        parser.print_help()
        return None
    return args


def _write_out_standard_output(prefix: str) -> int:
    """Flush standard output outside a command (help, usage): 0, or the status of its one line
    when it failed (a full disk under ``> help.txt``), never Python's "Exception ignored" at exit."""
    try:
        sys.stdout.flush()
        return 0
    except StandardOutputError as exc:
        code = _standard_output_failed(prefix, exc)
        if code == EXIT_BAD_INPUT:
            raise SystemExit(code) from None
        return code


def _standard_output_failed(prefix: str, exc: StandardOutputError, after: str = "") -> int:
    """The exit status of a command whose standard output failed, its one line printed: quiet where
    the reader went away (``| head``), as a tool killed by SIGPIPE; what is still buffered is dropped."""
    drop_standard_output()
    if closed_pipe(exc):
        return 128 + 13
    print(f"{prefix}: error: standard output: {one_line(exc.strerror or exc, 300)}{after}", file=sys.stderr)
    return EXIT_BAD_INPUT


def _empty_text(parser, args) -> str | None:
    """The first text argument of ``parser`` given as ``''`` (its name: ``--folder``, or a
    positional's metavar), or None: no text option means nothing when empty (a path, a name, a
    list), and a command testing its truth would take it as not given."""
    import argparse
    for action in parser._actions:
        if action.type is not None or not isinstance(action, (argparse._StoreAction, argparse._AppendAction)):
            continue
        value = getattr(args, action.dest, None)
        values = value if isinstance(value, list) else [value]
        if any(isinstance(v, str) and v == "" for v in values):
            return action.option_strings[-1] if action.option_strings else action.metavar or action.dest
    return None


def _repeated_option(parser, argv: list[str]) -> str | None:
    """The first option of ``parser`` that takes one value and appears twice in ``argv`` (its
    spellings as typed, e.g. ``--out``, or an abbreviation argparse takes for it, ``--ou``), or
    None; repeatable options (``append``) and switches may repeat."""
    import argparse

    from .commands.common import option_typed
    single = {option: action.dest for action in parser._actions if type(action) is argparse._StoreAction
              for option in action.option_strings}
    seen: dict[str, str] = {}
    for token in argv:
        if token == "--":
            break
        name = token.split("=", 1)[0]
        dest = single.get(option_typed(parser, token))   # (--conf for --config: argparse takes the prefix)
        if dest is None:
            continue
        if dest in seen:
            return seen[dest] if seen[dest] == name else f"{seen[dest]} / {name}"
        seen[dest] = name
    return None


def _python_code(filename) -> bool:
    """Whether ``filename`` is a module of Python or of an installed library (a late import that
    failed, out of file handles): naming it would point the user at a file that is not theirs."""
    import sysconfig
    try:
        path = os.path.realpath(os.fsdecode(filename))
    except (TypeError, ValueError):
        return False
    roots = {sys.prefix, sys.base_prefix, *(sysconfig.get_paths().get(k, "") for k in ("stdlib", "purelib",
                                                                                       "platlib"))}
    return path.endswith((".py", ".pyc", ".so")) and any(
        root and path.startswith(os.path.realpath(root) + os.sep) for root in roots)


def _run(args, prepare=lambda: None, ended=lambda code: None) -> tuple[int, bool]:
    """Run a sub-command after ``prepare``; return (exit code, whether it ended normally). ``ended``
    runs once the command has returned (the caller's signal handlers back: a stop after it ends
    the process as the system does, never with a traceback from outside this function)."""
    from tespike.golden.atomic import finished_outputs, raise_lost_stop, watching_inputs
    prefix = f"tespike {args.command}"
    start = len(finished_outputs())
    try:
        prepare()
        with watching_inputs():           # (an input written over while read: its outputs are not written)
            code = int(args.run(args) or 0)
        sys.stdout.flush()                # (a full disk under "> log" is the command's fault, said below)
        raise_lost_stop()                 # (a stop Python dropped in a finalizer: the command did not end well)
        ended(code)
        return code, True
    except TespikeError as exc:
        print(f"{prefix}: error: {one_line(exc, 300)}{_notes(exc)}{_before(start, exc)}", file=sys.stderr)
        return EXIT_BAD_INPUT, False
    except StandardOutputError as exc:
        return _standard_output_failed(prefix, exc, f"{_notes(exc)}{_before(start, exc)}"), False
    except OSError as exc:
        where = f" {exc.filename!r}:" if exc.filename and not _python_code(exc.filename) else ""
        cause = one_line(exc.strerror or exc, 300)
        if "No usable temporary directory" in cause:       # tempfile's words hide the cause
            from tespike.golden.paths import temporary_directory_fault
            cause = temporary_directory_fault() or cause
        from tespike.golden.resources import file_handles_fault, file_size_text
        cause = file_handles_fault(exc) or cause
        if exc.errno == errno.EFBIG:                       # (the system's words name no limit)
            cause += file_size_text()
        print(f"{prefix}: error:{where} {cause}{_notes(exc)}{_before(start, exc)}", file=sys.stderr)
        return EXIT_BAD_INPUT, False
    except MemoryError as exc:        # numpy's says what it could not allocate; library_room's, what is left
        detail = f" ({one_line(exc)})" if str(exc) else ""
        print(f"{prefix}: error: out of memory{address_space_text()}{detail}{_notes(exc)}{_before(start, exc)}",
              file=sys.stderr)
        return 1, False
    except (RuntimeError, ImportError, SystemError) as exc:   # torch's failed allocation; a library that
        if isinstance(exc, RuntimeError) and str(exc) == "can't start new thread":   # cannot be mapped; ...
            print(f"{prefix}: error: cannot start a thread: out of memory or of processes{address_space_text()}"
                  f"{_notes(exc)}{_before(start, exc)}", file=sys.stderr)
            return 1, False
        if isinstance(exc, SystemError):   # ... under ulimit -v, an allocation that failed in C ("returned NULL
            memory = bool(address_space_text())  # without setting an exception": import dask); elsewhere a bug
        else:
            memory = any(words in str(exc) for words in OUT_OF_MEMORY) or \
                bool(address_space_text() and any(words in str(exc) for words in OUT_OF_MEMORY_UNDER_LIMIT))
        if not memory:
            raise
        print(f"{prefix}: error: out of memory{address_space_text()} ({one_line(exc, 160)}){_notes(exc)}"
              f"{_before(start, exc)}",
              file=sys.stderr)
        return 1, False
    except KeyboardInterrupt as exc:
        print(f"{prefix}: interrupted{_after(start, exc)}{_notes(exc)}", file=sys.stderr)
        return 130, False
    except Terminated as exc:
        import signal
        print(f"{prefix}: terminated by {signal.Signals(exc.signum).name}{_after(start, exc)}{_notes(exc)}",
              file=sys.stderr)
        return 128 + exc.signum, False


if __name__ == "__main__":
    sys.exit(main())
