"""The long-running service behind ``footprint-uq serve``: transports, drop policy, metrics, drain.

Inputs: JSON Lines on stdin, or MQTT topics ``<input-prefix>/<camera_id>`` (QoS 1).  Outputs:
JSON Lines on stdout, or MQTT topics ``<output-prefix>/<camera_id>`` (QoS 1), errors on
``<output-prefix>/errors`` and health on ``<output-prefix>/health``.  One worker thread runs
:meth:`footprint_uq.service.Service.process_frame_json` (the record as JSON text, written without
building per-object dicts); the transports only move bytes.

Overload policy (:class:`FrameQueue`): at most **one pending frame per camera**.  With
``newest`` (the default for MQTT) a frame that arrives while its camera's previous frame is
still waiting replaces it and the replaced one is counted in ``frames_dropped``; with ``block``
(the default for stdin) the reader waits, so a pipe pushes back on the detector and nothing is
dropped, and the frames are processed in the order they were read (a recording replays as recorded,
whatever the reader's lead: the CP service never sees two cameras' frames swapped by the queue).
Memory is bounded by the number of cameras, never by the backlog.

Accounting: ``frames_in = frames_out + errors + frames_dropped + pending`` at every health
message; after a drain ``pending`` is 0.

Garbage collection: the objects that exist when the service starts are frozen (``gc.freeze``) and the
young-generation threshold is raised while it runs, so that the cyclic collector does not stall a frame
for 100 ms traversing numpy's, numba's and paho's long-lived objects; per-frame data is acyclic and freed
by reference counting.

Faults: the MQTT client reconnects with exponential back-off (1 s to 16 s), resubscribes on
every connect, and uses a persistent session (``clean_session=False``, fixed client id) so the
broker keeps QoS-1 messages for it while it is away.  SIGTERM / SIGINT (or the end of stdin)
stops reading, processes everything pending, waits for the outputs to be acknowledged and
returns exit status 0.
"""

from __future__ import annotations

import collections
import contextlib
import gc
import io
import multiprocessing as mp
import os
import select
import signal
import socket
import sys
import threading
import time
from urllib.parse import urlparse

import numpy as np
import orjson

from .._notices import set_compile_handler
from ..errors import ConfigError, InputError
from ..integrations.ros2.live import ROSBAG_PREFIX, LiveBag
from ..io import load_camera
from ..io.registry import load_registry
from ..products.warmup import compile_handler
from ..tracking.consistency import DEFAULT_WINDOW_S
from .core import RECORD_ERROR, RECORD_FOOTPRINTS, RECORD_LAYOUTS, FrameOutput, Service, error_record
from .cp_serve import cp_workers, start_cp_service
from .frame_scan import ScannedFrame, scan_frame
from .messages.asn1_cpm import DEFAULT_CDD

__all__ = ["FrameQueue", "Metrics", "serve", "run", "parse_mqtt_url", "POLICIES"]

POLICIES = ("newest", "block")
#: frames pending per camera (a burst of this many frames of one camera is processed, not replaced)
QUEUE_DEPTH = 2
#: the largest frame accepted (bytes of one MQTT payload or stdin line; a 255-object frame is ~60 kB)
MAX_FRAME_BYTES = 4 << 20
#: the most bytes of frames pending in all
MAX_PENDING_BYTES = 256 << 20


def _plain(v):
    return v if v is None or isinstance(v, (str, int, float, bool)) else repr(v)


def _dumps(obj) -> bytes:
    return orjson.dumps(obj)


def _loads(data):
    return orjson.loads(data)


class FrameQueue:
    """Pending frames, at most ``depth`` per key (camera): ``newest`` serves the key waiting longest first,
    ``block`` the frames in the order they were put (see the module doc).

    Parameters
    ----------
    policy : {"newest", "block"}
    max_keys : int
        Most distinct keys pending at once (a bound on memory when ids are garbage): a frame
        of a new key beyond it is dropped (``newest``) or waits (``block``).
    depth : int
        Most frames pending per key: with ``newest`` a frame arriving when its key already has ``depth``
        frames pending replaces the oldest of them (counted in :attr:`dropped`); with ``block`` it waits.
        ``newest`` serves the key waiting longest first (cameras in turn, fair under overload); ``block`` serves
        every frame in the order it was put (a replay is deterministic).
    max_bytes : int
        Most bytes pending in all (the ``nbytes`` given to :meth:`put`): beyond it a frame is dropped
        (``newest``, counted) or waits (``block``), so memory stays bounded whatever the frames' sizes.
    """

    def __init__(self, policy: str = "newest", max_keys: int = 4096, depth: int = 1, max_bytes: int = 1 << 62):
        if policy not in POLICIES:
            raise InputError("policy", policy, f"one of {POLICIES}")
        if int(depth) < 1:
            raise InputError("depth", depth, "an integer >= 1 (frames pending per camera)")
        self.policy = policy
        self.max_keys = int(max_keys)
        self.depth = int(depth)
        self.max_bytes = int(max_bytes)
        self._items: collections.OrderedDict = collections.OrderedDict()  # key -> deque of (item, nbytes)
        self._cv = threading.Condition()
        self._closed = False
        self._n = 0
        self._seq = 0  # the order of the puts (``block`` serves by it)
        self.bytes = 0
        self.dropped = 0

    def _full(self, key, nbytes: int) -> bool:
        dq = self._items.get(key)
        return ((dq is not None and len(dq) >= self.depth) or (dq is None and len(self._items) >= self.max_keys)
                or (self._n > 0 and self.bytes + nbytes > self.max_bytes))

    def put(self, key, item, nbytes: int = 0) -> bool:
        """Queue ``item`` for ``key``; False if it was dropped (key or byte limit) or the queue is closed."""
        with self._cv:
            if self.policy == "block":
                while not self._closed and self._full(key, nbytes):
                    self._cv.wait(0.1)
            if self._closed:
                return False
            dq = self._items.get(key)
            if dq is not None and len(dq) >= self.depth:  # newest: the oldest pending frame of the key goes
                _, nb, _ = dq.popleft()
                self._n -= 1
                self.bytes -= nb
                self.dropped += 1
            if (dq is None and len(self._items) >= self.max_keys) or (self._n > 0 and
                                                                      self.bytes + nbytes > self.max_bytes):
                self.dropped += 1
                return False
            if dq is None:
                dq = self._items[key] = collections.deque()  # keeps its place in line: cameras are served fairly
            dq.append((item, nbytes, self._seq))
            self._seq += 1
            self._n += 1
            self.bytes += nbytes
            self._cv.notify_all()
            return True

    def get(self, timeout: float | None = None):
        """``newest``: the oldest pending item of the key waiting longest; ``block``: the item put first (None after
        ``timeout`` s, or when closed and empty); a key's frames come out in the order they were put."""
        with self._cv:
            end = None if timeout is None else time.monotonic() + timeout
            while not self._items:
                if self._closed:
                    return None
                remaining = None if end is None else end - time.monotonic()
                if remaining is not None and remaining <= 0:
                    return None
                self._cv.wait(remaining)
            if self.policy == "block":
                key = min(self._items, key=lambda k: self._items[k][0][2])
                dq = self._items[key]
            else:
                key, dq = next(iter(self._items.items()))
            item, nb, _ = dq.popleft()
            if dq:
                self._items.move_to_end(key)  # its next frame waits behind the other cameras' ones
            else:
                del self._items[key]
            self._n -= 1
            self.bytes -= nb
            self._cv.notify_all()
            return item

    def close(self) -> None:
        """No more puts; :meth:`get` drains what is pending, then returns None."""
        with self._cv:
            self._closed = True
            self._cv.notify_all()

    def __len__(self) -> int:
        with self._cv:
            return self._n


