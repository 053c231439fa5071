"""Edge service: detections in, positions with uncertainty and V2X messages out, frame by frame.

* :class:`Service` -- the per-frame API for embedding (``process_frame``; ``process_frame_json`` gives the
  record as JSON text, a :class:`FrameOutput`, what the transports send);
* :mod:`~footprint_uq.service.runner` -- the long-running service (stdin or MQTT in, stdout or
  MQTT out, drop policy, metrics, SIGTERM drain) behind ``footprint-uq serve``;
* :mod:`~footprint_uq.service.messages` -- the ETSI CPM (JSON and UPER) and SAE J3224 SDSM.

See ``docs/service.md``.
"""

from .core import FrameOutput, Service, error_record
from .runner import tcp_no_delay

__all__ = ["Service", "FrameOutput", "error_record", "tcp_no_delay"]
