"""Room and quiet for a library whose start cannot be stopped or refused from Python.

Two faults of torch's import kill the process from C++, past any handling in Python:

- Under an address-space limit (``ulimit -v``, RLIMIT_AS) its static initialisers throw
  ``std::bad_alloc`` when its libraries do not fit (SIGABRT). So, under such a limit only,
  the import is tried in a child process first (which inherits the limit) and what it maps is
  measured; when it cannot fit in what is left here, the import raises :class:`MemoryError`
  with the sizes, which the command line prints as one line.
- Ctrl-C or SIGTERM while it loads raise in Python code that its C++ start called (pybind11),
  which ends in ``std::terminate`` and 77 lines of a C++ trace (SIGABRT; seen in the fault
  sweep with SIGTERM 0.9 s into ``evaluate --store``). So the load runs with the stops held
  (:func:`tespike.golden.atomic.stops_held`): a stop meanwhile ends the command, with its one
  line, once the library has loaded (about 2 s on an idle machine).

:func:`guard_imports` installs one finder of ``sys.meta_path`` that does both.
"""

from __future__ import annotations

import os
import sys

from tespike.golden.atomic import stops_held
from tespike.entry import short_of_room
from tespike.golden import resources   # (its functions looked up at each call: a test that patches one
                                       # while this module is first imported must not leave it bound here)

#: Libraries whose room is checked (under a limit) and whose load runs with the stops held.
GUARDED = ("torch",)
#: Libraries whose load only runs with the stops held: a Ctrl-C or SIGTERM in the middle of one
#: (0.3 s into ``dataset --workers 2``, as Dask loads) left a half-initialised module, and the next
#: import of it, on the way out, raised ``AttributeError: partially initialized module 'yaml'``,
#: a 100-line traceback in place of the command's line.
HELD = ("dask", "distributed", "zarr", "yaml")
#: Seconds the trial import may take (torch: about 2 on an idle machine).
PROBE_SECONDS = 120
#: Address space kept free beyond the library's own mappings (its first tensors, threads).
MARGIN = 64 << 20


_PROBE = """
import sys
def vm():
    for line in open('/proc/self/status'):
        if line.startswith('VmSize:'):
            return int(line.split()[1]) * 1024
import numpy
before = vm()
import {name}
print(vm() - before)
"""


def _refusal(name: str, limit: int) -> str | None:
    """Why ``name`` cannot be imported within ``limit`` bytes of address space, or None."""
    import subprocess
    try:
        done = subprocess.run([sys.executable, "-c", _PROBE.format(name=name)], capture_output=True, text=True,
                              stdin=subprocess.DEVNULL, env=dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path)),
                              timeout=PROBE_SECONDS)
    except OSError:
        return None                       # no process to try it in: the import itself will tell
    except subprocess.TimeoutExpired:     # a start short of room can hang (OpenBLAS's threads)
        return f"{name} did not load within {PROBE_SECONDS} s under the address-space limit"
    left = max(0, limit - resources.mapped_bytes())
    if short_of_room(done):               # (torch's import under ulimit -v 617 MB printed CPython's SystemError)
        return f"{name} cannot be loaded: it does not fit in {left >> 20} MB of address space"
    if done.returncode != 0:
        return None                       # another failure: the import itself will tell
    try:
        needed = int(done.stdout.split()[-1]) + MARGIN
    except (ValueError, IndexError):
        return None
    if needed > left:
        return f"loading {name} needs about {needed >> 20} MB of address space, {left >> 20} MB is left"
    return None


class _HeldLoader:
    """A library's own loader, whose ``exec_module`` runs with the stops held; everything else
    (``get_resource_reader``, ``is_package`` ...) is the library's loader's."""

    def __init__(self, loader):
        self.loader = loader

    def __getattr__(self, name):
        return getattr(self.loader, name)

    def create_module(self, spec):
        return self.loader.create_module(spec)

    def exec_module(self, module):
        try:
            with stops_held():
                self.loader.exec_module(module)
        finally:               # the module keeps its own loader, as if this one had never been
            module.__loader__ = self.loader
            if getattr(module, "__spec__", None) is not None:
                module.__spec__.loader = self.loader


class _Guard:
    """A finder of ``sys.meta_path``: on a guarded library's first import, checks its room
    (under an address-space limit) and hands back the usual finders' spec with its load held."""

    def __init__(self):
        self.checked: set[str] = set()

    def find_spec(self, fullname, path, target=None):
        if fullname not in (*GUARDED, *HELD) or fullname in self.checked:
            return None
        self.checked.add(fullname)       # (removing itself here would skip the next finder of the loop)
        limit = resources.address_space_limit() if fullname in GUARDED else None
        refusal = None if limit is None else _refusal(fullname, limit)
        if refusal:
            raise MemoryError(refusal)
        for finder in sys.meta_path:     # the finders that would have found it, this one aside
            if finder is self or not hasattr(finder, "find_spec"):
                continue
            spec = finder.find_spec(fullname, path, target)
            if spec is not None:
                if spec.loader is not None and hasattr(spec.loader, "exec_module"):
                    spec.loader = _HeldLoader(spec.loader)
                return spec
        return None


def guard_imports() -> None:
    """Check :data:`GUARDED` libraries' room before they load (under an address-space limit) and
    load them and :data:`HELD`'s with the stops held; once per process, and not for a library
    already loaded."""
    if all(name in sys.modules for name in (*GUARDED, *HELD)) \
            or any(isinstance(finder, _Guard) for finder in sys.meta_path):
        return
    sys.meta_path.insert(0, _Guard())