class Metrics:
    """Counters and latencies of the service (thread-safe); :meth:`snapshot` is the health message."""

    def __init__(self):
        self._lock = threading.Lock()
        self.t_start = time.monotonic()
        self.frames_in = 0
        self.frames_out = 0
        self.errors = 0
        self.publish_failed = 0
        #: bad detections reported inside footprints records (their ``detection_errors``; the frames went on)
        self.detection_errors = 0
        self._lat_ms: list[float] = []
        self._proc_us: list[float] = []
        self._lat_total = collections.deque(maxlen=100_000)

    def received(self, n: int = 1) -> None:
        with self._lock:
            self.frames_in += n

    def done(self, record: dict, latency_s: float) -> None:
        self.done_output(record.get("type"), record["processing_us"]["total"] if record.get("type") ==
                         RECORD_FOOTPRINTS else None, latency_s, len(record.get("detection_errors") or ()))

    def done_output(self, kind, processing_us: float | None, latency_s: float, detection_errors: int = 0) -> None:
        """One output written: a footprints record (with its total processing time and its number of bad
        detections) or an error record."""
        with self._lock:
            if kind == RECORD_FOOTPRINTS:
                self.frames_out += 1
                self.detection_errors += detection_errors
                self._proc_us.append(processing_us)
            else:
                self.errors += 1
            self._lat_ms.append(1e3 * latency_s)
            self._lat_total.append(1e3 * latency_s)

    def snapshot(self, dropped: int, pending: int) -> dict:
        """Totals since the start and p50/p99 latency (receipt -> output written) over the last interval."""
        with self._lock:
            lat, self._lat_ms = self._lat_ms, []
            proc, self._proc_us = self._proc_us, []
            rec = {"type": "health", "time_s": time.time(), "uptime_s": round(time.monotonic() - self.t_start, 3),
                   "frames_in": self.frames_in, "frames_out": self.frames_out, "frames_dropped": dropped,
                   "errors": self.errors, "pending": pending, "publish_failed": self.publish_failed,
                   "detection_errors": self.detection_errors, "interval_frames": len(lat)}
        q = np.percentile(lat, [50, 99]).tolist() if lat else [None, None]
        p = np.percentile(proc, [50, 99]).tolist() if proc else [None, None]
        rec.update(latency_ms_p50=q[0], latency_ms_p99=q[1], processing_us_p50=p[0], processing_us_p99=p[1])
        return rec

    def latency_total_ms(self) -> list[float]:
        with self._lock:
            return list(self._lat_total)


def _check_transport(input, mqtt, output) -> None:
    if input not in ("-", None):
        raise InputError("--input", input, "'-' (stdin); use --mqtt for MQTT input")
    if output not in ("-", "mqtt") and not (isinstance(output, str) and output.startswith(ROSBAG_PREFIX)
                                            and len(output) > len(ROSBAG_PREFIX)):
        raise InputError("--output", output, "'-' (stdout), 'mqtt' or 'rosbag:PATH' (a .mcap file or a bag folder)")
    if (input is None or output == "mqtt") and not mqtt:
        raise InputError("--mqtt", None, "mqtt://HOST:PORT for MQTT input or output")
    if mqtt:
        parse_mqtt_url(mqtt)


def _log(text: str) -> None:
    """One line on stderr (the operator's log; the records go to stdout or MQTT)."""
    print(f"footprint-uq serve: {text}", file=sys.stderr, flush=True)


def parse_mqtt_url(url: str) -> tuple[str, int]:
    """``mqtt://HOST:PORT`` -> (host, port) (port 1883 by default)."""
    u = urlparse(url)
    if u.scheme != "mqtt" or not u.hostname:
        raise InputError("--mqtt", url, "mqtt://HOST:PORT")
    try:
        port = u.port or 1883
    except ValueError:
        raise InputError("--mqtt", url, "mqtt://HOST:PORT with a numeric port") from None
    return u.hostname, port


