"""The training-free reconstruction's settings and the rules every method shares.

Its sizes and switches in one dataclass (:class:`ReconSettings`); the window rule
(:data:`DEFAULT_WINDOW`, :func:`check_window`, :func:`check_window_reach`, :func:`uses_window`),
the device check, and the training-free methods' registry (:data:`TRAINING_FREE`,
:func:`check_known`, :data:`TFI_SEARCH`). Nothing in :mod:`recon` keeps global state:
every function takes its device and its sizes explicitly, and :class:`ReconSettings`
gathers them for callers that want one object to pass around (the CLI, the benchmarks,
the evaluation).
"""

from __future__ import annotations

import dataclasses
import numbers

import numpy as np

from tespike.golden.decode import ESTIMATORS
from tespike.golden.errors import InputError, one_line

#: Readouts per window of the training-free methods (paper section 6.4).
DEFAULT_WINDOW = 9


def check_window(window, what: str = "window") -> None:
    """The one window rule: an odd integer >= 1 (readouts centred on the key moment)."""
    if type(window) is not int or window < 1 or window % 2 == 0:
        raise InputError(f"{what} {window!r}: must be an odd integer >= 1 (readouts centred on the key moment)")


def check_window_reach(window: int, readouts: int, what: str) -> None:
    """Refuse a window given wider than ``2 K - 1`` for ``what`` of K ``readouts`` ("this 9-readout
    stream", "the 9-readout sequence 'a'"): every window is cut to the ends, so no frame's can be
    that wide (the default window is not checked: a short sequence takes what it has)."""
    if window > 2 * readouts - 1:
        raise InputError(f"--window {window}: wider than any window of {what} "
                         f"({2 * readouts - 1} readouts at most; a wider one changes nothing)")


def check_device(device) -> None:
    """Refuse, in one line, a torch device that cannot hold a tensor on this machine (a misspelt
    name, cuda without a GPU, the data-less meta device, a CPU index other than 0, which torch
    accepts and ignores), before any work is done on it."""
    import torch
    if isinstance(device, bool) or not isinstance(device, (str, int, torch.device)):
        raise InputError(f"device = {device!r}: must be a torch device name such as 'cpu' or 'cuda:0' "
                         f"(or a torch.device)")
    if str(device).startswith("meta"):
        raise InputError(f"device = {device!r}: the meta device holds no data")
    try:
        named = torch.device(device)
        torch.empty(0, device=named)
    except (RuntimeError, TypeError, AssertionError) as exc:
        raise InputError(f"device = {device!r}: not a usable torch device ({one_line(exc)})") from None
    if named.type == "cpu" and named.index not in (None, 0):
        raise InputError(f"device = {device!r}: there is one CPU device ('cpu' or 'cpu:0'); torch would "
                         f"ignore the index")


#: The training-free methods: name -> what it computes (their code: :data:`tespike.recon.methods.RECON_METHODS`;
#: named here, without torch, so that the command line lists and checks them quickly).
TRAINING_FREE = {"tfp": "mean decoded light over the window (spike-firing rate)",
                 "tfi": "decoded spikes over the spike interval around each readout"}

def check_known(method: str, known, what: str = "reconstruction method") -> None:
    """Refuse a method name not among ``known`` in one line (every place that takes a method's name:
    the registry, the learned methods' loader, the evaluations, the command line)."""
    if not isinstance(method, str) or method not in known:       # (a list: "unhashable type")
        raise InputError(f"unknown {what} {method!r} (known: {', '.join(known)})")


def names(value, what: str = "names") -> tuple:
    """A sequence of names (methods, sensors, metrics) as a tuple; one name given as a string is
    that name (its letters had been taken as names: methods='tfp' was 'unknown reconstruction
    method 't''). Anything else (a number, a name that is no string) is refused in one line naming
    ``what`` (``metrics=3`` had been Python's "not iterable")."""
    if isinstance(value, str):
        return (value,)
    try:
        out = tuple(value)
    except TypeError:
        out = None
    if out is None or not all(isinstance(name, str) for name in out):
        raise InputError(f"{what} {value!r}: must be a name or a sequence of names (strings)")
    return out


#: TFI search modes: the whole stream (default) or the window around the key moment.
TFI_SEARCH = ("stream", "window")


@dataclasses.dataclass(frozen=True)
class ReconSettings:
    """Everything the training-free methods need besides the stream itself.

    ``window``: readouts per window, odd, centred on the key moment (paper
    section 6.4 uses 9). ``chunk_elements``: readouts x pixels processed at
    once (bounds memory; results do not depend on it); ``None`` picks
    :meth:`block_elements`. ``estimator``: the
    :data:`tespike.golden.decode.ESTIMATORS` rule. ``search``: where TFI looks for the
    non-zero codes that bound a spike interval (see :mod:`tespike.recon.tfi`).
    ``device``: any torch device string. ``dtype``: the float type of the
    arithmetic, "float32" (default: the output is float32, windows are short
    sums, so it costs < 1e-6 relative) or "float64".
    """

    window: int = DEFAULT_WINDOW
    chunk_elements: int | None = None
    estimator: str = "ratio"
    search: str = "stream"
    device: str = "cpu"
    dtype: str = "float32"

    def __post_init__(self) -> None:
        for key in ("window", "chunk_elements"):     # numpy integers welcome, bool and float not
            value = getattr(self, key)
            if isinstance(value, numbers.Integral) and not isinstance(value, (bool, np.bool_)):
                object.__setattr__(self, key, int(value))
        check_window(self.window, "window =")
        if self.chunk_elements is not None and (type(self.chunk_elements) is not int
                                                or self.chunk_elements < 1):
            raise InputError(f"chunk_elements = {self.chunk_elements!r}: must be an integer >= 1")
        if not isinstance(self.estimator, str) or self.estimator not in ESTIMATORS:   # (a list: unhashable)
            raise InputError(f"estimator = {self.estimator!r}: must be one of {', '.join(ESTIMATORS)}")
        if self.search not in TFI_SEARCH:
            raise InputError(f"search = {self.search!r}: must be one of {', '.join(TFI_SEARCH)}")
        if self.dtype not in ("float32", "float64"):
            raise InputError(f"dtype = {self.dtype!r}: must be 'float32' or 'float64'")
        check_device(self.device)

    def block_elements(self) -> int:
        """Readouts x pixels per block: ``chunk_elements``, or by default 2^19 on one
        torch thread (fits the caches) and 2^22 on more (fewer parallel regions,
        each of which ends in a barrier across the threads)."""
        if self.chunk_elements is not None:
            return self.chunk_elements
        import torch
        return 1 << 19 if torch.get_num_threads() == 1 else 1 << 22

    @property
    def torch_dtype(self):
        import torch
        return getattr(torch, self.dtype)

    @property
    def radius(self) -> int:
        """Window radius omega_h of the paper's eq. 4: window = 2 * radius + 1."""
        return self.window // 2


def uses_window(method: str, search: str = "stream") -> bool:
    """Whether ``method`` reads the ``window`` setting: TFP always, TFI only when it searches the
    window (``search="window"``; the whole stream otherwise), the learned methods never."""
    return method == "tfp" or (method == "tfi" and search == "window")
