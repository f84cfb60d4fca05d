"""Path checks shared by every reader, writer and command (standard library only).

A command refuses a bad path before it reads or writes anything, in one line
that names the path the user gave (never a hidden temporary):

- :func:`check_input_file`: an input must be an existing, non-empty regular
  file (a FIFO would block for ever, a device or a directory is not data);
- :func:`check_output_file`: an output may be a new or existing regular file
  (through a symlink: the target is written), or an existing character device
  or FIFO (``/dev/null``, a pipe: written through, never replaced); a directory,
  a block device, a socket, a missing or read-only directory is refused;
- :func:`check_distinct`: no output may be the same file as an input (compared
  by resolved path and by inode, so hard links count) or as another output;
- :func:`check_format`: a file an output names is named for what it holds (a stream
  written as ``S.png`` would be shown as a picture by a file browser and ``view``);
- :func:`check_outputs`: all of the above for one command, before any work.
"""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path
from typing import Mapping

from .errors import InputError

#: Kinds of file, for messages.
_KINDS = ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO"), (stat.S_ISCHR, "a character device"),
          (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))


def kind(mode: int) -> str:
    """'a directory', 'a FIFO', ... or 'a regular file' for an ``st_mode``."""
    for test, name in _KINDS:
        if test(mode):
            return name
    return "a regular file"


def _reason(exc: OSError) -> str:
    return exc.strerror or str(exc) or type(exc).__name__


def path_text(path, what: str = "path") -> str:
    """``path`` as text where it is a str or an os.PathLike of one, refused in one line naming
    ``what`` otherwise (a number had been os.fspath's TypeError naming no argument)."""
    if isinstance(path, (str, os.PathLike)):
        text = os.fspath(path)
        if isinstance(text, str):
            if "\x00" in text:                          # (the system's "embedded null byte" ValueError)
                raise InputError(f"{what}: the path {text!r} holds a NUL character, which no file name can")
            return text
    raise InputError(f"{what}: a path must be a str or an os.PathLike, not {type(path).__name__}")


def check_input_file(path: str | os.PathLike, what: str = "input") -> Path:
    """Refuse an input that is missing, unreadable, empty or not a regular file; return it.

    ``what`` names the input in the message (``"stimulus"``, ``"--config"``...).
    A FIFO is refused rather than opened: opening one with no writer blocks.
    """
    text = path_text(path, what)
    if not text:
        raise InputError(f"{what}: empty path")
    try:
        info = os.stat(text)
    except FileNotFoundError:
        raise InputError(f"{what} file {text!r} does not exist") from None
    except OSError as exc:
        raise InputError(f"{what} file {text!r}: {_reason(exc)}") from None
    if not stat.S_ISREG(info.st_mode):
        raise InputError(f"{what} file {text!r} is {kind(info.st_mode)}, not a regular file")
    if info.st_size == 0:
        raise InputError(f"{what} file {text!r} " + ("is empty (0 bytes)" if _holds_nothing(text) else
                         "is a pseudo-file its file system calls 0 bytes long (as /proc's are), "
                         "not a file of data"))
    if not os.access(text, os.R_OK):
        raise InputError(f"{what} file {text!r}: permission denied")
    return Path(text)


def _holds_nothing(text: str) -> bool:
    """Whether a file ``stat`` calls 0 bytes long reads as nothing (a kernel pseudo-file, /proc's
    or /sys's, is 0 bytes to ``stat`` and holds text)."""
    try:
        with open(text, "rb") as handle:
            return not handle.read(1)
    except OSError:
        return True


def resolve_output(path: str | os.PathLike) -> Path:
    """The file an output path names: symlinks (also dangling ones) followed to their target."""
    return Path(os.path.realpath(os.fspath(path)))