# -- sinks -------------------------------------------------------------------------------------------
class _StdoutSink:
    """JSON Lines on a binary stream; when its reader goes away (broken pipe) it calls ``on_broken`` and
    drops what follows (there is nobody left to deliver to)."""

    def __init__(self, stream, on_broken):
        self._out = stream
        self._lock = threading.Lock()
        self._broken = False
        self._on_broken = on_broken

    def write(self, record: dict) -> None:
        self.write_json(record.get("type"), record.get("camera_id"), _dumps(record))

    def write_json(self, kind, camera_id, data: bytes) -> None:
        """One record already written as JSON text (:meth:`Service.process_frame_json`)."""
        data += b"\n"
        with self._lock:
            if self._broken:
                return
            try:
                self._out.write(data)
                self._out.flush()
            except BrokenPipeError:
                self._broken = True
                self._on_broken()

    def close(self, timeout_s: float) -> None:
        with self._lock:
            if not self._broken:
                try:
                    self._out.flush()
                except BrokenPipeError:
                    self._broken = True


class _BagSink:
    """``--output rosbag:PATH``: footprints records into the bag (:class:`~footprint_uq.integrations.ros2.live.
    LiveBag`), error and health records on to ``rest`` (stdout); the bag is put in place at :meth:`close`."""

    def __init__(self, bag: LiveBag, rest: _StdoutSink):
        self._bag = bag
        self._rest = rest

    def write(self, record: dict) -> None:
        self._rest.write(record)

    def write_json(self, kind, camera_id, data: bytes) -> None:
        if kind == RECORD_FOOTPRINTS:
            self._bag.write_record(data)
        else:
            self._rest.write_json(kind, camera_id, data)

    def close(self, timeout_s: float) -> None:
        try:
            info = self._bag.close()
            _log(f"bag {info['path']}: {info['frames']} frames, {info['objects']} objects"
                 + "".join(f", {n} objects not in it ({why})" for why, n in info["objects_not_in_bag"].items()))
        finally:
            self._rest.close(timeout_s)


def _bag_sink(service: Service, output: str, rest: _StdoutSink) -> _BagSink:
    grounds = {cid: float(setup.processor.camera.ground_z_m) for cid, setup in service.cameras.items()}
    return _BagSink(LiveBag(output[len(ROSBAG_PREFIX):], ground_z_m=grounds), rest)


class _MqttSink:
    def __init__(self, client, prefix: str, metrics: Metrics):
        self._c = client
        self._prefix = prefix
        self._metrics = metrics
        self._last = None

    def write(self, record: dict) -> None:
        self.write_json(record.get("type"), record.get("camera_id"), _dumps(record))

    def write_json(self, kind, camera_id, data: bytes) -> None:
        """One record already written as JSON text (:meth:`Service.process_frame_json`)."""
        if kind == RECORD_FOOTPRINTS:
            topic = f"{self._prefix}/{camera_id if camera_id is not None else 'camera'}"
        elif kind == RECORD_ERROR:
            topic = f"{self._prefix}/errors"
        else:
            topic = f"{self._prefix}/health"
        info = self._c.publish(topic, data, qos=1)
        if info.rc != 0:  # queue full (broker away for long): counted, never unbounded
            with self._metrics._lock:
                self._metrics.publish_failed += 1
        else:
            self._last = info

    def write_cpm(self, camera_id, cpm_uper: bytes) -> None:
        """A compact record's CPM, UPER-encoded, as bytes on ``<prefix>/<camera_id>/cpm`` (after its record)."""
        self.publish(f"{camera_id if camera_id is not None else 'camera'}/cpm", cpm_uper)

    def publish(self, subtopic: str, data: bytes) -> None:
        """``data`` on ``<prefix>/<subtopic>`` (QoS 1; a refused publish is counted in ``publish_failed``)."""
        info = self._c.publish(f"{self._prefix}/{subtopic}", data, qos=1)
        if info.rc != 0:
            with self._metrics._lock:
                self._metrics.publish_failed += 1
        else:
            self._last = info

    def close(self, timeout_s: float) -> None:
        end = time.monotonic() + timeout_s
        while self._c.want_write() or (self._last is not None and not self._last.is_published()):
            if time.monotonic() > end:
                break
            time.sleep(0.01)


# -- sources ---------------------------------------------------------------------------------------------
def _stdin_lines(stream, max_bytes: int, stop: threading.Event):
    """Yield ``(line, length)`` of each line of ``stream``; ``line`` is None for a line longer than ``max_bytes``
    (its bytes are skipped, never held).  A real file descriptor is read with ``select`` + ``os.read`` so that a
    stop request ends the reader even while the input is open and idle (and no thread is left holding the
    interpreter's stdin lock at exit)."""
    try:
        fd = stream.fileno()
        select.select([fd], [], [], 0)  # a descriptor select can wait on (not so on every platform)
    except (AttributeError, OSError, ValueError, io.UnsupportedOperation):
        fd = None
    if fd is None:
        while True:
            line = stream.readline(max_bytes + 1)
            if not line:
                return
            n = len(line)
            if n > max_bytes and not line.endswith(b"\n"):
                while line and not line.endswith(b"\n"):
                    line = stream.readline(1 << 16)
                    n += len(line)
                yield None, n
            else:
                yield line, n
    buf, skipped = bytearray(), -1  # skipped >= 0: inside an over-long line (its length so far)
    while not stop.is_set():
        if not select.select([fd], [], [], 0.1)[0]:
            continue
        chunk = os.read(fd, 1 << 16)
        if not chunk:
            break
        start = 0
        while (end := chunk.find(b"\n", start)) >= 0:
            if skipped >= 0 or len(buf) + end - start + 1 > max_bytes:
                yield None, max(skipped, 0) + len(buf) + end - start + 1
                skipped = -1
                buf.clear()
            else:
                buf += chunk[start:end + 1]
                yield bytes(buf), len(buf)
                buf.clear()
            start = end + 1
        rest = len(chunk) - start
        if skipped >= 0:
            skipped += rest
        elif len(buf) + rest > max_bytes:
            skipped, buf = len(buf) + rest, bytearray()
        else:
            buf += chunk[start:]
    if skipped >= 0:
        yield None, skipped
    elif buf and not stop.is_set():
        yield bytes(buf), len(buf)


