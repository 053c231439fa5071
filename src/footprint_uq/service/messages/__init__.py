"""V2X messages of the edge service: ETSI CPM (JSON + UPER) and SAE J3224 SDSM detected objects (JSON)."""

from .cpm import build_cpm, cpm_to_asn1_value, decode_cpm_uper, encode_cpm_uper, timestamp_its_ms
from .sdsm import build_sdsm

__all__ = ["build_cpm", "encode_cpm_uper", "decode_cpm_uper", "cpm_to_asn1_value", "timestamp_its_ms", "build_sdsm"]
