"""The camera registry: camera id -> camera, error budget and optional heading offset / geodetic origin, read
from a folder of camera files or a CSV / YAML / JSON table (docs/batch.md, "Camera registry").

Used by the fleet batch (:mod:`footprint_uq.batch.fleet`, which re-exports it), the edge service and the
validation commands.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from .._files import read_input_text
from .._parse import load_yaml
from ..errors import ConfigError
from ..uncertainty.budget import load_budget
from .camera_files import load_camera

__all__ = ["RegistryEntry", "load_registry"]


@dataclass
class RegistryEntry:
    """One camera of the fleet: its loaded camera and budget and optional map tie."""

    camera_id: str
    camera: object
    budget: object
    heading_offset_deg: float | None = None
    origin_lat_deg: float | None = None
    origin_lon_deg: float | None = None
    source: str = ""
    #: the camera's ``sensorId`` in the roadside unit's CPMs (0..255; None: the default of ``serve --cp-service``,
    #: its index in the sorted camera ids + 1)
    sensor_id: int | None = None
    #: the sigmas of the camera's clock offset and jitter (s; the CP service's time term, docs/rsu-fusion.md)
    clock_offset_sigma_s: float = 0.0
    clock_jitter_sigma_s: float = 0.0


_REG_KEYS = {"camera_id", "camera", "budget", "heading_offset_deg", "origin_lat_deg", "origin_lon_deg", "sensor_id",
             "clock_offset_sigma_s", "clock_jitter_sigma_s"}
#: the largest ``sensor_id`` (the CPM's ``Identifier1B``)
MAX_SENSOR_ID = 255


def _absent(v) -> bool:
    return v is None or (isinstance(v, float) and np.isnan(v)) or (isinstance(v, str) and not v.strip())


def _sensor_id(v, where: str) -> int | None:
    """An optional ``sensor_id``: an integer 0..255 (a CSV cell's text too); None when absent."""
    if _absent(v):
        return None
    expected = f"an integer sensor id in 0..{MAX_SENSOR_ID} (the CPM's sensorId)"
    if isinstance(v, bool):
        raise ConfigError(f"{where}: sensor_id", v, expected)
    try:
        n = int(v.strip()) if isinstance(v, str) else int(v)
    except (TypeError, ValueError, OverflowError):
        raise ConfigError(f"{where}: sensor_id", v, expected) from None
    if (not isinstance(v, str) and n != v) or not 0 <= n <= MAX_SENSOR_ID:
        raise ConfigError(f"{where}: sensor_id", v, expected)
    return n


def _clock_sigma(rec: dict, key: str, where: str) -> float:
    """An optional clock sigma (s): a finite number >= 0; 0 when absent."""
    v = rec.get(key)
    if _absent(v):
        return 0.0
    try:
        x = float(v) if not isinstance(v, bool) else float("nan")
    except (TypeError, ValueError):
        x = float("nan")
    if not (np.isfinite(x) and x >= 0.0):
        raise ConfigError(f"{where}: {key}", v, "a finite number of seconds >= 0")
    return x


def _entry(rec: dict, where: str, base: Path, default_budget) -> RegistryEntry:

    unknown = set(rec) - _REG_KEYS
    if unknown:
        raise ConfigError(f"{where}: {sorted(unknown)[0]}", rec[sorted(unknown)[0]], f"one of {sorted(_REG_KEYS)}")
    cid = rec.get("camera_id")
    if cid is None or str(cid).strip() == "":
        raise ConfigError(f"{where}: camera_id", cid, "a camera id")
    cam = rec.get("camera")
    if not cam:
        raise ConfigError(f"{where}: camera", cam, "a camera file path")
    cpath = Path(str(cam))
    cpath = cpath if cpath.is_absolute() else base / cpath
    bud = rec.get("budget")
    if bud is None or (isinstance(bud, float) and np.isnan(bud)) or str(bud).strip() == "":
        if default_budget is None:
            raise ConfigError(f"{where}: budget", bud, "a budget (preset or file) in the registry, or --budget")
        budget = load_budget(default_budget)
    else:
        b = str(bud)
        bp = Path(b) if Path(b).is_absolute() else base / b
        budget = load_budget(str(bp) if bp.suffix.lower() in (".yaml", ".yml", ".json") else b)

    def num(key):
        v = rec.get(key)
        if v is None or (isinstance(v, float) and np.isnan(v)) or (isinstance(v, str) and not v.strip()):
            return None
        try:
            return float(v)
        except (TypeError, ValueError):
            raise ConfigError(f"{where}: {key}", v, "a number (degrees)") from None

    return RegistryEntry(str(cid), load_camera(cpath), budget, num("heading_offset_deg"), num("origin_lat_deg"),
                         num("origin_lon_deg"), str(cpath), _sensor_id(rec.get("sensor_id"), where),
                         _clock_sigma(rec, "clock_offset_sigma_s", where),
                         _clock_sigma(rec, "clock_jitter_sigma_s", where))


def load_registry(path, *, budget=None) -> dict[str, RegistryEntry]:
    """Read a camera registry.

    Parameters
    ----------
    path : folder or file
        * a **folder**: every ``<camera_id>.yaml`` / ``.yml`` / ``.json`` camera file in it
          (budget: ``budget``, or a ``<camera_id>.budget.yaml`` next to it);
        * a **table** -- ``.csv`` (header), ``.yaml``/``.json`` (a list of mappings, or a
          mapping with key ``cameras``) -- with keys ``camera_id``, ``camera`` (camera file,
          relative to the registry's folder), optional ``budget`` (preset or file; default
          ``budget``), ``heading_offset_deg``, ``origin_lat_deg``, ``origin_lon_deg``, ``sensor_id`` (0..255,
          unique), ``clock_offset_sigma_s``, ``clock_jitter_sigma_s`` (s, >= 0; default 0).
    budget : preset, path or ErrorBudget, optional
        Default budget.

    Returns
    -------
    dict camera_id -> RegistryEntry
    """
    p = Path(path)
    if not p.exists():
        raise ConfigError("registry", str(path), "an existing folder or file")
    recs: list[tuple[dict, str]] = []
    if p.is_dir():
        base = p
        for f in sorted(p.iterdir()):
            if f.suffix.lower() not in (".yaml", ".yml", ".json") or ".budget." in f.name:
                continue
            rec = {"camera_id": f.stem, "camera": f.name}
            for ext in (".yaml", ".yml", ".json"):
                b = p / f"{f.stem}.budget{ext}"
                if b.exists():
                    rec["budget"] = b.name
            recs.append((rec, str(f)))
    else:
        base = p.parent
        suffix = p.suffix.lower()
        try:
            text = read_input_text(p, "registry", encoding="utf-8-sig")  # a FIFO: a stream
        except (OSError, UnicodeDecodeError) as e:
            raise ConfigError("registry", str(p), f"a readable UTF-8 text file ({type(e).__name__}: {e})") from None
        if "\x00" in text:
            raise ConfigError("registry", str(p), "a text file (it holds NUL bytes)")
        if suffix == ".csv":

            try:
                recs = [({k: v for k, v in r.items() if v != ""}, f"{p}: line {i + 2}")
                        for i, r in enumerate(csv.DictReader(io.StringIO(text, newline=""), strict=True))]
            except csv.Error as e:
                raise ConfigError("registry", str(p), f"a valid CSV table ({e})") from None
            for rec, where in recs:
                if None in rec or any(v is None for v in rec.values()):
                    raise ConfigError(where, "wrong number of fields", "as many fields as the header")
        elif suffix in (".yaml", ".yml", ".json"):

            try:
                data = load_yaml(text, str(p))
            except (yaml.YAMLError, ValueError, RecursionError) as e:
                first = (str(e).strip().splitlines() or [type(e).__name__])[0]
                raise ConfigError("registry", str(p), f"a valid YAML/JSON registry ({first})") from None
            if isinstance(data, dict) and "cameras" in data:
                data = data["cameras"]
            if not isinstance(data, list) or not all(isinstance(r, dict) for r in data):
                raise ConfigError(f"{p}", type(data).__name__, "a list of camera entries (or a mapping 'cameras:')")
            recs = [(r, f"{p}: cameras[{i}]") for i, r in enumerate(data)]
        else:
            raise ConfigError("registry", str(p), "a folder, or a .csv/.yaml/.json registry table")
    out: dict[str, RegistryEntry] = {}
    for rec, where in recs:
        e = _entry(rec, where, base, budget)
        if e.camera_id in out:
            raise ConfigError(f"{where}: camera_id", e.camera_id, "unique camera ids")
        if e.sensor_id is not None and any(o.sensor_id == e.sensor_id for o in out.values()):
            raise ConfigError(f"{where}: sensor_id", e.sensor_id, "a sensor id no other camera of the registry has")
        out[e.camera_id] = e
    if not out:
        raise ConfigError("registry", str(path), "at least one camera")
    return out