def _stdin_reader(stream, queue: FrameQueue, sink, metrics: Metrics, stop: threading.Event,
                  max_frame_bytes: int = 1 << 62) -> None:
    lineno = 0
    last_key = None  # an unreadable line waits behind the frames of the camera of the line before it
    for line, nbytes in _stdin_lines(stream, max_frame_bytes, stop):
        lineno += 1
        if stop.is_set():
            break
        if line is not None and not line.strip():
            continue
        t = time.monotonic()
        metrics.received()
        src = f"stdin line {lineno}"
        if line is None:
            rec = error_record(f"frame of {nbytes} bytes is larger than the limit of {max_frame_bytes} bytes "
                               "(--max-frame-bytes)", source=src)
            _queue_error(queue, last_key, rec, src, t, sink, metrics)
            continue
        frame = scan_frame(line)  # the common layout straight into columns (frame_scan); else parsed in full
        if frame is not None:
            key = frame.camera_id
        else:
            try:
                frame = _loads(line)
            except ValueError as e:
                _queue_error(queue, last_key, error_record(f"invalid JSON: {e}", source=src), src, t, sink, metrics)
                continue
            key = frame.get("camera_id") if isinstance(frame, dict) else None
        key = last_key = key if isinstance(key, str) else repr(key)
        if not queue.put(key, (frame, src, t, None), nbytes):
            rec = error_record("service stopping, too many cameras or bytes pending", source=src,
                               camera_id=key if isinstance(frame, dict) and isinstance(frame.get("camera_id"), str)
                               else None)
            sink.write(rec)
            metrics.done(rec, time.monotonic() - t)
    queue.close()


#: the fourth element of a queued item whose first element is a finished FrameOutput (an error found on receipt)
_READY = object()


def _queue_error(queue: FrameQueue, key, rec: dict, src: str, t: float, sink, metrics: Metrics) -> None:
    """An error record found on receipt goes through the queue, behind the frames received before it (records
    leave in input order); written at once only if the queue refuses it."""
    out = FrameOutput(_dumps(rec), RECORD_ERROR, rec.get("camera_id"), None, rec)
    if not queue.put(key, (out, src, t, _READY), len(out.data)):
        sink.write(rec)
        metrics.done(rec, time.monotonic() - t)


def _topic_level_error(camera_id) -> str | None:
    """Why ``camera_id`` cannot be the last level of an MQTT topic (None if it can): MQTT 3.1.1 clause 4.7 --
    no wildcard ``#`` / ``+`` in a topic name, no NUL, not empty, at most 65535 bytes in all."""
    if camera_id is None:
        return None
    if not isinstance(camera_id, str) or not camera_id or "#" in camera_id or "+" in camera_id or "\0" in camera_id:
        return (f"camera_id {camera_id!r} cannot name an MQTT topic (MQTT 3.1.1 clause 4.7: no '#', '+' or NUL, "
                "not empty)")
    if len(camera_id.encode("utf-8", "surrogatepass")) > 60000:
        return f"camera_id of {len(camera_id)} characters is too long for an MQTT topic"
    return None


def _mqtt_frame(payload: bytes, cam: str, src: str):
    """(frame, None) from an MQTT payload of topic ``<prefix>/<cam>``, or (None, the error output).  A payload in
    the common layout naming the topic's camera is read straight into columns (:func:`.frame_scan.scan_frame`);
    any other is parsed in full."""
    scanned = scan_frame(payload)
    if scanned is not None and scanned.camera_id == cam:
        return scanned, None
    try:
        frame = _loads(payload)
    except ValueError as e:
        rec = error_record(f"invalid JSON: {e}", camera_id=cam, source=src)
        return None, FrameOutput(_dumps(rec), RECORD_ERROR, cam, None, rec)
    if isinstance(frame, dict):
        if frame.get("camera_id") is None:  # absent or null: the topic names the camera
            frame["camera_id"] = cam
        elif frame["camera_id"] != cam:
            topic = src.removeprefix("mqtt ")
            rec = error_record(f"camera_id {frame['camera_id']!r} does not match the topic {topic!r}",
                               field="camera_id", camera_id=cam, frame=frame.get("frame"), source=src)
            return None, FrameOutput(_dumps(rec), RECORD_ERROR, cam, None, rec)
    return frame, None


def _mqtt_client(host: str, port: int, client_id: str):
    try:
        import paho.mqtt.client as mqtt
    except ImportError:
        raise ConfigError("--mqtt", "paho-mqtt not installed", "pip install 'footprint-uq[service]'") from None
    c = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=client_id, clean_session=False)
    c.reconnect_delay_set(min_delay=1, max_delay=16)
    c.max_queued_messages_set(10_000)
    c.max_inflight_messages_set(100)
    c.on_socket_open = tcp_no_delay
    return c