def check_output_file(path: str | os.PathLike, what: str | None = None) -> Path:
    """Refuse an output path that cannot be written safely; return the resolved target.

    Accepted: a new file in an existing writable directory, an existing writable
    regular file (replaced atomically), an existing character device or FIFO
    (written through by :func:`tespike.golden.io.atomic_output`, never replaced).
    """
    text = path_text(path, what or "output")
    label = f"{what} {text!r}" if what else repr(text)
    if not text:
        raise InputError(f"{what or 'output'}: empty path")
    _refuse_control_characters(text, label)
    if text.endswith(os.sep) and not os.path.isdir(text):     # (a directory's name, not a file's)
        raise InputError(f"cannot write {label}: a path ending in {os.sep!r} names a directory "
                         "(name a file)")
    target = resolve_output(text)
    if written_through(text):           # a device or FIFO, links followed as the kernel follows them
        if not os.access(text, os.W_OK):
            raise InputError(f"cannot write {label}: permission denied")
        return target if os.path.exists(target) else Path(text)   # (a pipe behind /dev/stdout: realpath
    try:                                                            # names no file, the kernel opens it)
        info = os.stat(target)
    except FileNotFoundError:
        info = None
    except OSError as exc:
        raise InputError(f"cannot write {label}: {_reason(exc)}") from None
    if info is not None:
        if not stat.S_ISREG(info.st_mode):
            raise InputError(f"cannot write {label}: it is {kind(info.st_mode)}"
                             + (" (name a file inside it)" if stat.S_ISDIR(info.st_mode) else ""))
        if not os.access(target, os.W_OK) or not info.st_mode & 0o222:   # (root may write any file:
            raise InputError(f"cannot write {label}: the file is read-only")  # its mode says no to all)
    directory = target.parent
    if not directory.is_dir():
        shown = os.path.dirname(text) or "."
        raise InputError(f"cannot write {label}: directory {shown!r} does not exist")
    if not writable_directory(directory):
        shown = os.path.dirname(text) or "."
        raise InputError(f"cannot write {label}: directory {shown!r} is not writable")
    return target


def writable_directory(path: str | os.PathLike) -> bool:
    """Whether a command may write in directory ``path``: the process may (``os.access``) and its mode
    lets someone (root may write anywhere, but a folder whose mode says no to all is read-only)."""
    try:
        return os.access(path, os.W_OK | os.X_OK) and bool(os.stat(path).st_mode & 0o222)
    except OSError:
        return False


def lies_inside(path: str | os.PathLike, folder: str | os.PathLike) -> bool:
    """Whether ``path`` is ``folder`` or lies anywhere below it, links followed (``realpath``: a link
    loop does not raise): an input a run that replaces the folder would lose, or an output a
    reader of the folder would take for one of its own."""
    root = os.path.realpath(folder)
    return os.path.commonpath([root, os.path.realpath(path)]) == root


def same_file(a: str | os.PathLike, b: str | os.PathLike) -> bool:
    """True if two paths name one file: equal once resolved, or one inode (hard links)."""
    ra, rb = resolve_output(a), resolve_output(b)
    if ra == rb:
        return True
    try:
        return os.path.samefile(ra, rb)
    except OSError:
        return False


def check_distinct(inputs, outputs: Mapping[str, str | os.PathLike | None]) -> None:
    """Refuse an output that is an input file or another output, naming both.

    Keys are the flags (``"--stimulus"``), values the paths (``None`` skipped); ``inputs`` may
    also be (flag, path) pairs, for the many files of one flag (the frames of a folder).
    An input that is not an existing file (a preset name such as ``--config te``)
    cannot be overwritten and is skipped.
    """
    pairs = inputs.items() if isinstance(inputs, Mapping) else inputs
    outs = [(flag, os.fspath(p)) for flag, p in outputs.items() if p is not None]
    ins = [(flag, os.fspath(p)) for flag, p in pairs
           if p is not None and os.path.lexists(os.fspath(p))]
    for i, (oflag, out) in enumerate(outs):
        for iflag, inp in ins:
            if same_file(out, inp):
                raise InputError(f"{oflag} {out!r} is the same file as {iflag} {inp!r}: "
                                 "refusing to overwrite an input")
        for oflag2, out2 in outs[:i]:
            if same_file(out, out2):
                raise InputError(f"{oflag} {out!r} is the same file as {oflag2} {out2!r}: "
                                 "two outputs cannot share a file")


#: Characters that reorder or break the line they are printed in: the bidirectional controls (a
#: right-to-left override makes ``S.npz`` read as another name) and the line and paragraph separators.
_LINE_BREAKERS = frozenset("\u061c\u200e\u200f\u2028\u2029\u202a\u202b\u202c\u202d\u202e"
                           "\u2066\u2067\u2068\u2069")


