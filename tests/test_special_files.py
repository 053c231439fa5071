"""FIFOs and other special files given as inputs (issue 35, part 5): read as a stream where the format allows
it (CSV, JSON Lines, config files, label files), refused in one line where it does not (Parquet: seeking) or
where nothing is written; never a hang.  Every test that could hang is bounded by a timeout."""

from __future__ import annotations

import errno
import json
import os
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from footprint_uq import _files
from footprint_uq.batch.readers import open_detections
from footprint_uq.errors import InputError

pytestmark = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs os.mkfifo")

BOX = ("u_min_px", "v_min_px", "u_max_px", "v_max_px")
LIMIT_S = 20.0  # the bound of every call that could hang


def _bounded(fn, timeout_s: float = LIMIT_S):
    """``fn()`` in a thread; fails (instead of hanging the suite) when it has not returned within the timeout."""
    out = {}

    def run():
        try:
            out["value"] = fn()
        except BaseException as e:  # noqa: BLE001 - handed back to the test
            out["error"] = e

    t = threading.Thread(target=run, daemon=True)
    t.start()
    t.join(timeout_s)
    assert not t.is_alive(), f"hung for more than {timeout_s} s"
    if "error" in out:
        raise out["error"]
    return out["value"]


def _writer(path, data: bytes, *, delay_s: float = 0.1, deadline_s: float = LIMIT_S):
    """A thread that writes ``data`` into the FIFO once a reader has it open (never blocks for good: it opens
    without blocking and gives up after ``deadline_s``)."""

    def run():
        time.sleep(delay_s)
        end = time.monotonic() + deadline_s
        while True:
            try:
                fd = os.open(path, os.O_WRONLY | os.O_NONBLOCK)
                break
            except OSError as e:
                if e.errno != errno.ENXIO or time.monotonic() > end:
                    return
                time.sleep(0.01)
        os.set_blocking(fd, True)
        try:
            with os.fdopen(fd, "wb") as f:
                f.write(data)
        except BrokenPipeError:
            pass

    t = threading.Thread(target=run, daemon=True)
    t.start()
    return t


def _fifo(tmp_path, name):
    p = tmp_path / name
    os.mkfifo(p)
    return p


def _read_all(path, chunk_rows=7):
    r = open_detections(path, chunk_rows=chunk_rows)
    r.select(BOX)
    chunks = list(r)
    return r, chunks


@pytest.mark.parametrize("n", [3, 2500])  # 2500 JSON lines: more than the 1000 the column scan reads first
def test_csv_and_json_lines_fifos_are_read_as_streams(tmp_path, n):
    rows = np.arange(4 * n, dtype=float).reshape(n, 4)
    csv_text = "u_min_px,v_min_px,u_max_px,v_max_px\n" + "".join(",".join(f"{v:g}" for v in r) + "\n" for r in rows)
    jsonl_text = "".join(json.dumps(dict(zip(BOX, r.tolist(), strict=True))) + "\n" for r in rows)
    for name, text, first_line in (("d.csv", csv_text, 2), ("d.jsonl", jsonl_text, 1)):
        p = _fifo(tmp_path, name)
        _writer(p, text.encode())
        r, chunks = _bounded(lambda p=p: _read_all(p, chunk_rows=1000))
        got = np.concatenate([np.stack([c.table.column(k).to_numpy() for k in BOX], 1) for c in chunks])
        lines = np.concatenate([c.rows for c in chunks]) + first_line
        np.testing.assert_array_equal(got, rows)
        assert lines.tolist() == list(range(first_line, first_line + n))  # line numbers as for a file
        assert r.total is None and r.lines == n
        with pytest.raises(InputError, match="read once"):
            list(r)  # a stream cannot be read a second time: said, not an empty result


def test_parquet_fifo_is_refused_up_front(tmp_path):
    p = _fifo(tmp_path, "d.parquet")  # nobody writes: a refusal must not wait for a writer
    t0 = time.monotonic()
    with pytest.raises(InputError, match=r"regular file \(Parquet needs a seekable file.*got a FIFO\)"):
        _bounded(lambda: open_detections(p))
    assert time.monotonic() - t0 < 5


def test_fifo_nobody_writes_is_one_error_after_the_wait(tmp_path, monkeypatch):
    monkeypatch.setattr(_files, "FIFO_WAIT_S", 0.3)
    p = _fifo(tmp_path, "d.csv")
    t0 = time.monotonic()
    with pytest.raises(InputError, match="nothing was written to it within 0.3 s"):
        _bounded(lambda: open_detections(p))
    assert 0.25 < time.monotonic() - t0 < 10