def tcp_no_delay(client, userdata, sock) -> None:
    """A paho-mqtt ``on_socket_open`` callback: Nagle's algorithm off on the broker connection
    (``TCP_NODELAY``).  A record's last TCP segment, a PUBACK, would otherwise wait for the peer's ACK of
    the previous one (milliseconds at the p99 of the load benchmark; the broker's side: Mosquitto's
    ``set_tcp_nodelay true``, docs/service.md).  Detectors and receivers: ``client.on_socket_open =
    tcp_no_delay``."""
    try:
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    except (OSError, AttributeError):  # not a TCP socket (a websocket wrapper, a Unix socket)
        pass
    quick_ack(sock)


_QUICKACK = getattr(socket, "TCP_QUICKACK", None)  # Linux only


def quick_ack(sock) -> None:
    """ACK what the broker sent at once instead of delaying the ACK (``TCP_QUICKACK``, Linux; the kernel may
    leave quick-ack mode again, so the service sets it after every message it receives).

    Why: a broker with Nagle's algorithm on (Mosquitto's default, ``set_tcp_nodelay false``) holds the next
    frame for this client while its last small segment to it -- the PUBACK of the service's previous record --
    is unacknowledged, and a delayed ACK waits up to 40 ms: at 50 Hz the frames then arrived in pairs
    (measured: gaps 44 ms / 0.1 ms, `bench/bench_service_50hz.py`) and ``--overload newest`` replaced half of
    them.  Costs one system call per frame."""
    if _QUICKACK is None or sock is None:
        return
    try:
        sock.setsockopt(socket.IPPROTO_TCP, _QUICKACK, 1)
    except (OSError, AttributeError):
        pass


# -- the service --------------------------------------------------------------------------------------------
def serve(service: Service, *, input: str | None = "-", mqtt: str | None = None, output: str = "-",
          input_prefix: str = "detections", output_prefix: str = "footprints", policy: str | None = None,
          health_interval_s: float = 1.0, client_id: str | None = None, cameras: list[str] | None = None,
          worker: str | None = None, stdin=None, stdout=None,
          stop: threading.Event | None = None, install_signals: bool = True, drain_timeout_s: float = 10.0,
          queue_depth: int = QUEUE_DEPTH, max_frame_bytes: int = MAX_FRAME_BYTES,
          max_pending_bytes: int = MAX_PENDING_BYTES, cp=None) -> int:
    """Run the service until SIGTERM/SIGINT, ``stop`` or the end of stdin; return the exit status (0).

    Parameters
    ----------
    service : Service
    input : "-" (stdin) or None (MQTT, needs ``mqtt``)
    mqtt : "mqtt://HOST:PORT", optional
        Broker for MQTT input (``input=None``) and/or output (``output="mqtt"``).
    output : "-" (stdout JSON Lines) or "mqtt"
    policy : {"newest", "block"}, optional
        Overload policy (default: ``block`` for stdin, ``newest`` for MQTT).
    health_interval_s : float
        Period of the health/metrics message (0: none).
    cameras : list of str, optional
        MQTT input: subscribe to these cameras' topics only (default: ``<input_prefix>/+``).
    worker : str, optional
        Label added to the health records (``"1/2"``: worker 1 of 2, see :func:`run`).
    queue_depth : int
        Frames pending per camera (:class:`FrameQueue` ``depth``): a burst of up to this many frames of one
        camera is processed, not replaced.
    max_frame_bytes, max_pending_bytes : int
        A frame (MQTT payload, stdin line) larger than ``max_frame_bytes`` is refused with an error record
        before it is queued (a stdin line is skipped without being held); the frames pending in all hold at
        most ``max_pending_bytes`` (beyond: dropped and counted with ``newest``, waiting with ``block``).
    cp : CpServe, optional
        The roadside unit's CP service (``--cp-service``, :mod:`.cp_serve`): its outputs follow each frame's record,
        its counts go into the health record (``cp_service``).
    """
    _check_transport(input, mqtt, output)
    policy = policy or ("block" if input == "-" else "newest")
    stop = stop or threading.Event()
    metrics = Metrics()
    queue = FrameQueue(policy, depth=queue_depth, max_bytes=max_pending_bytes)
    client = topics = None
    if mqtt:
        host, port = parse_mqtt_url(mqtt)
        client = _mqtt_client(host, port, client_id or f"footprint-uq-serve-{os.getpid()}")
        topics = [f"{input_prefix}/+"] if cameras is None else [f"{input_prefix}/{c}" for c in cameras]
    out_stream = stdout if stdout is not None else sys.stdout.buffer
    sink = _MqttSink(client, output_prefix, metrics) if output == "mqtt" else _StdoutSink(out_stream, stop.set)
    if output.startswith(ROSBAG_PREFIX):
        sink = _bag_sink(service, output, sink)
    if cp is not None:
        sink = cp.wrap(sink, mqtt=output == "mqtt")
    if client is not None:
        _mqtt_input(client, topics if input is None else None, input_prefix, queue, sink, metrics, stop,
                    max_frame_bytes)
        client.connect_async(host, port, keepalive=5)
        client.loop_start()

    old_handlers = _stop_on_signals(stop) if install_signals else {}

    def snapshot() -> dict:
        rec = metrics.snapshot(queue.dropped, len(queue))
        if worker is not None:
            rec["worker"] = worker
        motion, lines = service.motion_health() if service.tracks else (None, [])
        if motion is not None:
            rec["motion_consistency"] = motion  # (docs/motion-fit.md, "Consistency on line")
        for line in lines:
            _log(line)
        if cp is not None:
            rec["cp_service"] = cp.counts()
        return rec

    with _steady_runtime():
        threads = _start_threads(service, queue, sink, metrics, output, stop, snapshot,
                                 stdin=(stdin if stdin is not None else sys.stdin.buffer) if input == "-" else None,
                                 max_frame_bytes=max_frame_bytes, health_interval_s=health_interval_s)
        _log(f"ready: input {'stdin' if input == '-' else mqtt + ' ' + ', '.join(topics)}, output "
             f"{'stdout' if output == '-' else output if output != 'mqtt' else mqtt + ' ' + output_prefix + '/...'}"
             f", overload policy {policy}"
             + (f", worker {worker}" if worker else ""))
        try:
            # run until a stop request or the end of the input (stdin: the reader closes the queue)
            while not stop.wait(0.05):
                if input == "-" and not threads[0].is_alive():
                    break
        finally:
            _shutdown(stop, client, topics if input is None else None, queue, threads, input == "-", sink, snapshot,
                      drain_timeout_s)
            for sig, h in old_handlers.items():
                signal.signal(sig, h)
            _log(f"stopped: frames in {metrics.frames_in}, out {metrics.frames_out}, dropped {queue.dropped}, "
                 f"errors {metrics.errors}")
    return 0


