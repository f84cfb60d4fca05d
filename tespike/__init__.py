"""tespike: the time-encoding spike camera from circuit to image.

The four rooms are sub-packages: :mod:`tespike.golden` (numpy golden model and
simulators), :mod:`tespike.rtl` (Amaranth RTL and Verilog), :mod:`tespike.recon`
(torch reconstruction) and :mod:`tespike.cosim` (co-simulation and the
``tespike`` command). In the repository they sit beside this folder
(``golden/``, ``rtl/``, ...); an installed copy holds them inside it.
"""

from pathlib import Path as _Path

_CHECKOUT = _Path(__file__).resolve().parent.parent
if not (_Path(__file__).parent / "golden").is_dir() and (_CHECKOUT / "pyproject.toml").is_file() \
        and (_CHECKOUT / "golden" / "__init__.py").is_file():
    # A source checkout (run from it, or installed editable): its rooms are this
    # checkout's folders, never another copy's.
    __path__.append(str(_CHECKOUT))

__version__ = "0.1.0"
