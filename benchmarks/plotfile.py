"""Where a benchmark's plot goes: ``--png`` (default ``out/bench/<name>``, git-ignored) or,
with ``--docs``, the copy the docs show (``docs/figures/<name>``, the one home of the docs'
figures, regenerated on purpose). The figure itself is saved by
:func:`tespike.recon.pictures.save_figure`."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

#: The folder of every figure the docs show (training curves under ``net/``).
DOCS_FIGURES = ROOT / "docs" / "figures"


def add_png_arguments(parser, name: str, flag: str = "--png") -> None:
    """``flag`` (the plot to write) and ``--docs`` (write the docs' copy instead)."""
    parser.add_argument(flag, default=str(ROOT / "out" / "bench" / name),
                        help=f"plot to write (default out/bench/{name}, git-ignored)")
    parser.add_argument("--docs", action="store_true",
                        help=f"write the plot the docs show, docs/figures/{name} (regenerate it on purpose)")


def png_path(args, name: str, flag: str = "--png") -> str:
    """The plot's path for parsed ``args`` (its folder made), stored back on ``args``."""
    attribute = flag.lstrip("-").replace("-", "_")
    path = str(DOCS_FIGURES / name) if args.docs else getattr(args, attribute)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    setattr(args, attribute, path)
    return path


def write_plot(fig, args, name: str, flag: str = "--png") -> str:
    """Save ``fig`` where :func:`png_path` says and say so on stdout -> the path."""
    from tespike.recon.pictures import save_figure
    path = png_path(args, name, flag)
    save_figure(fig, path)
    print(f"wrote {path}")
    return path