def _stop_on_signals(stop: threading.Event) -> dict:
    """SIGTERM / SIGINT set ``stop`` (in the main thread only); returns the handlers they replaced."""
    old = {}
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGTERM, signal.SIGINT):
            old[sig] = signal.signal(sig, lambda s, f: stop.set())
    return old


def _start_threads(service: Service, queue: FrameQueue, sink, metrics: Metrics, output: str, stop: threading.Event,
                   snapshot, *, stdin, max_frame_bytes: int, health_interval_s: float) -> list[threading.Thread]:
    """Start the service's threads: the worker (always first), the stdin reader (``stdin`` a stream) and the health
    thread (``health_interval_s`` > 0)."""
    threads = [threading.Thread(target=_work, args=(service, queue, sink, metrics, output, stop),
                                name="footprint-uq-worker", daemon=True)]
    if stdin is not None:
        threads.append(threading.Thread(target=_stdin_reader, args=(stdin, queue, sink, metrics, stop, max_frame_bytes),
                                        name="footprint-uq-stdin", daemon=True))
    if health_interval_s and health_interval_s > 0:
        threads.append(threading.Thread(target=_health, args=(sink, snapshot, stop, health_interval_s),
                                        name="footprint-uq-health", daemon=True))
    for t in threads:
        t.start()
    return threads


def _mqtt_input(client, topics: list | None, input_prefix: str, queue: FrameQueue, sink, metrics: Metrics,
                stop: threading.Event, max_frame_bytes: int) -> None:
    """The MQTT client's callbacks: subscribe to ``topics`` on (re)connection (None: MQTT is the output only) and
    queue each payload as it comes (refused with an error record beyond ``max_frame_bytes``)."""

    def on_connect(c, userdata, flags, reason_code, properties):
        if not reason_code.is_failure and topics is not None and not stop.is_set():
            c.subscribe([(t, 1) for t in topics])

    def on_message(c, userdata, msg):
        # the network thread only queues the payload: the worker parses it (a frame replaced by a newer one
        # of its camera is never parsed, and the network thread is free for the next packet)
        t = time.monotonic()
        quick_ack(c.socket())
        metrics.received()
        cam = msg.topic[len(input_prefix) + 1:]
        src = f"mqtt {msg.topic}"
        if len(msg.payload) > max_frame_bytes:  # refused before it is queued (paho frees it on return)
            rec = error_record(f"frame of {len(msg.payload)} bytes is larger than the limit of {max_frame_bytes} "
                               "bytes (--max-frame-bytes)", camera_id=cam, source=src)
            _queue_error(queue, cam, rec, src, t, sink, metrics)
            return
        if not queue.put(cam, (msg.payload, src, t, cam), len(msg.payload)):
            rec = error_record("service stopping or too many cameras pending", camera_id=cam, source=src)
            sink.write(rec)
            metrics.done(rec, time.monotonic() - t)

    client.on_connect = on_connect
    client.on_message = on_message
    client.on_publish = lambda c, *a: quick_ack(c.socket())  # the PUBACK of a record: ACK it at once


def _frame_output(service: Service, item: tuple, output: str) -> FrameOutput:
    """The output of one queued item ``(frame, source, receipt time, topic camera)``: a ready error record, a
    ``camera_id`` that cannot name an output topic, an MQTT payload (parsed here, checked against its topic) or a
    stdin frame through :meth:`Service.process_frame_json`."""
    frame, src, t, topic_camera = item
    try:
        if topic_camera is _READY:  # an error record found on receipt, in its place in the line
            return frame
        scanned = isinstance(frame, ScannedFrame)  # (a stdin frame read straight into columns)
        if output == "mqtt" and (scanned or isinstance(frame, dict)) and (why := _topic_level_error(
                frame.camera_id if scanned else frame.get("camera_id"))) is not None:
            rec = error_record(why, field="camera_id", camera_id=_plain(frame.camera_id if scanned else
                                                                        frame.get("camera_id")),
                               frame=_plain(frame.frame if scanned else frame.get("frame")), source=src)
            return FrameOutput(_dumps(rec), RECORD_ERROR, None, None, rec)
        if topic_camera is not None:  # an MQTT payload: parsed here, its camera_id checked against the topic
            frame, out = _mqtt_frame(frame, topic_camera, src)
            if out is not None:
                return out
        return service.process_frame_json(frame, source=src)
    except Exception as e:  # noqa: BLE001 - a bug met by one frame is reported in its record, not fatal
        rec = error_record(f"internal error (please report): {type(e).__name__}: {e}", source=src,
                           camera_id=frame.get("camera_id") if isinstance(frame, dict) else None)
        return FrameOutput(_dumps(rec), RECORD_ERROR, rec["camera_id"], None, rec)


