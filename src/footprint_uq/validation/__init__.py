"""Contact with reality: detections paired with ground truth, and a verdict on the uncertainty.

* :mod:`~footprint_uq.validation.readers` -- labelled data in: KITTI-layout folders (Rope3D), DAIR-V2X-I
  label JSON, TUMTraf OpenLABEL JSON, and generic tables of detection/truth pairs (the probe-vehicle
  workflow).  Every reader yields :class:`~footprint_uq.validation.readers.LabelChunk` objects: per
  object a 2-D box (the detection), a ground-truth point in the camera's world frame, and why a row
  cannot be used (``error``), never dropped silently.
* :mod:`~footprint_uq.validation.pairs` -- the contact function (2-D box -> ground point with its
  covariance and Jacobian) and the pairs builder: residual (truth - prediction), ``dxy_dp``,
  ``cov_object_m2``, calibration group, the arrays the budget fit takes.
* :mod:`~footprint_uq.validation.coverage` -- per-object NEES and ellipse membership; streaming
  accumulation of coverage, bias and the NEES test that accounts for the calibration draw shared by
  every object of one camera.
* :mod:`~footprint_uq.validation.fit` -- the budget fit: REML variance components with the calibration
  error shared by the objects of one group, identifiability (unidentifiable and merged terms), intervals,
  cross-validated coverage, ``budget.yaml`` (docs/budget-fit.md); the job of ``footprint-uq calibrate
  budget`` is :mod:`footprint_uq.viz.budget_fit_run`.

The HTML report and the whole job are :mod:`footprint_uq.viz.validation` and
:mod:`footprint_uq.viz.validation_run`; the command is ``footprint-uq validate`` (docs/validation.md).
"""
