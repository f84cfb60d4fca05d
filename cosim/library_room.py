"""Room in the address space for a library that aborts from C when it runs out of it.

Under an address-space limit (``ulimit -v``, RLIMIT_AS) torch's import throws
``std::bad_alloc`` from a static initialiser when its libraries do not fit: the
process dies of SIGABRT, past any handling in Python. So, under such a limit only,
:func:`guard_imports` tries the import in a child process first (which inherits the
limit) and measures what it maps; when it cannot fit in what is left here, the
import raises :class:`MemoryError` with the sizes, which the command line prints
as one line. Without a limit nothing is installed and imports cost nothing more.
"""

from __future__ import annotations

import os
import sys

from tespike.golden.resources import address_space_limit, mapped_bytes

#: Libraries tried in a child first.
GUARDED = ("torch",)
#: What a child's failed import prints when the address space, not the library, was at fault.
_NO_ROOM_WORDS = ("alloc", "memory", "Memory", "map segment", "pthread_create", "can't start new thread")
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
    left = max(0, limit - mapped_bytes())
    if done.returncode != 0:
        if done.returncode < 0 or any(word in done.stderr for word in _NO_ROOM_WORDS):
            return f"{name} cannot be loaded: it does not fit in {left >> 20} MB of address space"
        return None                       # another failure: the import itself will tell
    try:
        needed = int(done.stdout.split()[-1]) + MARGIN
    except (ValueError, IndexError):
        return None
    if needed > left:
        return f"loading {name} needs about {needed >> 20} MB of address space, {left >> 20} MB is left"
    return None


class _Guard:
    """A finder of ``sys.meta_path`` (``find_spec`` is all one needs): checks the room for each
    guarded library on its first import, then lets the usual finders load it."""

    def __init__(self):
        self.checked: set[str] = set()

    def find_spec(self, fullname, path, target=None):
        if fullname not in GUARDED or fullname in self.checked:
            return None
        self.checked.add(fullname)       # (removing itself here would skip the next finder of the loop)
        limit = address_space_limit()
        refusal = None if limit is None else _refusal(fullname, limit)
        if refusal:
            raise MemoryError(refusal)
        return None                       # the usual finders load it


def guard_imports() -> None:
    """Under an address-space limit, check :data:`GUARDED` libraries' room before they load."""
    if address_space_limit() is None or any(name in sys.modules for name in GUARDED) \
            or any(isinstance(finder, _Guard) for finder in sys.meta_path):
        return
    sys.meta_path.insert(0, _Guard())