def _work(service: Service, queue: FrameQueue, sink, metrics: Metrics, output: str, stop: threading.Event) -> None:
    """The worker thread: each queued frame in turn to its record, written to the sink, until the queue is closed
    and drained (or the sink's reader has gone)."""
    while True:
        item = queue.get(timeout=0.1)
        if item is None:
            if queue._closed:
                return
            continue
        out = _frame_output(service, item, output)
        try:
            sink.write_json(out.type, out.camera_id, out.data)
            if out.cpm_uper is not None:  # a compact record's CPM (MQTT output only: run() checks)
                sink.write_cpm(out.camera_id, out.cpm_uper)
        except BrokenPipeError:  # stdout closed by the reader: nothing more can be delivered
            stop.set()
            return
        except Exception as e:  # noqa: BLE001 - e.g. the MQTT client refusing a publish: counted, never fatal
            with metrics._lock:
                metrics.publish_failed += 1
            _log(f"output failed ({type(e).__name__}: {e}); counted in publish_failed")
        metrics.done_output(out.type, out.processing_us, time.monotonic() - item[2], out.n_detection_errors)


def _health(sink, snapshot, stop: threading.Event, interval_s: float) -> None:
    """The health thread: ``snapshot()`` written every ``interval_s`` until the stop request."""
    while not stop.wait(interval_s):
        try:
            sink.write(snapshot())
        except BrokenPipeError:
            stop.set()


@contextlib.contextmanager
def _steady_runtime():
    """The interpreter set for steady per-frame latency while the service runs; restored on exit.

    The cyclic garbage collector would otherwise traverse the ~10^5 long-lived objects of numpy, numba, pyproj
    and paho every few frames (a frame allocates thousands of short-lived dicts and lists, all freed by
    reference counting): measured 100+ ms stalls at the 99th percentile.  Freeze what exists now and collect the
    young generation less often.  The GIL's switch interval 0.5 ms: the network thread gets the GIL within
    0.5 ms of a packet (default 5 ms).
    """
    old_gc = gc.get_threshold()
    gc.collect()
    gc.freeze()
    gc.set_threshold(50_000, 20, 100)
    old_switch = sys.getswitchinterval()
    sys.setswitchinterval(0.0005)
    try:
        yield
    finally:
        gc.set_threshold(*old_gc)
        gc.unfreeze()
        sys.setswitchinterval(old_switch)


def _shutdown(stop: threading.Event, client, topics: list | None, queue: FrameQueue, threads: list,
              stdin_input: bool, sink, snapshot, drain_timeout_s: float) -> None:
    """Stop taking frames in, drain the queue through the worker, write the last health record, close the output
    and the MQTT client."""
    stop.set()
    if client is not None and topics is not None:
        client.unsubscribe(topics)
        time.sleep(0.2)  # messages already on the way are still taken in
    queue.close()
    threads[0].join(drain_timeout_s)
    if stdin_input:
        threads[1].join(1.0)  # the stdin reader sees the stop within 0.1 s (select), even on an idle open pipe
    try:
        sink.write(snapshot())
        sink.close(drain_timeout_s)
    except BrokenPipeError:  # stdout's reader has gone (e.g. `| head`): nothing more to deliver
        pass
    if client is not None:
        client.disconnect()
        client.loop_stop()


def run(*, camera=None, budget=None, registry=None, camera_id: str | None = None, heading_offset_deg: float = 0.0,
        origin_lat_deg: float | None = None, origin_lon_deg: float | None = None, confidence: float = 0.95,
        contact: str = "bottom-centre", allow_outside_image: bool = False, station_id: int | None = None,
        uper_encoder: str = "fast", linearity: bool = False, linear_threshold: float | None = None,
        workers: int | None = 1, cpm_cdd: str = DEFAULT_CDD, v2x_policy: str = "sampled", pose=None,
        **serve_options) -> int:
    """``footprint-uq serve``: build the :class:`Service` from files (a camera file and budget, or a
    registry) and :func:`serve` it; returns the exit status.

    With ``workers`` > 1 (MQTT input and a registry) the registry's cameras are split over that many
    worker processes (camera ``i`` of the sorted ids goes to worker ``i mod workers``), each with its
    own MQTT client (``<client_id>-w<k>``) subscribed to its cameras' topics and its own health
    records (labelled ``"k/N"``); SIGTERM/SIGINT is passed on to them and the exit status is the
    largest of theirs.  ``workers=None`` (the command's default): :func:`default_workers` of the registry's
    cameras with MQTT input, else 1.  ``pose`` (a pose mapping or file) completes an intrinsics-only ``camera``
    file (:func:`footprint_uq.io.load_camera`).
    """
    if (camera is None) == (registry is None):
        raise InputError("--camera/--registry", "both" if camera is not None else "neither",
                         "one camera (--camera with --budget) or many (--registry)")
    _check_transport(serve_options.get("input", "-"), serve_options.get("mqtt"), serve_options.get("output", "-"))
    serve_options["record"] = _record_layout(serve_options.get("record"), serve_options.get("output", "-"))
    cp_options = serve_options.pop("cp_service", None)
    if cp_options is not None:  # the fusion needs every camera in one process (docs/service.md, "Workers")
        workers = cp_workers(workers, registry is not None and serve_options.get("input", "-") is None, _log)
        registry = registry if registry is None or isinstance(registry, dict) else load_registry(registry,
                                                                                                 budget=budget)
    if workers is None:
        workers = 1
        if registry is not None and serve_options.get("input", "-") is None:
            n_cameras = len(registry) if isinstance(registry, dict) else len(load_registry(registry, budget=budget))
            workers = default_workers(n_cameras)
            _log(f"--workers {workers} (the default: min(cores - 1, cameras) = min({usable_cores()} - 1, "
                 f"{n_cameras}))")
    if workers > 1:
        if str(serve_options.get("output", "-")).startswith(ROSBAG_PREFIX):
            raise InputError("--workers", workers, "1 with --output rosbag:PATH (one process records the bag)")
        if registry is None or serve_options.get("input", "-") is not None:
            raise InputError("--workers", workers, "1, unless the input is MQTT (--mqtt without --input) and "
                                                   "the cameras come from a --registry")
        return _run_workers(workers, dict(
            budget=budget, registry=registry, heading_offset_deg=heading_offset_deg, origin_lat_deg=origin_lat_deg,
            origin_lon_deg=origin_lon_deg, confidence=confidence, contact=contact,
            allow_outside_image=allow_outside_image, uper_encoder=uper_encoder, linearity=linearity,
            linear_threshold=linear_threshold, cpm_cdd=cpm_cdd, v2x_policy=v2x_policy, **serve_options))
    # a SIGTERM while the cameras load and the kernels compile (seconds) is a stop request too: nothing was
    # taken in yet, so the drain is empty and the exit status 0
    stop = serve_options.pop("stop", None) or threading.Event()
    old = {}
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGTERM, signal.SIGINT):
            old[sig] = signal.signal(sig, lambda s, f: stop.set())
    _log("starting: loading the cameras and the compiled kernels")
    set_compile_handler(compile_handler(_log))  # a cold cache's notice, said when the kernels are first used
    try:
        cam = None
        if camera is not None:

            if budget is None:
                raise InputError("--budget", None, "an error budget (preset or file) for --camera")
            cam = load_camera(camera, pose=pose)
        service = Service(cam, budget, registry=registry, camera_id=camera_id, heading_offset_deg=heading_offset_deg,
                          origin_lat_deg=origin_lat_deg, origin_lon_deg=origin_lon_deg, confidence=confidence,
                          contact=contact, allow_outside_image=allow_outside_image, station_id=station_id,
                          uper_encoder=uper_encoder, linearity=linearity, linear_threshold=linear_threshold,
                          cpm_cdd=cpm_cdd, v2x_policy=v2x_policy,
                          # the per-camera CPM / SDSM only where the per-camera record is written
                          messages=cp_options is None or cp_options.per_camera_output,
                          tracks=serve_options.pop("tracks", False),
                          class_names=serve_options.pop("class_names", None),
                          unknown_class=serve_options.pop("unknown_class", None), record=serve_options.pop("record"),
                          consistency_window_s=serve_options.pop("consistency_window_s", DEFAULT_WINDOW_S))
        cp = None if cp_options is None else start_cp_service(
            service, cp_options, registry=registry, camera=(camera_id, cam), station_id=station_id,
            cdd=cpm_cdd, heading_offset_deg=heading_offset_deg, origin_lat_deg=origin_lat_deg,
            origin_lon_deg=origin_lon_deg, log=_log)
        return serve(service, stop=stop, cp=cp, **serve_options)
    finally:
        for sig, h in old.items():
            signal.signal(sig, h)


