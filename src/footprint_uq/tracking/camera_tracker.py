"""One camera's tracker as a service frame runs it: one call per frame from the centres to the motion columns.

:class:`CameraTracker` is a small component (Stone Soup style) over the tracking layer's parts, so that a frame
enters ``tracking/`` once and comes back with every column the records and the messages need:

1. :meth:`~footprint_uq.tracking.classes.ClassTracks.step` -- the tracks' compiled IMM update (per class model),
   ``B`` at the tracks' predicted positions, each update's NIS;
2. :meth:`~footprint_uq.tracking.consistency.NisMonitor.observe` -- the on-line consistency check (those NIS per
   class over a window; optional);
3. :meth:`~footprint_uq.tracking.contact_slide.ContactSlide.apply` -- 2-D boxes only: the sliding contact's
   velocity term added to the reported velocity covariance (not to the track's state);
4. :func:`~footprint_uq.tracking.motion.object_motion` -- speed, heading, yaw and their sigmas, true east / north.

Steps 1 and 2 run under :attr:`CameraTracker.lock` (one frame of a camera at a time; the health record reads the
monitor under it too).  The result, :class:`FrameMotion`, carries the tracker's output with the slide term (what
the CP service fuses, ``service/cp_serve.py``) beside the motion columns.  ``tests/test_camera_tracker.py`` holds
:meth:`CameraTracker.step_frame` to the sequence of the four calls on seeded frames.
"""

from __future__ import annotations

import math
import threading
from typing import NamedTuple

import numpy as np

from .._checks import as_float
from .classes import ClassTracks, tracker_configs
from .consistency import DEFAULT_WINDOW_S, NisMonitor
from .contact_slide import ContactSlide
from .motion import ObjectMotion, object_motion
from .table import SharedJacobianAt, TrackerConfig, TrackOutput

__all__ = ["CameraTracker", "FrameMotion"]


class FrameMotion(NamedTuple):
    """One frame's objects through a :class:`CameraTracker` (n objects, in frame order).

    track_id : (n,) int64      the object's track (-1: not tracked)
    motion : ObjectMotion      velocity, speed, heading, yaw, their sigmas, age (true east / north; NaN: unknown);
                               its ``age_s`` is ``tracks.age_s`` (one array: neither is written after the step)
    tracks : TrackOutput       the tracker's output, with the sliding contact's term in ``cov_v_m2ps2`` for 2-D
                               boxes (frame W)
    """

    track_id: np.ndarray
    motion: ObjectMotion
    tracks: TrackOutput


#: a tuple of :class:`FrameMotion`'s three fields made a FrameMotion without the named tuple's ``__new__``
_new_frame = tuple.__new__