def test_devices_and_directories_are_refused(tmp_path):
    for target, kind in (("/dev/zero", "character device"), (str(tmp_path), "directory")):
        link = tmp_path / f"x{len(kind)}.csv"
        link.symlink_to(target)
        with pytest.raises(InputError, match=f"got a {kind}"):
            _bounded(lambda link=link: open_detections(link))


def test_fifo_wait_from_the_environment(monkeypatch):
    monkeypatch.setenv(_files.FIFO_WAIT_ENV, "2.5")
    assert _files.fifo_wait_s() == 2.5
    for bad in ("nan", "inf", "-1", "0", "abc"):
        monkeypatch.setenv(_files.FIFO_WAIT_ENV, bad)
        with pytest.raises(InputError, match=_files.FIFO_WAIT_ENV):
            _files.fifo_wait_s()


def test_config_files_from_a_fifo(tmp_path, monkeypatch):
    """A camera file and a budget file written into FIFOs are read as streams; one nobody writes is an error."""
    from footprint_uq.io import load_camera
    from footprint_uq.uncertainty.budget import load_budget

    cam = _fifo(tmp_path, "cam.yaml")
    _writer(cam, b"model: pantilt\nfocal_px: 1000\nimage_size_px: [1920, 1080]\nheight_m: 8\npan_deg: 0\n"
                 b"tilt_deg: 20\n")
    camera = _bounded(lambda: load_camera(cam))
    assert camera.image_size_px == (1920, 1080)
    bud = _fifo(tmp_path, "budget.yaml")
    _writer(bud, b"name: fifo\npan_deg: 0.1\ntilt_deg: 0.1\n")
    assert _bounded(lambda: load_budget(str(bud))).name == "fifo"
    monkeypatch.setattr(_files, "FIFO_WAIT_S", 0.2)
    silent = _fifo(tmp_path, "silent.yaml")
    with pytest.raises(InputError, match="nothing was written"):
        _bounded(lambda: load_budget(str(silent)))


def test_kitti_label_fifo_nobody_writes_is_an_error_row(tmp_path, monkeypatch):
    """A label file that is a FIFO nobody writes: that file's error row; the other frames go on."""
    from footprint_uq.validation.readers import read_kitti_folder

    monkeypatch.setattr(_files, "FIFO_WAIT_S", 0.2)
    root = tmp_path / "kitti"
    for sub in ("calib", "denorm", "label_2"):
        (root / sub).mkdir(parents=True)
    p2 = "P2: 2763.2 0 970.6 0 0 2946.6 550.7 0 0 0 1 0\n"
    for fid in ("a", "b"):
        (root / "calib" / f"{fid}.txt").write_text(p2)
        (root / "denorm" / f"{fid}.txt").write_text("-0.0109 -0.9771 -0.2124 7.0044\n")
    (root / "label_2" / "a.txt").write_text("car 0 0 0.1 900 600 960 700 1.5 1.8 4.2 1 2 30 0.3\n")
    os.mkfifo(root / "label_2" / "b.txt")
    chunks = _bounded(lambda: list(read_kitti_folder(root)))
    by_file = {os.path.basename(c.source): c for c in chunks}
    assert by_file["a.txt"].error == [None]
    assert by_file["b.txt"].line.tolist() == [1] and "nothing was written" in by_file["b.txt"].error[0]


def _cli(args, env_extra, timeout_s=60):
    env = {**os.environ, **env_extra, "PYTHONPATH": os.pathsep.join(sys.path)}
    return subprocess.run([sys.executable, "-m", "footprint_uq.cli", *args], capture_output=True, text=True,
                          timeout=timeout_s, env=env)


