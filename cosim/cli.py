"""The ``tespike`` command (SPEC section 6).

Each sub-command lives in its own module under :mod:`cosim.commands` with
``HELP``, ``add_arguments(parser)`` and ``run(args) -> int``. Modules import
their heavy dependencies (amaranth, torch) inside ``run`` so that ``tespike
golden`` and ``tespike simulate`` start in numpy time. Every refusal of bad
input is one line on stderr and a non-zero exit, never a traceback.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from golden.errors import TespikeError

#: sub-command -> module under cosim.commands
COMMANDS = {
    "golden": "golden_cmd",
    "simulate": "simulate_cmd",
    "rtl-sim": "rtl_sim_cmd",
    "verilog": "verilog_cmd",
    "cocotb": "cocotb_cmd",
    "reconstruct": "reconstruct_cmd",
    "evaluate": "evaluate_cmd",
    "demo": "demo_cmd",
    "scene": "scene_cmd",
}

EXIT_BAD_INPUT = 2


def _available_commands() -> dict[str, object]:
    modules = {}
    for name, module in COMMANDS.items():
        try:
            modules[name] = importlib.import_module(f"cosim.commands.{module}")
        except ModuleNotFoundError as exc:
            if exc.name != f"cosim.commands.{module}":
                raise
    return modules


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="tespike",
        description="Time-encoding spike camera: golden model, RTL, co-simulation and reconstruction.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, module in _available_commands().items():
        command = sub.add_parser(name, help=module.HELP, description=module.HELP)
        module.add_arguments(command)
        command.set_defaults(run=module.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.run(args) or 0)
    except TespikeError as exc:
        print(f"tespike {args.command}: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except OSError as exc:
        where = f" {exc.filename!r}" if exc.filename else ""
        print(f"tespike {args.command}: error:{where} {exc.strerror or exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except MemoryError:
        print(f"tespike {args.command}: error: out of memory", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"tespike {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