class CameraTracker:
    """One camera's tracks, their consistency check and the 2-D boxes' slide term, one call per frame (module doc).

    Parameters
    ----------
    tracks : ClassTracks
        The camera's tracks (a motion model per class).
    slide : ContactSlide, optional
        The sliding contact's velocity term of 2-D boxes (None: a camera that cannot render a box).
    nis : NisMonitor, optional
        The on-line NIS check over ``tracks`` (None: off).
    heading_offset_deg : float
        Bearing of W's +y axis from true north (the camera's map tie): the motion's east / north and compass
        angles.
    """

    def __init__(self, tracks: ClassTracks, *, slide: ContactSlide | None = None, nis: NisMonitor | None = None,
                 heading_offset_deg: float = 0.0):
        self.tracks, self.slide, self.nis = tracks, slide, nis
        self.heading_offset_deg = as_float("heading_offset_deg", heading_offset_deg)
        self.lock = threading.Lock()
        self._rank = tracks.rank

    @classmethod
    def for_camera(cls, camera, budget, config: TrackerConfig | None = None, *, window_s: float = DEFAULT_WINDOW_S,
                   heading_offset_deg: float = 0.0) -> CameraTracker:
        """The tracker of a camera with its error ``budget`` (an :class:`~footprint_uq.uncertainty.budget.
        ErrorBudget`; its ``motion`` section, if any, gives the class models over ``config``): ``B`` evaluated at
        the predicted positions (:class:`~footprint_uq.tracking.table.SharedJacobianAt`), the slide term where the
        camera can render a box, the NIS check over ``window_s`` seconds (0: off)."""
        at = SharedJacobianAt(camera, budget)
        configs = tracker_configs(getattr(budget, "motion", None), config or TrackerConfig())
        tracks = ClassTracks(*configs, rank=at.rank, shared_at=at)
        window_s = as_float("window_s", window_s, nonnegative=True)
        return cls(tracks, slide=ContactSlide.for_camera(camera), nis=NisMonitor(tracks, window_s=window_s)
                   if window_s else None, heading_offset_deg=heading_offset_deg)

    def fresh(self) -> CameraTracker:
        """An empty copy: the same models, slide term and window, no tracks, nothing observed."""
        tracks = self.tracks.fresh()
        nis = None if self.nis is None else NisMonitor(tracks, window_s=self.nis.window_s, alpha=self.nis.alpha,
                                                       min_updates=self.nis.min_updates,
                                                       max_updates=self.nis.max_updates,
                                                       tolerance=self.nis.tolerance)
        return CameraTracker(tracks, slide=self.slide, nis=nis, heading_offset_deg=self.heading_offset_deg)

    def warm_up(self) -> None:
        """Load the compiled steps of the tracks (:meth:`~footprint_uq.tracking.classes.ClassTracks.warm_up`)."""
        self.tracks.warm_up()

    def step_frame(self, time_s: float, object_ids, classes, xy_m, cov_m2, shared_m=None, *, yaw_rad=None,
                   contact_2d: bool = False, motion_pass: tuple | None = None) -> FrameMotion:
        """One frame of n objects: the tracks' step, the NIS check, the slide term (``contact_2d``) and the motion.

        Parameters
        ----------
        time_s : float
            The frame's time, s (frames in time order: :meth:`~footprint_uq.tracking.table.TrackTable.step`).
        object_ids : sequence of n hashables (None: not tracked)
        classes : list of n class names (None: no class)
        xy_m : (n, 2)          centres in W, m (NaN: no centre)
        cov_m2 : (n, 2, 2)     their whole covariance, m^2 (calibration share included)
        shared_m : (n, 2, r), optional
            Their whitened calibration Jacobians ``B`` (None: unknown, NaN: the tracks then take ``B`` at their
            predicted positions and new tracks are not started).
        yaw_rad : (n,), optional
            3-D boxes' yaw (W, counter-clockwise from +x): the motion's ``yaw_deg``.
        contact_2d : bool
            The centres are 2-D boxes' contact points: add the sliding contact's velocity term.
        motion_pass : (kernel, extra), optional
            Step 4's compiled call (:func:`~footprint_uq.tracking.motion.object_motion`'s ``motion_pass``: its pass
            and more in one call; the service: the messages' codes, ``service/messages/motion.py`` ``codes_pass``).
        """
        if shared_m is None:
            shared_m = np.full((len(object_ids), 2, self._rank), math.nan)
        with self.lock:
            out = self.tracks.step(time_s, object_ids, classes, xy_m, shared_m=shared_m, cov_m2=cov_m2)
            if self.nis is not None:
                self.nis.observe(time_s, out, classes)  # (the NIS of the step's own innovations)
        if contact_2d and self.slide is not None:
            out = self.slide.apply(out, classes)
        # (the motion's age_s the step's own array: this frame's tracks, read by the caller, written by none)
        motion = object_motion(out, heading_offset_deg=self.heading_offset_deg, yaw_rad=yaw_rad,
                               motion_pass=motion_pass, age_s=out.age_s)
        return _new_frame(FrameMotion, (out.track_id, motion, out))
