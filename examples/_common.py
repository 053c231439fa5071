"""Shared by the example scripts: where to write figures and files.

Every example takes ``--out DIR`` (default: ``$FOOTPRINT_UQ_EXAMPLES_OUT`` or ``out/examples``)
and uses matplotlib's Agg backend unless ``MPLBACKEND`` says otherwise.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path


def output_dir(description: str, name: str) -> Path:
    """Parse ``--out`` and return ``<out>/<name>`` (created)."""
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--out", default=os.environ.get("FOOTPRINT_UQ_EXAMPLES_OUT", "out/examples"),
                    help="output folder (default: $FOOTPRINT_UQ_EXAMPLES_OUT or out/examples)")
    args = ap.parse_args()
    out = Path(args.out) / name
    out.mkdir(parents=True, exist_ok=True)
    os.environ.setdefault("MPLBACKEND", "Agg")
    return out