def usable_cores() -> int:
    """The cores this process may run on (its CPU affinity, e.g. under ``taskset``; else the machine's)."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # (not every platform has affinities)
        return os.cpu_count() or 1


def default_workers(n_cameras: int, cores: int | None = None) -> int:
    """``serve``'s default ``--workers`` with MQTT input and a registry: ``min(cores - 1, cameras)``, at least 1 --
    one core left to the broker, paho's network threads and the detector; never more workers than cameras
    (docs/service.md, "Workers")."""
    cores = usable_cores() if cores is None else int(cores)
    return max(1, min(cores - 1, int(n_cameras)))


def _record_layout(record: str | None, output: str) -> str:
    """The record layout of ``serve``: ``compact`` by default with MQTT output (the CPM's bytes on their own topic),
    ``full`` otherwise; ``compact`` needs MQTT output (JSON Lines carry no bytes beside the record)."""
    if record is None:
        return "compact" if output == "mqtt" else "full"
    if record not in RECORD_LAYOUTS:
        raise InputError("--record", record, f"one of {RECORD_LAYOUTS}")
    if record == "compact" and output != "mqtt":
        raise InputError("--record", record, "'full' with --output - (a compact record's CPM goes as bytes on its own "
                                             "MQTT topic), or --output mqtt")
    return record


def _worker_main(options: dict, cameras: list[str], label: str) -> None:  # pragma: no cover - child process

    entries = load_registry(options.pop("registry"), budget=options["budget"])
    sub = {c: entries[c] for c in cameras}
    sys.exit(run(registry=sub, cameras=cameras, worker=label, workers=1, **options))


def _run_workers(n: int, options: dict) -> int:


    ids = sorted(load_registry(options["registry"], budget=options["budget"]))
    if n > len(ids):
        raise InputError("--workers", n, f"at most the number of cameras in the registry ({len(ids)})")
    base = options.pop("client_id", None) or f"footprint-uq-serve-{os.getpid()}"
    ctx = mp.get_context("spawn")
    procs = [ctx.Process(target=_worker_main, name=f"footprint-uq-worker-{k + 1}",
                         args=({**options, "client_id": f"{base}-w{k + 1}"}, ids[k::n], f"{k + 1}/{n}"))
             for k in range(n)]
    stopping = threading.Event()
    old = {}
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGTERM, signal.SIGINT):
            old[sig] = signal.signal(sig, lambda s, f: stopping.set())
    try:
        for p in procs:
            p.start()
        while any(p.is_alive() for p in procs):
            if stopping.wait(0.1):
                for p in procs:
                    if p.is_alive():
                        os.kill(p.pid, signal.SIGTERM)
                for p in procs:
                    p.join()
        # a worker stopped by SIGTERM before its own handler was installed had subscribed to nothing yet
        codes = [0 if p.exitcode == -signal.SIGTERM and stopping.is_set() else p.exitcode for p in procs]
        return next((c if c > 0 else 1 for c in codes if c != 0), 0)
    finally:
        for sig, h in old.items():
            signal.signal(sig, h)
