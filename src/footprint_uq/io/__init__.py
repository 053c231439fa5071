"""Reading and writing camera and budget files.

* :func:`load_camera` reads our own camera files (YAML/JSON, ``model: pan-tilt`` or
  ``model: opencv``), OpenCV FileStorage calibration files, ROS CameraInfo YAML and
  TUMTraf/A9 calibration JSON (format detected from the content).
* :func:`save_camera` / :func:`save_budget` write our own formats (exact round trip).
* :func:`load_intrinsics` and :func:`camera_from_intrinsics_and_pose` combine an
  intrinsics-only calibration with a pose given separately.

Every format is described in ``docs/file-formats.md``.
"""

from .camera_files import (
    FORMATS,
    camera_from_dict,
    camera_to_dict,
    detect_format,
    load_camera,
    load_intrinsics,
    save_budget,
    save_camera,
)
from .dataset_files import read_tumtraf_calibration
from .opencv_files import read_opencv_file
from .pose import camera_from_intrinsics_and_pose, read_pose
from .ros_files import read_ros_camera_info

__all__ = ["FORMATS", "camera_from_dict", "camera_to_dict", "detect_format", "load_camera", "load_intrinsics",
           "save_budget", "save_camera", "camera_from_intrinsics_and_pose", "read_pose", "read_opencv_file",
           "read_ros_camera_info", "read_tumtraf_calibration"]