def _refuse_control_characters(text: str, label: str) -> None:
    """Refuse an output path holding a control character: the command's success line names its
    outputs, and a newline there would split it, a right-to-left override reverse it (the refusal
    quotes it with repr, on one line)."""
    control = next((c for c in text if ord(c) < 32 or 127 <= ord(c) < 160 or c in _LINE_BREAKERS), None)
    if control is not None:
        raise InputError(f"cannot write {label}: the path holds the control character {control!r} "
                         "(name one without)")


def written_through(path: str | os.PathLike) -> bool:
    """Whether ``path`` is (or links to) a character device or a FIFO: an output written through
    (``/dev/null``, a pipe), never replaced, and no file of its own."""
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return False
    return passes_through(mode)


def passes_through(mode: int) -> bool:
    """:func:`written_through` from an ``st_mode`` already read."""
    return stat.S_ISCHR(mode) or stat.S_ISFIFO(mode)


def check_format(flag: str, path: str | os.PathLike, suffixes: tuple[str, ...]) -> None:
    """Refuse an output file named with a suffix other than ``suffixes`` (the first is the
    format's own, e.g. ``.npz``; any case): the file would hold one format under another's
    name. A FIFO or character device (``/dev/null``, a pipe) takes any name."""
    text = os.fspath(path)
    if written_through(text):
        return
    if Path(text).suffix.lower() not in suffixes:
        names = " or ".join(suffixes)
        stemless = Path(text).name.lower() in suffixes          # ".npz": a hidden file without a suffix
        raise InputError(f"{flag} {text!r}: the file is written in the {suffixes[0]} format; "
                         + (f"give it a name before {names} (the name is all suffix)" if stemless
                            else f"give a name ending in {names}"))


def check_outputs(outputs: Mapping[str, str | os.PathLike | None], inputs=None,
                  formats: Mapping[str, tuple[str, ...]] | None = None) -> None:
    """Every output path of a command checked (:func:`check_output_file`; its suffix
    against ``formats[flag]``, :func:`check_format`) and kept apart from the inputs
    (:func:`check_distinct`: a mapping, or (flag, path) pairs), before any output is written."""
    for flag, path in outputs.items():
        if path is not None:
            check_output_file(path, flag)
    check_distinct(inputs or {}, outputs)
    for flag, suffixes in (formats or {}).items():      # (after: an input named as an output is the worse fault)
        if outputs.get(flag) is not None:
            check_format(flag, outputs[flag], suffixes)


def check_folder_path(text: str, what: str = "--out") -> None:
    """Refuse an output folder's path that names no folder of its own: ``''`` (the current folder),
    or one that reaches an existing folder through a missing one (``nosuch/..``, ``file/..``: absent
    as written, the current folder once resolved). A run replaces its output folder whole: either
    would have replaced the folder holding its inputs."""
    if not text:
        raise InputError(f"cannot write {what} '': an empty path (name the output folder)")
    if not os.path.lexists(text) and os.path.lexists(os.path.realpath(text)):
        raise InputError(f"cannot write {what} {text!r}: it reaches the existing folder "
                         f"{os.path.realpath(text)!r} through a folder that does not exist: name that folder "
                         "itself (a run replaces its output folder whole)")


def check_output_dir(path: str | os.PathLike, what: str = "--out",
                     files: tuple[str, ...] = ()) -> Path:
    """An output folder: existing directory or creatable (parent exists); ``files``
    (relative names written inside it) are checked like single outputs, and a
    name ending in ``/`` must be a directory or absent."""
    text = path_text(path, what)
    _refuse_control_characters(text, f"{what} {text!r}")
    check_folder_path(text, what)
    folder = Path(text)
    if os.path.islink(text) and not os.path.exists(text):
        try:
            os.stat(text)
        except OSError as exc:
            if exc.errno == errno.ELOOP:             # (its target exists: a loop of links, not a missing folder)
                raise InputError(f"cannot write {what} {text!r}: it is a loop of symbolic links "
                                 f"({exc.strerror})") from None
        raise InputError(f"cannot write {what} {text!r}: it is a symbolic link to {os.readlink(text)!r}, "
                         "which does not exist (make that folder, or name another)")
    if os.path.lexists(text) and not folder.is_dir():
        raise InputError(f"cannot write {what} {text!r}: it exists and is not a directory")
    if not folder.is_dir():
        parent = folder.resolve().parent
        if not parent.is_dir():
            raise InputError(f"cannot write {what} {text!r}: directory "
                             f"{os.path.dirname(text.rstrip('/')) or '.'!r} does not exist")
        if not writable_directory(parent):
            raise InputError(f"cannot create {what} {text!r}: its parent directory is not writable")
        return folder
    if not writable_directory(folder):
        raise InputError(f"cannot write {what} {text!r}: directory is not writable")
    for name in files:
        inside = folder / name
        if name.endswith("/"):
            if os.path.lexists(inside) and not inside.is_dir():
                raise InputError(f"cannot write {what} {text!r}: {str(inside)!r} exists and is "
                                 "not a directory")
            continue
        if os.path.lexists(inside) or inside.parent.is_dir():
            check_output_file(inside, what)
        elif os.path.lexists(inside.parent):
            raise InputError(f"cannot write {what} {str(inside)!r}: "
                             f"{str(inside.parent)!r} is not a directory")
    return folder


