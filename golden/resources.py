"""Memory a run may use, so a command can refuse up front instead of being killed.

:func:`available_memory` is the least of the kernel's ``MemAvailable``, the
cgroup's ``memory.max`` minus its ``memory.current`` and the address-space
limit (``ulimit -v``) minus what the process has mapped; :func:`require_memory`
refuses, naming both sizes, a job whose estimate is larger.
:func:`keep_freed_memory` tunes glibc's allocator for array-heavy loops.
"""

from __future__ import annotations

import ctypes
import errno
import resource
from pathlib import Path

from .errors import InputError, is_count, is_positive_number

#: Most worker processes any command starts (``simulate``, ``prove``, ``dataset`` and ``evaluate
#: --store``'s local cluster, ``train``'s data engine): each costs a Python process, and a typo
#: of a few zeros would otherwise fork until memory is gone.
MAX_WORKERS = 256


def check_workers_argument(workers: int | None) -> None:
    """Refuse a ``--workers`` outside 1..MAX_WORKERS with one line (None: the default); 2.5 and True
    had been taken, '4' was a TypeError."""
    if workers is not None and not (is_count(workers, 1) and workers <= MAX_WORKERS):
        raise InputError(f"--workers {workers!r}: must be in 1..{MAX_WORKERS}")


def _read_int(path: str) -> int | None:
    try:
        text = Path(path).read_text().strip()
    except OSError:
        return None
    return int(text) if text.isdigit() else None


def _meminfo(key: str) -> int | None:
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith(key + ":"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def mapped_bytes() -> int:
    """Bytes of address space this process has mapped (``VmSize``; 0 if unknown)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmSize:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return 0


def available_memory() -> int | None:
    """Bytes this process can still allocate (best estimate), or None if unknown."""
    limits = []
    free = _meminfo("MemAvailable")
    if free is not None:
        limits.append(free)
    high, current = _read_int("/sys/fs/cgroup/memory.max"), _read_int("/sys/fs/cgroup/memory.current")
    if high is not None and current is not None:
        limits.append(max(0, high - current))
    limit = address_space_limit()
    if limit is not None:
        limits.append(max(0, limit - mapped_bytes()))
    return min(limits) if limits else None


def address_space_limit() -> int | None:
    """The soft address-space limit (``ulimit -v``, RLIMIT_AS) in bytes, None when unlimited."""
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    return None if soft == resource.RLIM_INFINITY else soft


def address_space_text() -> str:
    """The address-space limit this process runs under, for an out-of-memory line: ' within the
    address-space limit (ulimit -v) of N MB', or '' where there is none. (``tespike.entry`` says the
    same before numpy may load, in its own words.)"""
    limit = address_space_limit()
    return "" if limit is None else f" within the address-space limit (ulimit -v) of {limit >> 20} MB"


def file_size_text() -> str:
    """The file size limit this process runs under, for the line of a write it stopped (EFBIG, a short
    write, or a tool killed by SIGXFSZ): ' (over this process's file size limit, ulimit -f: N bytes)',
    or '' where there is none."""
    limit = resource.getrlimit(resource.RLIMIT_FSIZE)[0]
    return "" if limit == resource.RLIM_INFINITY else f" (over this process's file size limit, ulimit -f: {limit} bytes)"


def file_handles_fault(exc: OSError) -> str | None:
    """The cause of an OSError that ran out of file handles, with the limit that was reached (the
    system's words, "Too many open files", name neither); None for any other error."""
    if exc.errno == errno.EMFILE:
        soft, _ = resource.getrlimit(resource.RLIMIT_NOFILE)
        shown = "unlimited" if soft == resource.RLIM_INFINITY else str(soft)
        return f"too many open files (this process may hold {shown}: the open-file limit, ulimit -n)"
    if exc.errno == errno.ENFILE:
        return "too many open files in the system (its open-file table is full)"
    return None


def size_text(n: int) -> str:
    """Bytes for people: '512 B', '3.2 kB', '983.0 kB', '1.2 GB' (powers of 1024)."""
    for unit, scale in (("GB", 1 << 30), ("MB", 1 << 20), ("kB", 1 << 10)):
        if n >= scale:
            return f"{n / scale:.1f} {unit}"
    return f"{n} B"


def require_memory(needed: int, what: str) -> None:
    """Refuse ``what`` (e.g. "evaluating sequence 'x' (24 x 4000 x 6000)") if it needs
    more memory than is available, in one line naming both sizes."""
    if not (needed == 0 or is_positive_number(needed)):  # ('5', -5 or NaN had been a TypeError or taken)
        raise InputError(f"require_memory: {needed!r} bytes must be a finite number >= 0")
    free = available_memory()
    if free is not None and needed > free:
        raise InputError(f"{what} needs about {size_text(needed)} of memory, "
                         f"but only {size_text(free)} is available")


#: glibc mallopt parameters (malloc.h) and the values :func:`keep_freed_memory` sets.
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
MMAP_THRESHOLD = 32 << 20          # glibc's largest on 64-bit systems
TRIM_THRESHOLD = 256 << 20
_kept = None


def keep_freed_memory() -> bool:
    """Ask glibc's malloc to serve blocks below MMAP_THRESHOLD from its heap and
    to keep up to TRIM_THRESHOLD bytes of freed heap, for the rest of the process.

    Why: the fast simulator allocates and frees arrays of a frame many times per
    readout; with glibc's defaults each block above 128 KiB-ish is a fresh
    ``mmap`` whose pages fault in again, which measured 20-25 % of
    ``simulate_scene``'s CPU time on a 384 x 512 panorama pan (docs/simulator.md).
    Only speed changes. Idempotent; ``False`` (nothing done) where the C
    library is not glibc."""
    global _kept
    if _kept is None:
        _kept = False
        try:
            libc = ctypes.CDLL(None)
            if hasattr(libc, "gnu_get_libc_version") and hasattr(libc, "mallopt"):
                _kept = bool(libc.mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)
                             and libc.mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD))
        except OSError:
            pass
    return _kept
