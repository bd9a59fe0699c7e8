"""Pool workers that end with the process that started them.

A process pool's workers wait for work from their parent; when the parent is killed (``kill -9``,
the OOM killer) its pool cannot shut them down, and they stay: idle, holding their memory (a
diagnosis worker ~200 MB), or computing on a job nobody will read. :func:`exit_with_parent`, given
to a pool as its ``initializer``, ends the worker within a second of its parent's end (Linux and
macOS reparent an orphan, so its parent process id changes).
"""

from __future__ import annotations

import os
import threading
import time

__all__ = ["exit_with_parent"]

#: How often a worker looks whether its parent is still there, seconds.
PARENT_CHECK_S = 1.0


def exit_with_parent() -> None:
    """Pool initializer: a daemon thread that ends this process once its parent is gone."""
    parent = os.getppid()

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(PARENT_CHECK_S)
        os._exit(1)  # no cleanup to wait for: the results would go to a process that is gone

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()
