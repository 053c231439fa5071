"""The demo's camera view (footprint_uq.viz.camera_view): box corners pinned by hand, the ellipses drawn where the
footprint centres are, one per budget and object."""

from __future__ import annotations

import numpy as np
import pytest

from footprint_uq import FrameProcessor, InputError
from footprint_uq.io import camera_from_dict
from footprint_uq.uncertainty.ellipse import ellipse_axes
from footprint_uq.viz.camera_view import box_corners_m, plot_camera_view
from footprint_uq.viz.demo import DEMO_CAMERA, DEMO_OBJECTS


def test_box_corners_pinned():
    """A 4 x 2 x 1.5 m box at (10, 20), centre 0.75 m up: along east at yaw 0, along north at yaw 90 deg."""
    c = box_corners_m([[10.0, 20.0, 0.75, 4.0, 2.0, 1.5, 0.0]])[0]
    assert np.allclose(c[:4], [[12, 21, 0], [12, 19, 0], [8, 19, 0], [8, 21, 0]])
    assert np.allclose(c[4:, 2], 1.5) and np.allclose(c[4:, :2], c[:4, :2])
    c90 = box_corners_m([[10.0, 20.0, 0.75, 4.0, 2.0, 1.5, np.pi / 2]])[0]
    assert np.allclose(c90[:4, :2], [[9, 22], [11, 22], [11, 18], [9, 18]])
    with pytest.raises(InputError, match="boxes3d_world"):
        box_corners_m(np.zeros((2, 6)))


def test_ellipses_sit_on_the_footprint_centres():
    cam = camera_from_dict(dict(DEMO_CAMERA))
    fig = plot_camera_view(cam, ["basler1", "bw-cube1"], DEMO_OBJECTS)
    ax = fig.axes[0]
    est = FrameProcessor(cam, "bw-cube1").boxes3d(DEMO_OBJECTS)
    centre_uv = cam.project_ground(est.centre_xy_world_m).uv_px
    fills = [p for p in ax.patches if p.get_alpha() == pytest.approx(0.18)]
    assert len(fills) == 2 * len(DEMO_OBJECTS)  # one ellipse per budget and object
    for k, (u, v) in enumerate(centre_uv):  # each bw-cube1 ellipse (drawn second) contains its centre's pixel
        assert fills[len(DEMO_OBJECTS) + k].get_path().contains_point((u, v)), k
    labels = [t.get_text() for t in ax.texts if t.get_fontweight() == "bold"]  # (the range rings: not bold)
    a = ellipse_axes(est.centre_cov_m2, confidence=0.95)[0]
    assert labels == [f"{x:.2g} m" for x in a]  # labelled with the last budget's 95 % semi-major axes
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["Basler1", "BW-Cube1"]
