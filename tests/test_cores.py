"""fast.cores.free_cores and the points kernel's choice of one thread or all (issue 24: no stall waiting for a
busy core)."""

from __future__ import annotations

import os
import sys

import numpy as np
import pytest

from footprint_uq.fast import cores
from footprint_uq.fast import map_kernels as mk


def _loadavg(tmp_path, running: int):
    p = tmp_path / "loadavg"
    p.write_text(f"0.50 0.40 0.30 {running}/321 4567\n")
    return str(p)


@pytest.mark.parametrize(("running", "own", "expected"), [(1, 1, 0), (2, 1, -1), (3, 3, 0), (1, 2, 0)])
def test_free_cores_counts_other_processes_runnable_tasks(tmp_path, monkeypatch, running, own, expected):
    monkeypatch.setattr(cores, "_LOADAVG", _loadavg(tmp_path, running))
    monkeypatch.setattr(cores, "_own_running", lambda: own)
    monkeypatch.setattr(os, "cpu_count", lambda: 2)
    assert cores.free_cores() == 2 + expected


def test_free_cores_unknown_without_proc(tmp_path, monkeypatch):
    monkeypatch.setattr(cores, "_LOADAVG", str(tmp_path / "missing"))
    assert cores.free_cores() is None
    (tmp_path / "garbled").write_text("nothing here\n")
    monkeypatch.setattr(cores, "_LOADAVG", str(tmp_path / "garbled"))
    assert cores.free_cores() is None


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_free_cores_on_this_machine():
    """This thread is running while it asks: its own core is never counted as taken."""
    assert cores._own_running() >= 1
    free = cores.free_cores()
    assert isinstance(free, int) and free <= (os.cpu_count() or 1)


_N = mk.SERIAL_BELOW


@pytest.mark.parametrize(("n", "free", "expected"), [(10, 2, "serial"), (_N, 2, "threaded"), (_N, 1, "serial"),
                                                     (_N, None, "threaded"), (_N - 1, None, "serial")])
def test_points_run_threaded_only_with_a_free_core(monkeypatch, n, free, expected):
    ran = []
    monkeypatch.setattr(mk, "free_cores", lambda: free)
    monkeypatch.setattr(mk, "_points_general", lambda *a: ran.append("threaded"))
    monkeypatch.setattr(mk, "_points_general_serial", lambda *a: ran.append("serial"))
    k = dict(params=None, R=None, omega=None, colptr=None, rowidx=None, vals=None, vc=None, Ccc=None, has_qc=False)
    mk.points_into(k, None, np.zeros((n, 2)), None, None, None, None, None, None)
    assert ran == [expected]
