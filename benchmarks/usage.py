"""Resource use of the processes a benchmark started (standard library only)."""

import resource


def children_cpu() -> float:
    """User + system CPU seconds of the finished child processes of this process (a
    difference of two calls times what ran in between)."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime
