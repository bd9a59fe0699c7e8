"""Process runtime helpers: usable CPUs, the cyclic garbage collector paused around bulk work, pool
workers that end with their parent, and a folder held by one process."""

from __future__ import annotations

import gc
import os
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TextIO

from service.errors import StoreInUseError

__all__ = ["usable_cpu_count", "cyclic_gc_paused", "exit_with_parent", "PARENT_CHECK_S", "lock_folder"]

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


def lock_folder(folder: Path, holder: str) -> TextIO:
    """Hold ``folder`` for this process: an exclusive lock on its ``.lock`` file for as long as the
    returned file stays open (the kernel drops it when the process ends, however it ends).

    :raises StoreInUseError: another process, or another open lock of this one, holds it.
    """
    import fcntl

    folder.mkdir(parents=True, exist_ok=True)
    handle = (folder / ".lock").open("a+", encoding="utf-8")
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        handle.seek(0)
        held_by = handle.read().strip() or "another process"
        handle.close()
        raise StoreInUseError(f"{folder} is in use by {held_by}: one {holder} per folder") from None
    handle.seek(0)
    handle.truncate()
    handle.write(f"{holder} (pid {os.getpid()})")
    handle.flush()
    return handle
