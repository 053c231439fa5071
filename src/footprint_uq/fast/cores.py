"""Whether a second core is free right now: the threaded kernels' choice between one thread and all.

A parallel region of two threads on a machine whose other core is busy (a detector beside us, another
job) ends only when the descheduled worker has run: the call waits a scheduler slice, milliseconds, for a
core that a single thread would not have needed (issue 24: ``covariance_points`` on 10,000 points had a
p90 of 2-3.5 times its median with the other core busy).  So the kernels that may run threaded ask
:func:`free_cores` first and stay on the calling thread when no other core is idle.
"""

from __future__ import annotations

import os

__all__ = ["free_cores"]

_LOADAVG = "/proc/loadavg"
_TASKS = "/proc/self/task"


def _own_running() -> int:
    """Threads of this process that are runnable now (state ``R`` in ``/proc/self/task/*/stat``)."""
    n = 0
    for tid in os.listdir(_TASKS):
        try:
            with open(f"{_TASKS}/{tid}/stat", "rb") as f:
                s = f.read()
        except OSError:  # the thread ended meanwhile
            continue
        i = s.rfind(b")")  # the command name may hold spaces and parentheses; the state follows the last ')'
        n += s[i + 2:i + 3] == b"R"
    return n


def free_cores() -> int | None:
    """Cores not taken by another process's runnable thread at this instant, this thread's own included.

    ``os.cpu_count()`` minus the runnable tasks of the whole machine (``/proc/loadavg``, 4th field) that
    are not this process's.  None where that cannot be read (not Linux): the caller keeps its default.
    A snapshot, not an average: a quiet machine gives the core count, one busy neighbour one less.
    """
    try:
        with open(_LOADAVG, "rb") as f:
            running = int(f.read().split()[3].split(b"/")[0])
        own = _own_running()
    except (OSError, ValueError, IndexError):
        return None
    return (os.cpu_count() or 1) - max(0, running - own)
