"""Per-object motion with honest confidence: tracks of a camera's objects across frames.

Small components in the spirit of Stone Soup (docs/uncertainty-model.md, "Motion: velocity and heading"):

* :class:`~footprint_uq.tracking.models.ConstantVelocity` -- the transition model (nearly constant velocity,
  continuous white-noise acceleration);
* :class:`~footprint_uq.tracking.filter.InteractingModels` -- an interacting-multiple-model (IMM) filter over two
  such modes, a quiet one (driving on) and a manoeuvre one (turning, braking), switching as a Markov chain;
* :class:`~footprint_uq.tracking.filter.SchmidtPredictor`, :class:`~footprint_uq.tracking.filter.SchmidtUpdater`,
  :class:`~footprint_uq.tracking.filter.Initiator` -- a Schmidt-Kalman (consider-state) filter whose measurement
  model splits each centre's covariance into the camera's calibration error (shared by every frame: a consider
  state ``w``, mapped to each position by that frame's Jacobian) and the per-frame imaging / detector noise;
* :class:`~footprint_uq.tracking.table.TrackTable` -- one camera's tracks keyed by ``object_id``, with the
  deleter (timeout) and the gate (a jump inconsistent with the track starts a new one);
* :func:`~footprint_uq.tracking.motion.object_motion` -- velocity, speed, heading, yaw, their sigmas and the
  object's age as the arrays of the V2X messages' motion fields; :func:`~footprint_uq.tracking.motion.track_motion`
  -- a table's step and those fields in one call;
* :class:`~footprint_uq.tracking.rsu_fusion.RsuFusion` -- the roadside unit's one object list from its cameras'
  tracks (docs/rsu-fusion.md).
"""

from .filter import (
    Initiator,
    InteractingModels,
    SchmidtPredictor,
    SchmidtUpdater,
    SplitMeasurement,
    TrackState,
    mode_switch_probabilities,
)
from .models import ConstantVelocity
from .motion import MOTION_FIELDS, MotionArrays, ObjectMotion, object_motion, track_motion
from .rsu_fusion import FrameFusion, FusedObjects, RsuFusion, RsuFusionConfig
from .table import CALIBRATION_MODES, SharedJacobianAt, TrackerConfig, TrackOutput, TrackTable

__all__ = ["ConstantVelocity", "SchmidtPredictor", "SchmidtUpdater", "Initiator", "SplitMeasurement", "TrackState",
           "InteractingModels", "mode_switch_probabilities",
           "TrackTable", "SharedJacobianAt", "TrackerConfig", "TrackOutput", "CALIBRATION_MODES", "MotionArrays",
           "ObjectMotion", "MOTION_FIELDS", "object_motion", "track_motion", "RsuFusion", "RsuFusionConfig",
           "FrameFusion", "FusedObjects"]
