"""A catalogue of hostile inputs for the command line (issue 11), shared by the tests and the
reliability script (``bench/reliability.py``).

Every case is a command line and what the README promises for it:

* ``exit 2`` -- bad input: one line on stderr naming the field, no traceback, and nothing
  new under the output name;
* ``rows``   -- bad *rows* in a detection file: exit 0, every physical line of the file is one
  output row (``rows lost`` = lines - rows out must be 0), the bad ones with status ``error``;
* ``fleet rows`` -- the same for a fleet job (``--registry``): exit 0, its ``_summary.json`` consistent
  with every input row out, at least ``extra["errors"]`` of them error rows.

``extra["must_exist"]``: files that must still be there afterwards (nothing deleted outside --out).

No case may reach the last-resort handler (exit 3) or print a traceback.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

CAMERA = """model: pan-tilt
image_size_px: [1920, 1080]
focal_px: 1400.0
position_m: [0.0, 0.0]
height_m: 8.0
pan_deg: 30.0
tilt_deg: 20.0
"""
BUDGET = """name: site
focal_px: 0.5
principal_point_px: [0.4, 0.3]
position_m: [0.05, 0.05]
height_m: 0.10
pan_deg: 0.05
tilt_deg: 0.05
imaging_px: [0.1, 0.1]
"""
HEADER = "frame,object_id,u_min_px,v_min_px,u_max_px,v_max_px"
GOOD = "{i},car{i},900,500,980,560"
BIG = "1" + "0" * 399  # a 400-digit number
#: a 397-byte "billion laughs" (the issue's was 472 bytes): 9 levels of 9 aliases, ~4e8 values once expanded (issue 24)
ANCHOR_BOMB = ("a: &a [lol, lol, lol, lol, lol, lol, lol, lol, lol]\n"
               + "".join(f"{n}: &{n} [{', '.join(['*' + p] * 9)}]\n" for p, n in zip("abcdefg", "bcdefgh", strict=True))
               + "model: [*h, *h, *h, *h, *h, *h, *h, *h, *h]\n")


@dataclass
class Case:
    """One hostile input: ``argv`` of ``footprint-uq``, the promise (``exit2`` or ``rows``)."""

    name: str
    argv: list
    expect: str = "exit2"
    out: Path | None = None          # output that must not appear (exit2) or whose rows are checked (rows)
    lines: int | None = None         # rows: physical data lines of the input
    stderr_has: str | None = None    # exit2: a word the one-line message must contain
    extra: dict = field(default_factory=dict)


def _homography(*, K_scale: float = 1.0, H_scale: float = 1.0) -> str:
    """The ``model: homography`` file of :data:`CAMERA` with K (focal lengths times ``K_scale``: a K that does not
    belong to H) and H times ``H_scale`` (the same homography, scaled out of range)."""
    import numpy as np
    import yaml

    from footprint_uq.cameras.homography import homography_from_camera
    from footprint_uq.io import camera_from_dict

    cam = camera_from_dict(yaml.safe_load(CAMERA))
    K = cam.K.copy()
    K[0, 0] *= K_scale
    K[1, 1] *= K_scale
    H = homography_from_camera(cam) * H_scale
    return yaml.safe_dump({"model": "homography", "image_size_px": [1920, 1080],
                           "H_ground_image": np.asarray(H).tolist(), "K": K.tolist()})


def _w(path: Path, data) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    if isinstance(data, bytes):
        path.write_bytes(data)
    else:
        path.write_text(data, encoding="utf-8")
    return path


def _camera_cases(d: Path, budget: Path) -> list[Case]:
    cams = {
        "camera 400-digit focal": CAMERA.replace("1400.0", BIG),
        "camera focal 1e308": CAMERA.replace("1400.0", "1e308"),
        "camera height 1e308": CAMERA.replace("height_m: 8.0", "height_m: 1e308"),
        "camera image size 1e308": CAMERA.replace("[1920, 1080]", "[1e308, 1e308]"),
        "camera image size 400 digits": CAMERA.replace("[1920, 1080]", f"[{BIG}, 1080]"),
        "camera position 1e308": CAMERA.replace("[0.0, 0.0]", "[1e308, 0.0]"),
        "camera not UTF-8": CAMERA.replace("pan-tilt", "pan-tilt\xe9").encode("latin-1"),
        "camera binary": bytes(range(256)) * 4,
        "camera empty": "",
        "camera list": "- 1\n- 2\n",
        "camera deep nesting": "[" * 100_000,
        "camera NaN tilt": CAMERA.replace("tilt_deg: 20.0", "tilt_deg: .nan"),
        "camera tilt 1e308": CAMERA.replace("tilt_deg: 20.0", "tilt_deg: 1e308"),
        "camera pan 400 digits": CAMERA.replace("pan_deg: 30.0", f"pan_deg: {BIG}"),
        "camera bool focal": CAMERA.replace("1400.0", "true"),
        "camera focal as list": CAMERA.replace("1400.0", "[1, 2]"),
        "camera yaml anchor bomb": ("a: &a [x, x, x, x, x, x, x, x, x]\nb: &b [*a, *a, *a, *a, *a, *a, *a, *a]\n"
                                    "c: &c [*b, *b, *b, *b, *b, *b, *b, *b]\nd: &d [*c, *c, *c, *c, *c, *c, *c]\n"
                                    "model: *d\n"),
        "camera yaml billion laughs 9x9 aliases": ANCHOR_BOMB,
        "camera duplicate key": CAMERA + "tilt_deg: 70.0\n",
        "camera focal 1e-300": CAMERA.replace("1400.0", "1e-300"),
        "homography K disagrees with H": _homography(K_scale=1.3),
        "homography H x 1e-300 with K": _homography(H_scale=1e-300),
    }
    out = []
    for name, text in cams.items():
        p = _w(d / f"{name.replace(' ', '_')}.yaml", text)
        out.append(Case(name, ["locate", "--camera", str(p), "--budget", str(budget), "--pixel", "959.5", "800"]))
    js = _w(d / "camera_400.json", '{"model": "pan-tilt", "image_size_px": [1920, 1080], "focal_px": ' + BIG
            + ', "position_m": [0, 0], "height_m": 8, "pan_deg": 30, "tilt_deg": 20}')
    out.append(Case("camera JSON 400-digit focal", ["locate", "--camera", str(js), "--budget", "basler1",
                                                    "--pixel", "959.5", "800"]))
    js = _w(d / "camera_duplicate_key.json", json.dumps({"model": "pan-tilt", "image_size_px": [1920, 1080],
                                                         "focal_px": 1400, "height_m": 8, "pan_deg": 30,
                                                         "tilt_deg": 20})[:-1] + ', "tilt_deg": 70}')
    out.append(Case("camera JSON duplicate key", ["locate", "--camera", str(js), "--budget", "basler1",
                                                  "--pixel", "959.5", "800"], stderr_has="tilt_deg"))
    js = _w(d / "camera_huge_int.json", '{"model": "pan-tilt", "image_size_px": [1920, 1080], "focal_px": 1'
            + "0" * 5000 + ', "position_m": [0, 0], "height_m": 8, "pan_deg": 30, "tilt_deg": 20}')
    out.append(Case("camera JSON 5000-digit focal", ["locate", "--camera", str(js), "--budget", "basler1",
                                                     "--pixel", "959.5", "800"]))
    return out


def _budget_cases(d: Path, camera: Path) -> list[Case]:
    buds = {
        "budget 400-digit sigma": BUDGET.replace("focal_px: 0.5", f"focal_px: {BIG}"),
        "budget sigma 1e200": BUDGET.replace("focal_px: 0.5", "focal_px: 1e200"),
        "budget all sigmas 1e200": "\n".join(line.split(":")[0] + ": " + ("[1e200, 1e200]" if "[" in line else "1e200")
                                             if ":" in line and not line.startswith("name") else line
                                             for line in BUDGET.splitlines()) + "\n",
        "budget not UTF-8": (BUDGET + "description: caf\xe9\n").encode("latin-1"),
        "budget covariance names 5": BUDGET + "covariance: {names: 5}\n",
        "budget covariance matrix text": BUDGET + "covariance: {names: [focal_px], matrix: abc}\n",
        "budget covariance not PSD": "name: x\ncovariance: {names: [pan_rad, tilt_rad], matrix: [[1, 2], [2, 1]]}\n",
        "budget covariance inf": "name: x\ncovariance: {names: [pan_rad], matrix: [[.inf]]}\n",
        "budget binary": bytes(range(256)) * 4,
        "budget negative sigma": BUDGET.replace("focal_px: 0.5", "focal_px: -0.5"),
        "budget sigma text": BUDGET.replace("focal_px: 0.5", "focal_px: abc"),
        "budget list": "- 1\n",
        "budget billion laughs 9x9 aliases": ANCHOR_BOMB.replace("model", "focal_px"),
        "budget duplicate key": BUDGET + "focal_px: 0.0\n",
    }
    out = []
    for name, text in buds.items():
        p = _w(d / f"{name.replace(' ', '_')}.yaml", text)
        out.append(Case(name, ["locate", "--camera", str(camera), "--budget", str(p), "--pixel", "959.5", "800"]))
    p = _w(d / "budget_duplicate.json", '{"name": "x", "tilt_deg": 0.05, "tilt_deg": 0.0}')
    out.append(Case("budget JSON duplicate key", ["locate", "--camera", str(camera), "--budget", str(p), "--pixel",
                                                  "959.5", "800"], stderr_has="tilt_deg"))
    return out


def _locate_cases(camera: Path) -> list[Case]:
    base = ["locate", "--camera", str(camera), "--budget", "basler1"]
    return [
        Case("locate pixel 1e308", base + ["--pixel", "1e308", "1e308"]),
        Case("locate pixel nan", base + ["--pixel", "nan", "800"]),
        Case("locate pixel inf", base + ["--pixel", "inf", "800"]),
        Case("locate confidence 1", base + ["--pixel", "959.5", "800", "--confidence", "1"]),
        Case("locate confidence nan", base + ["--pixel", "959.5", "800", "--confidence", "nan"]),
    ]


def _detections(d: Path, camera: Path) -> list[Case]:
    """Detection files with bad lines (rows) and unreadable detection files (exit 2)."""
    out = []
    good = [GOOD.format(i=i) for i in range(20)]

    def rows_case(name, body: bytes | str, lines: int, ext="csv", fmt="csv"):
        p = _w(d / f"{name.replace(' ', '_')}.{ext}", body)
        o = d / f"{name.replace(' ', '_')}.out.{fmt}"
        return Case(name, ["objects", "--camera", str(camera), "--budget", "basler1", "--detections", str(p),
                           "--out", str(o), "--quiet"], "rows", o, lines)

    g = "\n".join(good)
    out.append(rows_case("csv stray quote line 2", HEADER + "\n" + good[0] + '\n1,"car7,900,500,980,560\n'
                         + "\n".join(good[1:]) + "\n", 21))
    out.append(rows_case("csv unterminated quote last line", HEADER + "\n" + good[0] + "\n" + good[1]
                         + '\n2,car2,900,500,980,"560\n', 3))
    out.append(rows_case("csv quoted line break", HEADER + '\n1,"car\n7",900,500,980,560\n' + g + "\n", 22))
    out.append(rows_case("csv latin-1 line", (HEADER + "\n" + good[0] + "\n1,caf\xe9,900,500,980,560\n" + g + "\n")
                         .encode("latin-1"), 22))
    out.append(rows_case("csv BOM and CRLF", ("\ufeff" + HEADER + "\r\n" + "\r\n".join(good) + "\r\n")
                         .encode("utf-8"), 20))
    out.append(rows_case("csv lone CR", HEADER + "\n" + good[0] + "\r" + good[1] + "\n" + good[2] + "\n", 2))
    out.append(rows_case("csv frame 10^23", HEADER + "\n" + "1" + "0" * 23 + ",a,900,500,980,560\n" + g + "\n", 21))
    out.append(rows_case("csv 400-digit value", HEADER + "\n" + f"1,a,{BIG},500,980,560\n" + g + "\n", 21))
    out.append(rows_case("csv NUL byte", HEADER + "\n1,a\x00b,900,500,980,560\n" + g + "\n", 21))
    out.append(rows_case("csv empty lines", HEADER + "\n\n" + good[0] + "\n\n\n" + good[1] + "\n", 5))
    out.append(rows_case("csv no final newline", HEADER + "\n" + g, 20))
    out.append(rows_case("csv binary lines", HEADER.encode() + b"\n" + bytes(range(1, 256)) * 8 + b"\n"
                         + g.encode() + b"\n", 20 + 1 + (bytes(range(1, 256)) * 8).count(b"\n")))
    js = [json.dumps({"frame": i, "u_min_px": 900, "v_min_px": 500, "u_max_px": 980, "v_max_px": 560})
          for i in range(10)]
    out.append(rows_case("jsonl frame 10^23", "\n".join(js[:3] + ['{"frame": 1' + "0" * 23 + ', "u_min_px": 900, '
                                                                  '"v_min_px": 500, "u_max_px": 980, '
                                                                  '"v_max_px": 560}'] + js[3:]) + "\n",
                         11, "jsonl", "jsonl"))
    out.append(rows_case("jsonl frame 1e23", "\n".join(js[:3] + ['{"frame": 1e23, "u_min_px": 900, "v_min_px": 500,'
                                                                  ' "u_max_px": 980, "v_max_px": 560}'] + js[3:])
                         + "\n", 11, "jsonl", "jsonl"))
    out.append(rows_case("jsonl latin-1 and blank", ("\n".join(js[:2]) + '\n{"frame": 3, "class": "caf\xe9"}\n\n'
                                                     + "\n".join(js[2:]) + "\n").encode("latin-1"),
                         12, "jsonl", "jsonl"))
    out.append(rows_case("jsonl deep nesting", "\n".join(js[:2] + ["[" * 100_000] + js[2:]) + "\n", 11, "jsonl",
                         "jsonl"))
    out.append(rows_case("jsonl 5000-digit number", "\n".join(js[:2] + ['{"u_min_px": 1' + "0" * 5000 + "}"]
                                                              + js[2:]) + "\n", 11, "jsonl", "jsonl"))
    out.append(rows_case("jsonl null first line (pyarrow 26 SIGSEGV)", "null\n" + "\n".join(js) + "\n", 11, "jsonl",
                         "jsonl"))
    box3d = json.dumps({"frame": 99, "x_m": 5.0, "y_m": 20.0, "z_m": 0.8, "length_m": 4.0, "width_m": 2.0,
                        "height_m": 1.5, "yaw_deg": 0.0})
    out.append(rows_case("jsonl a 3-D box line in the first chunk", "\n".join(js[:2] + [box3d] + js[2:]) + "\n",
                         11, "jsonl", "jsonl"))
    out.append(rows_case("jsonl huge exponent", "\n".join(js[:2] + ['{"u_min_px": 1e999999}'] + js[2:]) + "\n",
                         11, "jsonl", "jsonl"))

    def exit2(name, body, ext, **kw):
        p = _w(d / f"{name.replace(' ', '_')}.{ext}", body)
        o = d / f"{name.replace(' ', '_')}.out.parquet"
        return Case(name, ["objects", "--camera", str(camera), "--budget", "basler1", "--detections", str(p),
                           "--out", str(o), "--quiet"], "exit2", o, **kw)

    out.append(exit2("parquet empty file", b"", "parquet", stderr_has="Parquet"))
    out.append(exit2("parquet garbage", b"PAR1" + bytes(range(256)) * 16, "parquet", stderr_has="Parquet"))
    out.append(exit2("csv empty file", b"", "csv"))
    out.append(exit2("csv latin-1 header", (HEADER + ",caf\xe9\n").encode("latin-1") + b"1,2,3\n", "csv"))
    out.append(exit2("csv binary file", bytes(range(256)) * 64, "csv"))
    out.append(exit2("csv header only garbage", b'"unterminated,header\n1,2\n', "csv"))
    out.append(exit2("jsonl binary file", bytes(range(256)) * 64, "jsonl"))
    out.append(exit2("csv duplicate header", HEADER + ",u_min_px\n" + GOOD.format(i=1) + ",3\n", "csv"))
    return out


def _detector_formats(d: Path, camera: Path) -> list[Case]:
    """Detector files (docs/integrations.md) with bad lines (rows, one per line) or unusable as a whole (exit 2)."""
    yolo = ["2 0.5 0.6 0.05 0.1 0.9"] * 5
    mot = ["1,3,901,501,80,60,0.9,-1,-1,-1"] * 5
    v5 = ["xmin,ymin,xmax,ymax,confidence,class,name"] + ["900,500,980,560,0.9,2,car"] * 5

    def rows_case(name, body, lines: int, ext: str):
        p = _w(d / f"{name.replace(' ', '_')}.{ext}", body)
        o = d / f"{name.replace(' ', '_')}.out.csv"
        return Case(name, ["objects", "--camera", str(camera), "--budget", "basler1", "--detections", str(p),
                           "--out", str(o), "--quiet"], "rows", o, lines)

    def exit2(name, path, stderr_has=None):
        o = d / f"{name.replace(' ', '_')}.out.csv"
        return Case(name, ["objects", "--camera", str(camera), "--budget", "basler1", "--detections", str(path),
                           "--out", str(o), "--quiet"], "exit2", o, stderr_has=stderr_has)

    out = [
        rows_case("yolo latin-1, NUL and blank lines", (yolo[0] + "\n2 caf\xe9 0.6 0.1 0.1\n\n2 0.5\x00 0.6 0.1 0.1\n"
                                                       + "\n".join(yolo[1:]) + "\n").encode("latin-1"), 8, "txt"),
        rows_case("yolo segment polygon and 1e400", "\n".join(yolo[:2] + ["0 0.1 0.1 0.2 0.1 0.2 0.2 0.1 0.2",
                                                                         "0 1e400 0.5 0.1 0.1"] + yolo[2:]) + "\n",
                  7, "txt"),
        rows_case("yolo binary lines", yolo[0].encode() + b"\n" + bytes(range(1, 256)) * 4 + b"\n"
                  + "\n".join(yolo[1:]).encode() + b"\n", 5 + 1 + (bytes(range(1, 256)) * 4).count(b"\n"), "txt"),
        rows_case("mot frame 10^23 and no final newline", "\n".join(mot[:2] + ["1" + "0" * 23 + mot[0][1:]] + mot[2:]),
                  6, "txt"),
        rows_case("yolov5 csv stray quote and latin-1", ("\n".join(v5[:2] + ['900,"500,980,560,0.9,2,car',
                                                                            "900,500,980,560,0.9,2,caf\xe9"] + v5[2:])
                                                       + "\n").encode("latin-1"), 7, "csv"),
        rows_case("coco entries that are not detections", json.dumps(
            [{"image_id": 1, "category_id": 3, "bbox": [900, 500, 80, 60], "score": 0.9}, None, [1, 2],
             {"image_id": True, "category_id": 3, "bbox": [900, 500, 80, 60]},
             {"image_id": 1, "category_id": 3, "bbox": [900, 500, -80, 60]},
             {"image_id": 10**30, "category_id": "3", "bbox": "x"}]), 6, "json"),
    ]
    out.append(exit2("coco truncated JSON", _w(d / "trunc.json", '[{"image_id": 1, "bbox": [1, 2'), "COCO"))
    out.append(exit2("coco binary JSON", _w(d / "bin.json", bytes(range(256)) * 16), "COCO"))
    out.append(exit2("coco images of another size", _w(d / "size.json", json.dumps(
        {"images": [{"id": 1, "file_name": "a.jpg", "width": 1280, "height": 720}], "categories": [],
         "annotations": [{"image_id": 1, "category_id": 3, "bbox": [1, 2, 3, 4]}]})), "1280 x 720"))
    seq = d / "seq"
    _w(seq / "seqinfo.ini", "[Sequence]\nimWidth=640\nimHeight=480\nframeRate=30\n")
    out.append(exit2("mot seqinfo of another size", _w(seq / "det" / "det.txt", "\n".join(mot) + "\n"), "640 x 480"))
    _w(seq / "bad" / "seqinfo.ini", bytes(range(256)) * 4)
    out.append(exit2("mot binary seqinfo", _w(seq / "bad" / "det.txt", "\n".join(mot) + "\n"), "seqinfo"))
    (d / "empty_dir").mkdir(parents=True, exist_ok=True)
    out.append(exit2("a folder without label files", d / "empty_dir", "detections"))
    labels = _w(d / "names_labels" / "000001.txt", "\n".join(yolo) + "\n")
    for name, fname, body in (("class names yaml anchor bomb", "bomb.yaml", ANCHOR_BOMB.replace("model:", "names:")),
                              ("class names binary file", "bin.names", bytes(range(256)) * 16),
                              ("class names negative id", "neg.yaml", "names: {-1: car, 2: car}\n"),
                              ("class names COCO categories without ids", "cats.json",
                               '{"categories": [{"name": 1}]}')):
        names = _w(d / "names" / fname, body)
        o = d / f"{name.replace(' ', '_')}.out.csv"
        out.append(Case(name, ["objects", "--camera", str(camera), "--budget", "basler1", "--detections", str(labels),
                               "--class-names", str(names), "--out", str(o), "--quiet"], "exit2", o,
                        stderr_has=fname))
    return out


def _truncated_parquet(d: Path, camera: Path) -> list[Case]:
    import numpy as np
    import pyarrow as pa
    import pyarrow.parquet as pq

    n = 5000
    t = pa.table({"frame": np.arange(n), "u_min_px": np.full(n, 900.0), "v_min_px": np.full(n, 500.0),
                  "u_max_px": np.full(n, 980.0), "v_max_px": np.full(n, 560.0)})
    d.mkdir(parents=True, exist_ok=True)
    full = d / "full.parquet"
    pq.write_table(t, full, row_group_size=1000)
    data = full.read_bytes()
    out = []
    for name, body in (("parquet truncated half", data[: len(data) // 2]), ("parquet no footer", data[:-8]),
                       ("parquet corrupt middle", data[:200] + bytes(400) + data[600:])):
        p = _w(d / f"{name.replace(' ', '_')}.parquet", body)
        o = d / f"{name.replace(' ', '_')}.out.parquet"
        out.append(Case(name, ["objects", "--camera", str(camera), "--budget", "basler1", "--detections", str(p),
                               "--out", str(o), "--quiet"], "exit2", o))
    # a fleet dataset with one truncated file; a binary registry; a camera id that climbs out of --out
    ds = d / "fleet"
    tc = t.append_column("camera_id", pa.array(["cam1"] * n))
    pq.write_table(tc, _w(ds / "a.parquet", b""), row_group_size=1000)
    _w(ds / "b.parquet", data[: len(data) // 2])
    _w(d / "reg" / "cam1.yaml", CAMERA)
    out.append(Case("fleet truncated file", ["objects", "--registry", str(d / "reg"), "--budget", "basler1",
                                             "--detections", str(ds), "--out", str(d / "fleet_out"), "--quiet"],
                    "exit2", d / "fleet_out"))
    reg = _w(d / "registry.csv", bytes(range(256)) * 8)
    out.append(Case("fleet binary registry", ["objects", "--registry", str(reg), "--budget", "basler1",
                                              "--detections", str(ds / "a.parquet"), "--out", str(d / "fleet_out2"),
                                              "--quiet"], "exit2", d / "fleet_out2"))
    reg = _w(d / "registry.yaml", bytes(range(256)) * 8)
    out.append(Case("fleet binary yaml registry", ["objects", "--registry", str(reg), "--budget", "basler1",
                                                   "--detections", str(ds / "a.parquet"), "--out",
                                                   str(d / "fleet_out3"), "--quiet"], "exit2", d / "fleet_out3"))
    return out


def _fleet_cases(d: Path) -> list[Case]:
    """Fleet jobs: camera ids too long for a folder name, a symlinked --out with --overwrite, a second job on the
    same --out, a registry that is an alias bomb (issue 24)."""
    import os

    import numpy as np
    import pyarrow as pa
    import pyarrow.parquet as pq

    n = 12
    boxes = {"frame": np.arange(n), "u_min_px": np.full(n, 900.0), "v_min_px": np.full(n, 500.0),
             "u_max_px": np.full(n, 980.0), "v_max_px": np.full(n, 560.0)}
    long_reg = "\u00e9" * 50  # registered, 300 characters once percent-encoded
    ids = ["cam1"] * 4 + ["x" * 300] * 4 + [long_reg] * 4  # the 300-character one is not registered
    ds = d / "ids"
    ds.mkdir(parents=True, exist_ok=True)
    pq.write_table(pa.table({"camera_id": ids, **boxes}), ds / "part.parquet")
    _w(d / "reg" / "cam1.yaml", CAMERA)
    reg = _w(d / "registry.csv", f"camera_id,camera\ncam1,reg/cam1.yaml\n{long_reg},reg/cam1.yaml\n")
    base = ["objects", "--registry", str(reg), "--budget", "basler1", "--detections", str(ds), "--quiet"]
    out = [Case("fleet camera ids too long for a folder name", base + ["--out", str(d / "out_ids")], "fleet rows",
                d / "out_ids", n, extra={"errors": 8})]
    victim_dir = d / "elsewhere"
    victim = _w(victim_dir / ".keep.tmp-0123abcd.parquet", b"not ours")  # looks like a temporary of ours
    link = d / "out_link"
    if not link.is_symlink():
        os.symlink(victim_dir, link)
    out.append(Case("fleet --out a symlink with --overwrite", base + ["--out", str(link), "--overwrite"], "exit2",
                    None, stderr_has="symbolic link", extra={"must_exist": [str(victim)]}))
    busy = d / "out_busy"
    _w(d / ".out_busy.lock", f"{os.getpid()}\n")  # a live job holds it
    out.append(Case("fleet second job on the same --out", base + ["--out", str(busy)], "exit2", busy,
                    stderr_has="lock", extra={"must_exist": [str(d / ".out_busy.lock")]}))
    bomb = _w(d / "bomb_registry.yaml", ANCHOR_BOMB)
    out.append(Case("fleet registry billion laughs", ["objects", "--registry", str(bomb), "--budget", "basler1",
                                                      "--detections", str(ds), "--out", str(d / "out_bomb"),
                                                      "--quiet"], "exit2", d / "out_bomb"))
    return out


def _fuse_cases(d: Path) -> list[Case]:
    hdr = "frame,object_id,x_m,y_m,cov_xx_m2,cov_xy_m2,cov_yy_m2"
    a = _w(d / "fa.csv", hdr + "\n1,o1,10.0,5.0,0.04,0.0,0.04\n2,o2,11.0,5.0,0.04,0.0,0.04\n")
    b = _w(d / "fb.csv", hdr + "\n1,o1,1e308,5.0,0.04,0.0,0.04\n2,o2,11.1,5.0,0.04,0.0,0.04\n")
    c = _w(d / "fc.csv", hdr + "\n1,o1,10.0,5.0,1e308,0.0,1e308\n2,o2,11.1,5.0,0.04,0.0,0.04\n")
    e = _w(d / "fe.parquet", b"")
    return [
        Case("fuse x_m 1e308", ["fuse", str(a), str(b), "--out", str(d / "fused1.csv")], "fuse", d / "fused1.csv"),
        Case("fuse cov 1e308", ["fuse", str(a), str(c), "--out", str(d / "fused2.csv")], "fuse", d / "fused2.csv"),
        Case("fuse empty parquet", ["fuse", str(a), str(e), "--out", str(d / "fused3.csv")], "exit2",
             d / "fused3.csv"),
    ]


def _calibration_cases(d: Path) -> list[Case]:
    images = Path(__file__).parent / "data" / "opencv-chessboard-right"  # OpenCV's 9x6 sample images
    return [
        Case("calibrate --board 7x5 on 9x6 images", ["calibrate", "intrinsics", str(images), "--board", "7x5",
                                                     "--square-m", "0.025", "--out", str(d / "cal75"), "--quiet",
                                                     "--workers", "1"], "exit2", None, stderr_has="board"),
        Case("calibrate max tilt 95", ["calibrate", "synthetic", "--out", str(d / "syn"), "--max-tilt-deg", "95"],
             "exit2", d / "syn"),
        Case("calibrate max tilt -5", ["calibrate", "synthetic", "--out", str(d / "syn2"), "--max-tilt-deg", "-5"],
             "exit2", d / "syn2"),
    ]


def _gcp_cases(d: Path) -> list[Case]:
    """``calibrate gcp``: point sigmas past the budget files' limits, a solve whose covariance a budget file
    could not hold, too many points, a photo too large to draw (told by its header, never decoded)."""
    import struct
    import zlib

    rows = ["200,700,-9.0,21.0", "1700,720,12.0,22.0", "960,1000,1.0,10.5", "300,600,-14.0,33.0",
            "1600,610,17.0,34.0", "950,560,0.5,45.0", "620,820,-6.0,15.0", "1300,840,6.0,15.5"]
    good = _w(d / "g.csv", "u_px,v_px,x_m,y_m\n" + "\n".join(rows) + "\n")

    def sig(name, v):
        return _w(d / f"{name}.csv", "u_px,v_px,x_m,y_m,sigma_px\n" + "".join(f"{r},{v}\n" for r in rows))

    many = _w(d / "many.csv", "u_px,v_px,x_m,y_m\n" + "1,2,3,4\n" * 10_001)
    ihdr = struct.pack(">IIBBBBB", 30000, 30000, 8, 2, 0, 0, 0)
    png = _w(d / "huge.png", b"\x89PNG\r\n\x1a\n" + struct.pack(">I", 13) + b"IHDR" + ihdr
             + struct.pack(">I", zlib.crc32(b"IHDR" + ihdr)))

    def case(name, pts, out, *extra, size="1920x1080", has=None):
        return Case(name, ["calibrate", "gcp", "--points", str(pts), "--image-size", size, *extra, "--out",
                           str(d / out)], "exit2", d / out, stderr_has=has)

    return [
        case("gcp sigma_px 1e-300", sig("tiny", "1e-300"), "o1", has="sigma_px"),
        case("gcp sigma_px 1e300", sig("huge", "1e300"), "o2", has="sigma_px"),
        case("gcp sigma_px 1e6 (budget refuses the solve)", sig("limit", "1e6"), "o3", has="budget files refuse"),
        case("gcp 10001 points", many, "o4", has="at most 10000"),
        case("gcp 30000x30000 PNG header", good, "o5", "--image", str(png), size="30000x30000", has="Mpx"),
        case("gcp image not PNG/JPEG", good, "o6", "--image", str(_w(d / "x.gif", b"GIF89a" + bytes(20))),
             has="PNG or JPEG"),
    ]


def _other_commands(d: Path, camera: Path) -> list[Case]:
    """Files read by the other commands (scenario configs, recordings, LiDAR correspondences)."""
    binary = _w(d / "binary.dat", bytes(range(256)) * 8)
    bad_yaml = _w(d / "bad.yaml", "a: [1, 2\n")
    bad_json = _w(d / "bad.json", '{"a": 1,\n')
    corr = _w(d / "corr.csv", bytes(range(256)) * 8)
    rec = _w(d / "rec.jsonl", bytes(range(256)) * 8)
    return [
        Case("case-study binary config", ["case-study", "--out", str(d / "cs1"), "--config", str(binary)], "exit2",
             d / "cs1"),
        Case("case-study broken YAML config", ["case-study", "--out", str(d / "cs2"), "--config", str(bad_yaml)],
             "exit2", d / "cs2"),
        Case("case-study broken JSON config", ["case-study", "--out", str(d / "cs3"), "--config", str(bad_json)],
             "exit2", d / "cs3"),
        Case("case-study binary recording", ["case-study", "--out", str(d / "cs4"), "--recording", str(rec)],
             "exit2", d / "cs4"),
        Case("carla export binary config", ["carla", "export", "--out", str(d / "r.jsonl"), "--config", str(binary)],
             "exit2", d / "r.jsonl"),
        *_plan_cases(d / "plan", binary, bad_yaml, bad_json),
        Case("extrinsics binary correspondences", ["calibrate", "extrinsics", "--pairs", str(corr), "--camera",
                                                   str(camera), "--board", "9x6", "--square-m", "0.1", "--ground",
                                                   "identity", "--out", str(d / "ex")], "exit2", None,
             stderr_has="corr.csv"),
    ]


SITE = """zones: [{name: road, polygon_m: [[0, 0], [20, 0], [20, 8], [0, 8]], max_semi_major_m: 1.0}]
mounts: [{name: a, position_m: [-5, 4], height_m: 8}]
cameras: [{name: hd, image_size_px: [640, 360], budget: basler1, lenses: [{name: n, focal_px: 500}]}]
search: {pan_step_deg: 90, tilts_deg: [20], heights_per_mount: 1, max_cameras: 1}
"""


def _plan_cases(d: Path, binary: Path, bad_yaml: Path, bad_json: Path) -> list[Case]:
    """Site and layout files of ``footprint-uq plan``."""
    site = _w(d / "site.yaml", SITE)
    nan_site = _w(d / "nan.yaml", SITE.replace("max_semi_major_m: 1.0", "max_semi_major_m: .nan"))
    huge = _w(d / "huge.yaml", SITE.replace("[[0, 0], [20, 0]", "[[0, 0], [1e300, 0]"))
    layout = _w(d / "layout.yaml", "cameras: [{name: a, camera_file: binary.dat, budget: basler1}]\n")
    _w(d / "binary.dat", bytes(range(256)) * 8)
    out = [Case(f"plan {n} site", ["plan", "--site", str(f), "--out", str(d / f"o{i}"), "--no-progress"], "exit2",
                d / f"o{i}") for i, (n, f) in enumerate((("binary", binary), ("broken YAML", bad_yaml),
                                                         ("broken JSON", bad_json), ("NaN requirement", nan_site),
                                                         ("huge polygon", huge)))]
    out.append(Case("plan --evaluate binary layout", ["plan", "--site", str(site), "--evaluate", str(binary),
                                                      "--out", str(d / "ev1")], "exit2", d / "ev1"))
    out.append(Case("plan --evaluate layout with a binary camera file", ["plan", "--site", str(site), "--evaluate",
                                                                        str(layout), "--out", str(d / "ev2")],
                    "exit2", d / "ev2"))
    return out


def build(d: Path) -> list[Case]:
    """Write every hostile file under ``d`` and return the cases."""
    d = Path(d)
    camera = _w(d / "camera.yaml", CAMERA)
    budget = _w(d / "budget.yaml", BUDGET)
    return (_camera_cases(d / "cam", budget) + _budget_cases(d / "bud", camera) + _locate_cases(camera)
            + _detections(d / "det", camera) + _detector_formats(d / "fmt", camera)
            + _truncated_parquet(d / "pq", camera) + _fleet_cases(d / "fleet")
            + _fuse_cases(d / "fuse")
            + _calibration_cases(d / "cal") + _gcp_cases(d / "gcp") + _other_commands(d / "other", camera))


def run(case: Case) -> dict:
    """Run one case in-process; returns what happened and whether the promise held."""
    import traceback

    from click.testing import CliRunner

    from footprint_uq.cli.main import main

    r = CliRunner().invoke(main, [str(a) for a in case.argv], catch_exceptions=True)
    err = r.stderr if hasattr(r, "stderr") else r.output
    tb = ("Traceback" in err or "Traceback" in r.output
          or (r.exception is not None and not isinstance(r.exception, SystemExit)))
    res = {"name": case.name, "expect": case.expect, "exit": r.exit_code, "traceback": bool(tb),
           "stderr": err.strip()[:300], "rows_lost": 0, "ok": False}
    if tb and r.exc_info is not None and not isinstance(r.exception, SystemExit):
        res["stderr"] = "".join(traceback.format_exception(*r.exc_info))[-600:]
    # one error line, the last one (progress notes such as "frame X: no board found" may precede it)
    lines_err = [x for x in err.strip().splitlines() if x.strip()]
    errors = [x for x in lines_err if x.startswith("footprint-uq: error:")]
    kept = all(Path(p).exists() for p in case.extra.get("must_exist", ()))
    if case.expect == "exit2":
        res["ok"] = (r.exit_code == 2 and len(errors) == 1 and lines_err[-1] == errors[0] and not tb
                     and (case.stderr_has is None or case.stderr_has in err)
                     and (case.out is None or not Path(case.out).exists()) and kept)
    elif case.expect == "fleet rows":
        summ = Path(case.out) / "_summary.json"
        js = json.loads(summ.read_text()) if r.exit_code == 0 and summ.exists() else {}
        res["rows_out"] = js.get("rows_out", 0)
        res["rows_lost"] = max(0, case.lines - res["rows_out"])
        res["ok"] = (r.exit_code == 0 and not tb and js.get("consistent") is True and js.get("rows_in") == case.lines
                     and res["rows_out"] == case.lines and js.get("rows_error", 0) >= case.extra["errors"] and kept)
    elif case.expect == "rows":
        rows_out = _rows(case.out) if r.exit_code == 0 and Path(case.out).exists() else 0
        res["rows_lost"] = max(0, case.lines - rows_out)
        res["rows_out"] = rows_out
        summ = Path(str(case.out) + ".summary.json")
        js = json.loads(summ.read_text()) if summ.exists() else {}
        res["ok"] = (r.exit_code == 0 and not tb and rows_out == case.lines and js.get("consistent") is True
                     and js.get("lines_in") == case.lines)
    elif case.expect == "fuse":
        res["ok"] = r.exit_code == 0 and not tb and _fused_finite(case.out)
    return res


def _rows(path) -> int:
    import pyarrow as pa

    from footprint_uq.batch.readers import open_detections

    p = Path(path)
    if p.suffix == ".parquet":
        import pyarrow.parquet as pq

        return pq.ParquetFile(p).metadata.num_rows
    if p.suffix == ".csv":
        import pyarrow.csv as pcsv

        return pcsv.read_csv(p).num_rows
    del pa, open_detections
    return sum(1 for line in p.read_text().splitlines() if line.strip())


def _fused_finite(path) -> bool:
    """Every fused object with status ok has a finite centre and covariance."""
    import numpy as np
    import pyarrow.csv as pcsv

    t = pcsv.read_csv(path).to_pandas()
    ok = t["status"] == "ok" if "status" in t else np.ones(len(t), bool)
    cols = [c for c in ("x_m", "y_m", "cov_xx_m2", "cov_xy_m2", "cov_yy_m2") if c in t]
    return bool(np.isfinite(t.loc[ok, cols].to_numpy(dtype=float)).all())
