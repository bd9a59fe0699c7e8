"""Process runtime helpers: usable CPUs, the cyclic garbage collector paused around bulk work, and
pool workers that end with their parent."""

from __future__ import annotations

import gc
import os
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["usable_cpu_count", "cyclic_gc_paused", "exit_with_parent", "PARENT_CHECK_S"]

#: How often a pool worker looks whether its parent is still there, seconds.
PARENT_CHECK_S = 1.0


def usable_cpu_count() -> int:
    """The CPUs this process may use, at least 1 (joblib's count): the fewest of the machine's CPUs,
    its affinity mask, its cgroup's CPU bandwidth limit and ``LOKY_MAX_CPU_COUNT``."""
    from joblib import cpu_count  # imported when asked: an alignment worker process never asks (45 ms of its start)

    return cpu_count(only_physical_cores=False)


@contextmanager
def cyclic_gc_paused() -> Iterator[None]:
    """Pause the cyclic garbage collector around bulk work on graph terms (millions of tuples, none
    in a reference cycle, that each full collection would re-scan). Reference counting still frees
    everything."""
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was_enabled:
            gc.enable()


def exit_with_parent() -> None:
    """Pool initializer: a daemon thread that ends this worker within :data:`PARENT_CHECK_S` of its
    parent's end (a killed parent cannot shut its pool down; an orphan is reparented, so its parent
    process id changes)."""
    parent = os.getppid()

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(PARENT_CHECK_S)
        os._exit(1)  # no cleanup to wait for: the results would go to a process that is gone

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()