def test_cli_fifo_nobody_writes_exits_2_in_one_line(tmp_path):
    """The command line, end to end: a detections FIFO nobody writes (CSV: after the wait; Parquet: at once)."""
    cam = tmp_path / "cam.yaml"
    cam.write_text("model: pantilt\nfocal_px: 1000\nimage_size_px: [1920, 1080]\nheight_m: 8\npan_deg: 0\n"
                   "tilt_deg: 20\n")
    for name in ("d.csv", "d.parquet"):
        p = _fifo(tmp_path, name)
        r = _cli(["objects", "--camera", str(cam), "--budget", "bw-cube1", "--detections", str(p), "--out",
                  str(tmp_path / f"out_{name}.csv")], {_files.FIFO_WAIT_ENV: "0.5"})
        assert r.returncode == 2, r.stderr
        lines = r.stderr.strip().splitlines()
        # the path may be shortened in the middle (a one-line message); its file name is always there
        assert len(lines) == 1 and lines[0].startswith("footprint-uq: error: detections:"), r.stderr
        assert f"{p.name}'" in lines[0] and (str(p) in lines[0] or "..." in lines[0]), r.stderr
        assert ("nothing was written" if name.endswith(".csv") else "Parquet needs a seekable file") in lines[0]


def test_validate_reads_a_pairs_table_and_a_camera_from_fifos(tmp_path):
    """validate end to end (in process): the pairs table and the camera file are FIFOs fed by writer threads."""
    from footprint_uq import PanTiltCamera
    from footprint_uq.io import save_camera
    from footprint_uq.viz.validation_run import run_validation

    cam = PanTiltCamera(focal_px=1400.0, image_size_px=(1920, 1080), height_m=8.0, pan_deg=30.0, tilt_deg=18.0)
    save_camera(cam, tmp_path / "cam_file.yaml")
    rng = np.random.default_rng(2)
    uv = np.c_[rng.uniform(300, 1600, 20), rng.uniform(700, 1050, 20)]
    xy = cam.backproject(uv).xy_world_m + rng.normal(0, 0.05, (20, 2))
    text = "u_min_px,v_min_px,u_max_px,v_max_px,x_m,y_m\n" + "".join(
        f"{u - 30},{v - 60},{u + 30},{v},{x},{y}\n" for (u, v), (x, y) in zip(uv, xy, strict=True))
    text += "1,2,3,4,inf,5\n"  # and a hostile row, line 22
    pairs, camera = _fifo(tmp_path, "pairs.csv"), _fifo(tmp_path, "cam.yaml")
    _writer(pairs, text.encode())
    _writer(camera, (tmp_path / "cam_file.yaml").read_bytes())
    summary, files = _bounded(lambda: run_validation(pairs, tmp_path / "out", "basler1", camera=camera,
                                                     report=False, fsync=False), timeout_s=600)
    assert summary["n_pairs"] == 20 and summary["rows"] == {"ok": 20, "error": 1}
    rows = files["objects"].read_text().splitlines()
    assert len(rows) == 22 and ',22,' in rows[-1]


def test_fleet_dataset_with_a_parquet_fifo_is_refused_by_name(tmp_path):
    """A FIFO named .parquet inside a fleet dataset folder is refused naming it (before: skipped silently)."""
    from footprint_uq.batch.fleet import plan

    ds = tmp_path / "ds" / "camera_id=a"
    ds.mkdir(parents=True)
    fifo = _fifo(ds, "part-0.parquet")
    with pytest.raises(InputError, match=r"part-0\.parquet.*got a FIFO"):
        _bounded(lambda: plan(tmp_path / "ds", tmp_path / "out", {}))
    assert fifo.exists()


def test_image_fifos_are_refused_not_waited_on(tmp_path):
    """Images are read with seeking (OpenCV, the header reader of `calibrate gcp --image`): a FIFO is refused."""
    from footprint_uq.calibration.detect import expand_inputs
    from footprint_uq.calibration.gcp_run import _image_header_size

    p = _fifo(tmp_path, "photo.png")
    for call in (lambda: expand_inputs([str(p)]), lambda: _image_header_size(p)):
        with pytest.raises(InputError, match="got a FIFO"):
            _bounded(call)


def test_detector_formats_never_sniff_or_wait_on_a_fifo(tmp_path):
    """Auto-detection reads a file's first bytes: on a FIFO it would take them from the reader (or wait for a
    writer forever).  A FIFO is taken by its extension (a canonical table streams), a detector format is refused."""
    from footprint_uq.batch.formats import detect_input_format, open_reader

    assert detect_input_format(_fifo(tmp_path, "d.csv")) == "csv"  # returns at once, nothing read
    for name, fmt in (("det.txt", None), ("results.json", "coco"), ("labels.txt", "mot")):
        p = _fifo(tmp_path, name)
        with pytest.raises(InputError, match="FIFO"):
            open_reader(p, format=fmt)
