"""Headroom a command needs, checked before any work: memory and disk, from an estimate.

A command whose output sizes follow from its arguments (frames x height x width,
the stimulus's shape, ...) calls :func:`require_room` before it prints, creates a
folder or writes a byte, so what cannot fit is one line up front instead of a
failure halfway (or a memory map dying of SIGBUS on a full disk). Estimates are
lower bounds of what the run will take: a refusal is never of a run that fits.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import Mapping

from tespike.golden.errors import InputError
from tespike.golden.paths import written_through
from tespike.golden.resources import require_memory, size_text


def _existing_folder(path: str | os.PathLike) -> Path:
    """The nearest existing folder at or above where ``path`` will be written."""
    folder = Path(os.path.abspath(path)).parent
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    return folder


def free_disk(path: str | os.PathLike) -> tuple[int, int] | None:
    """(device, bytes free to this user) of the file system ``path`` would be written on;
    None where it cannot be told (e.g. a permission error: the write will say so)."""
    folder = _existing_folder(path)
    try:
        usage = shutil.disk_usage(folder)
        device = os.stat(folder).st_dev
    except OSError:
        return None
    if usage.total == 0:            # /proc, /sys: no blocks to count; the write will say what is wrong
        return None
    return device, usage.free


def require_disk(outputs: Mapping[str | os.PathLike, int], what: str) -> None:
    """Refuse ``what`` in one line when the files ``outputs`` (path -> bytes) do not fit on
    their file systems; files on the same file system add up. Devices and FIFOs take none."""
    needs: dict[int, list] = {}
    for path, size in outputs.items():
        if size <= 0 or written_through(path):
            continue
        place = free_disk(path)
        if place is None:
            continue
        device, free = place
        entry = needs.setdefault(device, [0, free, path])
        entry[0] += int(size)
    for needed, free, path in needs.values():
        if needed > free:
            raise InputError(f"cannot write {os.fspath(path)!r}: {what} needs about {size_text(needed)}, "
                             f"but only {size_text(free)} is free on its file system")


def require_room(what: str, *, memory: int = 0, disk: Mapping[str | os.PathLike, int] | None = None) -> None:
    """:func:`tespike.golden.resources.require_memory` and :func:`require_disk` in one call."""
    if memory > 0:
        require_memory(int(memory), what)
    if disk:
        require_disk(disk, what)


def reserved_memmap(path: str | os.PathLike, dtype, shape):
    """A new ``.npy`` at ``path`` opened as a writable memory map, its blocks reserved first
    (``posix_fallocate``): a memory map writing into a sparse file on a full disk dies of
    SIGBUS, leaving its temporary; a reservation fails at once with ENOSPC (an OSError
    naming ``path``, which :func:`tespike.golden.io.atomic_output` reports and cleans up)."""
    import errno

    import numpy as np
    images = np.lib.format.open_memmap(path, mode="w+", dtype=dtype, shape=shape)
    size = os.path.getsize(path)
    fd = os.open(path, os.O_RDWR)
    try:
        os.posix_fallocate(fd, 0, size)
    except OSError as exc:
        if exc.errno not in (errno.EOPNOTSUPP, errno.EINVAL):      # a file system that cannot reserve
            del images
            raise OSError(exc.errno, os.strerror(exc.errno), os.fspath(path)) from None
    finally:
        os.close(fd)
    return images
