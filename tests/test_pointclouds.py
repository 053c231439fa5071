"""Point-cloud readers and writers: round trips, NaN/zero accounting, malformed files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from footprint_uq.calibration import pointclouds as pc
from footprint_uq.errors import InputError

DATA = Path(__file__).parent / "data" / "lidar"


@pytest.fixture
def cloud():
    rng = np.random.default_rng(0)
    xyz = rng.normal(0, 10, size=(500, 3))
    xyz[7] = np.nan
    xyz[11, 1] = np.inf
    xyz[20] = 0.0
    fields = {"intensity": rng.uniform(0, 255, 500).astype(np.float32),
              "ring": rng.integers(0, 128, 500).astype(np.uint16)}
    return xyz, fields


def _expected(xyz, dtype):
    keep = np.isfinite(xyz).all(1) & ~(xyz == 0).all(1)
    return xyz[keep].astype(dtype).astype(np.float64), keep


@pytest.mark.parametrize("data", ["ascii", "binary", "binary_compressed"])
@pytest.mark.parametrize("dtype", ["f4", "f8"])
def test_pcd_round_trip(tmp_path, cloud, data, dtype):
    xyz, fields = cloud
    p = pc.write_pcd(tmp_path / "c.pcd", xyz, fields, data=data, dtype=dtype)
    c = pc.read_point_cloud(p)
    exp, keep = _expected(xyz, dtype)
    np.testing.assert_array_equal(c.xyz_m, exp)
    assert c.xyz_m.dtype == np.float64 and c.xyz_m.shape == (497, 3)
    np.testing.assert_array_equal(c.fields["intensity"], fields["intensity"][keep])
    np.testing.assert_array_equal(c.fields["ring"], fields["ring"][keep])
    assert (c.n_read, c.n_nonfinite_dropped, c.n_zero_dropped) == (500, 2, 1)
    assert c.stats()["n_points"] == 497


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian"])
def test_ply_round_trip(tmp_path, cloud, fmt):
    xyz, fields = cloud
    p = pc.write_ply(tmp_path / "c.ply", xyz, fields, fmt=fmt, dtype="f8")
    c = pc.read_point_cloud(p)
    exp, keep = _expected(xyz, "f8")
    np.testing.assert_array_equal(c.xyz_m, exp)
    np.testing.assert_array_equal(c.fields["ring"], fields["ring"][keep])
    assert c.n_nonfinite_dropped == 2 and c.n_zero_dropped == 1


def test_ply_big_endian_and_faces(tmp_path):
    pts = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]], dtype=">f4")
    head = (b"ply\nformat binary_big_endian 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
            b"property float z\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n")
    (tmp_path / "b.ply").write_bytes(head + pts.tobytes())
    c = pc.read_ply(tmp_path / "b.ply")
    np.testing.assert_array_equal(c.xyz_m, pts.astype(np.float64))


def test_npy_and_csv_round_trip(tmp_path, cloud):
    xyz, fields = cloud
    c = pc.read_point_cloud(pc.write_npy(tmp_path / "c.npy", xyz, fields["intensity"]))
    exp, keep = _expected(xyz, "f8")
    np.testing.assert_array_equal(c.xyz_m, exp)
    np.testing.assert_allclose(c.fields["intensity"], fields["intensity"][keep])
    c = pc.read_point_cloud(pc.write_csv(tmp_path / "c.csv", xyz, {"intensity": fields["intensity"]}))
    np.testing.assert_array_equal(c.xyz_m, exp)
    # structured npy
    s = np.zeros(3, dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"), ("t", "f8")])
    s["x"], s["z"], s["t"] = [1, 2, 3], [4, 5, 6], [7, 8, 9]
    np.save(tmp_path / "s.npy", s)
    c = pc.read_npy(tmp_path / "s.npy")
    np.testing.assert_array_equal(c.xyz_m[:, 2], [4, 5, 6])
    np.testing.assert_array_equal(c.fields["t"], [7, 8, 9])


def test_csv_headerless_and_separators(tmp_path):
    (tmp_path / "a.csv").write_text("1 2 3 9\n4 5 6 8\n")
    c = pc.read_csv(tmp_path / "a.csv")
    np.testing.assert_array_equal(c.xyz_m, [[1, 2, 3], [4, 5, 6]])
    np.testing.assert_array_equal(c.fields["intensity"], [9, 8])
    (tmp_path / "b.csv").write_text("Z;Y;X\n3;2;1\n")
    np.testing.assert_array_equal(pc.read_csv(tmp_path / "b.csv").xyz_m, [[1, 2, 3]])


def test_hand_written_pcd_fixture():
    c = pc.read_point_cloud(DATA / "tiny_ascii.pcd")
    np.testing.assert_array_equal(c.xyz_m, [[1.5, -2.25, 0.125], [3, 4, 5]])
    np.testing.assert_array_equal(c.fields["intensity"], [10, 200])
    assert (c.n_read, c.n_nonfinite_dropped, c.n_zero_dropped) == (4, 1, 1)
    c = pc.read_pcd(DATA / "tiny_ascii.pcd", drop_zero=False)
    assert len(c) == 3 and c.n_zero_dropped == 0


def test_lzf_round_trip_with_back_references():
    rng = np.random.default_rng(1)
    for data in (b"", b"a", b"abcabcabcabcabcabc" * 50, rng.integers(0, 4, 5000).astype(np.uint8).tobytes(),
                 rng.integers(0, 256, 3000).astype(np.uint8).tobytes(), bytes(70000)):
        comp = pc.lzf_compress(data)
        assert pc.lzf_decompress(comp, len(data)) == data
    assert len(pc.lzf_compress(bytes(70000))) < 1000  # back-references are used
    with pytest.raises(ValueError):
        pc.lzf_decompress(b"\xe0\xff\xff", 10)  # reference before the start


def _pcd(fields="x y z", size="4 4 4", typ="F F F", n=2, data="ascii", body=b"1 2 3\n4 5 6\n"):
    return (f"VERSION 0.7\nFIELDS {fields}\nSIZE {size}\nTYPE {typ}\nCOUNT {' '.join('1' for _ in size.split())}\n"
            f"WIDTH {n}\nHEIGHT 1\nPOINTS {n}\nDATA {data}\n").encode() + body


@pytest.mark.parametrize("content, match", [
    (_pcd(fields="a b c"), "fields x, y and z"),
    (_pcd(body=b"1 2 3\n"), "2 rows"),
    (_pcd(body=b"1 2 3\n4 five 6\n"), "row 2"),
    (_pcd(data="binary", body=b"\x00" * 10), "24 bytes"),
    (_pcd(data="binary_compressed", body=b"\x05\x00\x00\x00\x18\x00\x00\x00\x00"), "compressed"),
    (_pcd(data="weird"), "ascii, binary or binary_compressed"),
    (_pcd(typ="F F Q"), "TYPE"),
    (b"hello world", "PCD"),
])
def test_malformed_pcd(tmp_path, content, match):
    p = tmp_path / "bad.pcd"
    p.write_bytes(content)
    with pytest.raises(InputError, match=match) as e:
        pc.read_point_cloud(p)
    assert "bad.pcd" in str(e.value)


def test_malformed_other_formats(tmp_path):
    (tmp_path / "a.ply").write_bytes(b"ply\nformat binary_middle_endian 1.0\nelement vertex 1\nend_header\n")
    with pytest.raises(InputError, match="a.ply.*ascii, binary_little_endian"):
        pc.read_point_cloud(tmp_path / "a.ply")
    (tmp_path / "b.ply").write_bytes(b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n1\n")
    with pytest.raises(InputError, match="x, y and z"):
        pc.read_point_cloud(tmp_path / "b.ply")
    np.save(tmp_path / "c.npy", np.zeros((4, 2)))
    with pytest.raises(InputError, match=r"c.npy.*\(N, 3\+\)"):
        pc.read_point_cloud(tmp_path / "c.npy")
    (tmp_path / "d.npy").write_bytes(b"not numpy")
    with pytest.raises(InputError, match="d.npy"):
        pc.read_point_cloud(tmp_path / "d.npy")
    (tmp_path / "e.csv").write_text("x,y,z\n1,2,3\n4,oops,6\n")
    with pytest.raises(InputError, match="e.csv: row 3"):
        pc.read_point_cloud(tmp_path / "e.csv")
    (tmp_path / "f.csv").write_text("a,b,c\n1,2,3\n")
    with pytest.raises(InputError, match="x, y and z"):
        pc.read_point_cloud(tmp_path / "f.csv")
    with pytest.raises(InputError, match="one of .pcd"):
        pc.read_point_cloud(tmp_path / "g.las")
    with pytest.raises(InputError, match="existing file"):
        pc.read_point_cloud(tmp_path / "missing.pcd")
    with pytest.raises(InputError, match=r"\(N, 3\)"):
        pc.write_pcd(tmp_path / "h.pcd", np.zeros((3, 2)))
