"""Processes as /proc shows them (a process's children and descendants, whether one still runs), and
how a child gets Ctrl-C as a terminal gives it."""

import os
import signal


def children(pid: int) -> list[int]:
    """The child processes of ``pid``, zombies included."""
    found = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as handle:
                    fields = handle.read().rsplit(")", 1)[1].split()
            except (OSError, IndexError):
                continue
            if int(fields[1]) == pid:
                found.append(int(entry))
    return found


def descendants(pid: int) -> set[int]:
    """Every process below ``pid`` (children, their children, ...)."""
    found, todo = set(), [pid]
    while todo:
        for child in children(todo.pop()):
            if child not in found:
                found.add(child)
                todo.append(child)
    return found


def interruptible() -> None:
    """In a child (``preexec_fn``): Ctrl-C, SIGTERM and a hang-up as a shell gives them. A test run from
    a shell's background job (``nohup pytest &``) inherits SIGINT and SIGHUP ignored, and tespike rightly
    leaves an ignored signal ignored, so a test that sends one starts it with the default disposition
    (the SIGHUP test of training ran on for its 10 minutes under CI's nohup)."""
    for number in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(number, signal.SIG_DFL)


def alive(pid: int) -> bool:
    """Whether ``pid`` is a live process (a zombie waiting to be reaped has ended)."""
    try:
        with open(f"/proc/{pid}/stat") as handle:
            return handle.read().rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return False
