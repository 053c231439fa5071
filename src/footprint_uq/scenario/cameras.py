"""The case study's two infrastructure cameras and the three camera types.

The paper (Section "Case study") uses two roadside cameras in CARLA: camera 1 "captures
the diagonal" of the intersection, camera 2 sees the vehicle "across from the first
camera".  Our defaults, for a vehicle approaching from the south and turning left
(west):

* **camera 1** on a pole at the north-east corner, looking south-west along the
  intersection's diagonal (pan 225 deg): it sees the approach lane, the whole turn and
  the exit lane;
* **camera 2** on a pole on the west side of the north arm, 12 m back from the corner,
  across the intersection from the approaching vehicle and facing it (pan 190 deg, i.e.
  roughly south); set back so that it also sees the first ~25 m of the exit lane.

Both are 1920x1080, 8 m and 10 m high, tilted 20 deg down, with 80 and 90 deg horizontal
fields of view (focal 1144 px and 960 px), like a real roadside installation.  The principal point is
the image centre ``(w/2, h/2)``, the convention of CARLA's camera sensor, so the same
camera can be placed in CARLA (:mod:`footprint_uq.integrations.carla.bridge`).

The camera *types* (Basler, BW-Bullet, BW-Cube) are error budgets: the paper's presets
``basler1``, ``bw-bullet1``, ``bw-cube1`` (:mod:`footprint_uq.uncertainty.presets`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from .._checks import as_float
from ..cameras.pantilt import PanTiltCamera
from ..errors import ConfigError
from .intersection import Intersection, cfg_float

__all__ = ["CameraSpec", "default_camera_specs", "CAMERA_TYPES", "focal_from_hfov", "hfov_from_focal"]

#: the paper's three camera types, in the order of its figure panels (a), (b), (c)
CAMERA_TYPES: tuple[str, ...] = ("basler1", "bw-bullet1", "bw-cube1")


def focal_from_hfov(hfov_deg: float, width_px: int) -> float:
    """Focal length (px) of a pinhole camera with horizontal field of view ``hfov_deg``."""
    h = as_float("hfov_deg", hfov_deg, lo=1.0, hi=179.0)
    return float(width_px / (2.0 * np.tan(np.deg2rad(h) / 2.0)))


def hfov_from_focal(focal_px: float, width_px: int) -> float:
    """Horizontal field of view (deg) of a pinhole camera."""
    return float(np.rad2deg(2.0 * np.arctan(width_px / (2.0 * as_float("focal_px", focal_px, positive=True)))))


@dataclass(frozen=True)
class CameraSpec:
    """Mounting and optics of one roadside camera.

    Parameters
    ----------
    name : str
    position_m : (x, y) foot point of the pole in W, metres
    height_m : float  mount height above the ground, metres
    pan_deg : float  compass heading of the boresight (clockwise from north)
    tilt_deg : float  below the horizontal (positive down)
    roll_deg : float
    hfov_deg : float  horizontal field of view (used when ``focal_px`` is None)
    focal_px : float, optional
    image_size_px : (width, height)
    """

    name: str
    position_m: tuple = (0.0, 0.0)
    height_m: float = 8.0
    pan_deg: float = 0.0
    tilt_deg: float = 20.0
    roll_deg: float = 0.0
    hfov_deg: float = 80.0
    focal_px: float | None = None
    image_size_px: tuple = (1920, 1080)
    description: str = field(default="", compare=False)

    @property
    def resolved_focal_px(self) -> float:
        if self.focal_px is not None:
            return as_float(f"cameras.{self.name}.focal_px", self.focal_px, positive=True)
        return focal_from_hfov(self.hfov_deg, int(self.image_size_px[0]))

    def build(self) -> PanTiltCamera:
        """The :class:`~footprint_uq.cameras.pantilt.PanTiltCamera` (principal point at ``(w/2, h/2)``)."""
        w, h = self.image_size_px
        return PanTiltCamera(self.resolved_focal_px, (w, h), self.height_m, self.pan_deg, self.tilt_deg,
                             self.roll_deg, position_m=tuple(self.position_m), principal_point_px=(w / 2, h / 2))

    def to_dict(self) -> dict:
        d = asdict(self)
        d["position_m"] = list(self.position_m)
        d["image_size_px"] = list(self.image_size_px)
        d["focal_px"] = self.resolved_focal_px
        d["hfov_deg"] = hfov_from_focal(d["focal_px"], int(self.image_size_px[0]))
        return d

    @classmethod
    def from_dict(cls, d: dict, *, where: str = "cameras") -> CameraSpec:
        if not isinstance(d, dict):
            raise ConfigError(where, d, "a mapping of camera settings")
        allowed = set(cls.__dataclass_fields__)
        unknown = sorted(set(d) - allowed)
        if unknown:
            raise ConfigError(f"{where}.{unknown[0]}", d[unknown[0]], f"one of {sorted(allowed)}")
        if "name" not in d:
            raise ConfigError(f"{where}.name", None, "a camera name")
        kw = dict(d)
        for k in ("position_m", "image_size_px"):
            if k in kw:
                v = kw[k]
                if not isinstance(v, list | tuple) or len(v) != 2:
                    raise ConfigError(f"{where}.{k}", v, "a pair of numbers")
                kw[k] = tuple(int(x) if k == "image_size_px" else float(x) for x in v)
        for k in ("height_m", "pan_deg", "tilt_deg", "roll_deg", "hfov_deg"):
            if k in kw:
                kw[k] = cfg_float(f"{where}.{k}", kw[k])
        spec = cls(**kw)
        spec.build()  # validates every value with the camera's own checks
        return spec


def default_camera_specs(intersection: Intersection | None = None, *, setback_m: float = 2.0) -> list[CameraSpec]:
    """The two cameras of the case study for a vehicle approaching from the south (see module doc)."""
    intersection = intersection or Intersection()
    c = intersection.half_width_m + as_float("setback_m", setback_m, nonnegative=True)
    return [
        CameraSpec("camera1", (c, c), 8.0, 225.0, 20.0, 0.0, 80.0, None, (1920, 1080),
                   "north-east corner, looking south-west along the diagonal of the intersection"),
        CameraSpec("camera2", (-c, c + 12.0), 10.0, 190.0, 20.0, 0.0, 90.0, None, (1920, 1080),
                   "north arm, 12 m back from the north-west corner, across the intersection, facing the "
                   "approaching vehicle"),
    ]
