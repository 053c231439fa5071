"""A Mosquitto broker on a free loopback port for the service benchmarks (``bench_service.py``,
``bench_service_50hz.py``), and the small waits they share."""

from __future__ import annotations

import contextlib
import shutil
import socket
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path
from typing import NamedTuple

#: the bench's broker: no persistence, a deep per-client queue, TCP_NODELAY on its sockets (docs/service.md)
TUNED = "persistence false\nmax_queued_messages 100000\nset_tcp_nodelay true\n"


class Broker(NamedTuple):
    process: subprocess.Popen
    port: int


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def port_open(port: int) -> bool:
    try:
        socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
        return True
    except OSError:
        return False


def wait(cond, timeout_s: float, what: str) -> None:
    """Poll ``cond()`` every 20 ms until it is true; RuntimeError after ``timeout_s``."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if cond():
            return
        time.sleep(0.02)
    raise RuntimeError(f"timed out waiting for {what}")


def mosquitto_path() -> str:
    path = shutil.which("mosquitto") or "/usr/sbin/mosquitto"
    if not Path(path).exists():
        raise RuntimeError("mosquitto not installed (apt-get install mosquitto; tools/sysdeps.sh)")
    return path


@contextlib.contextmanager
def mosquitto(workdir: Path, *, tuned: bool = True) -> Iterator[Broker]:
    """Mosquitto listening on a free loopback port (its config in ``workdir``), stopped on exit.

    ``tuned``: the bench's settings (:data:`TUNED`); False: Mosquitto's defaults but for the listener (what a
    deployment that changed nothing runs).
    """
    port = free_port()
    conf = Path(workdir) / "mosquitto.conf"
    conf.write_text(f"listener {port} 127.0.0.1\nallow_anonymous true\n" + (TUNED if tuned else ""))
    proc = subprocess.Popen([mosquitto_path(), "-c", str(conf)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        wait(lambda: port_open(port), 10, "mosquitto")
        yield Broker(proc, port)
    finally:
        proc.terminate()
        proc.wait(10)