def foreign_names(path: str | os.PathLike, patterns) -> list[str]:
    """The names in folder ``path`` that match none of ``patterns`` (``fnmatch``, a trailing ``/``
    ignored), sorted; none where the folder is absent or empty. What a command that replaces its
    folder whole would delete besides an earlier run's files (the demo, ``cocotb --work-dir``)."""
    import fnmatch
    try:
        present = sorted(os.listdir(path))
    except (FileNotFoundError, NotADirectoryError):
        return []
    return [name for name in present
            if not any(fnmatch.fnmatchcase(name, pattern.rstrip("/")) for pattern in patterns)]


def check_results_dir(path: str | os.PathLike, names: tuple[str, ...], force: bool,
                      what: str = "--out") -> Path:
    """A folder a command fills whole (:func:`tespike.golden.atomic.atomic_folder`): new or empty;
    holding a previous run's results only with ``force``; never a folder holding anything else,
    which replacing it would delete. ``names``: the results' files; ``dir/`` a folder of them,
    whose files must each match a ``dir/PATTERN`` of ``names`` (no pattern: the folder is empty)."""
    import fnmatch
    folder = check_output_dir(path, what)
    text = os.fspath(path)
    if not folder.is_dir():
        return folder
    try:
        present = sorted(os.listdir(folder))
    except OSError as exc:
        raise InputError(f"cannot read {what} {text!r}: {_reason(exc)}") from None
    if not present:
        return folder
    allowed = {name.rstrip("/") for name in names if "/" not in name.rstrip("/")}
    patterns: dict[str, list[str]] = {}
    for name in names:
        head, _, pattern = name.partition("/")
        if pattern:
            patterns.setdefault(head, []).append(pattern)
    foreign = [name for name in present if name not in allowed]
    for name in present:
        inner = folder / name
        if name in allowed and inner.is_dir() and not inner.is_symlink():
            try:
                entries = sorted(os.listdir(inner))
            except OSError as exc:
                raise InputError(f"cannot read {what} {text!r}'s folder {name!r}: {_reason(exc)}") from None
            foreign += [f"{name}/{entry}" for entry in entries
                        if not ((inner / entry).is_file() and not (inner / entry).is_symlink()
                                and any(fnmatch.fnmatchcase(entry, p) for p in patterns.get(name, ())))]
    if foreign:
        shown = ", ".join(n for n in names if "/" not in n.rstrip("/") or n.endswith("/"))
        raise InputError(f"{what} {text!r} holds {foreign[0]!r}, which is not one of a results folder's "
                         f"files ({shown}): choose a new or empty folder")
    if not force:
        raise InputError(f"{what} {text!r} holds a previous run's results: give --force to replace them "
                         "(the new run replaces the folder whole when it is done), or another folder")
    return folder


def temporary_directory_fault() -> str | None:
    """Why the temporary directory (``$TMPDIR``, else ``/tmp``) cannot take a file, or None.

    Python's ``tempfile`` says only "No usable temporary directory found in [...]" (an
    ENOENT) when every candidate fails its trial write, whatever the cause: a full disk
    (ENOSPC), a file-size limit (EFBIG), a read-only one. This names the folder and the cause.
    """
    import tempfile
    folder = os.environ.get("TMPDIR") or "/tmp"
    try:
        with tempfile.TemporaryFile(dir=folder) as probe:
            probe.write(b"\0" * 4096)
            probe.flush()
    except OSError as exc:
        return f"cannot write a temporary file in {folder!r}: {exc.strerror or exc}"
    return None
