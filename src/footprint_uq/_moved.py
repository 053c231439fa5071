"""Old module paths of footprint-uq 0.1 (before the package layout of the redesign), kept importable.

``import footprint_uq.kernels`` (or ``from footprint_uq.maps import uncertainty_map``) still works:
the old name is an alias of the module at its new place (the same module object, so monkeypatching
either name patches both), with a :class:`DeprecationWarning` naming the new path.  New code uses
the new paths; ``tests/test_architecture.py`` checks that the package itself never imports an old one.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
import warnings

__all__ = ["MOVED", "install"]

#: old module name -> new module name (both relative to ``footprint_uq``).  ``cli_core`` has no alias:
#: it was split into one module per command (cli/locate, map, presets, demo) and its logic moved to
#: the library (products.locate, viz.map_report, uncertainty.preset_tables, viz.demo).
MOVED = {
    "kernels": "products.covariance",
    "footprint_kernels": "fast.footprint_kernels",
    "budget": "uncertainty.budget",
    "presets": "uncertainty.presets",
    "propagation": "uncertainty.propagation",
    "ellipse": "uncertainty.ellipse",
    "ground": "cameras.ground",
    "maps": "products.maps",
    "footprints": "products.footprints",
    "v2x": "products.v2x",
    "geo": "products.geo",
    "fusion": "products.fusion",
    "fusion_io": "batch.fusion_files",
    "carla_bridge": "integrations.carla.bridge",
    "cli_calibrate": "cli.calibrate",
    "cli_extrinsics": "cli.calibrate_extrinsics",
    "cli_gcp": "cli.calibrate_gcp",
    "cli_carla": "cli.carla",
    "cli_case_study": "cli.case_study",
    "cli_convert": "cli.convert",
    "cli_fuse": "cli.fuse",
    "cli_objects": "cli.objects",
    "cli_serve": "cli.serve",
}


class _AliasLoader(importlib.abc.Loader):
    def __init__(self, new: str):
        self.new = new

    def create_module(self, spec):
        module = importlib.import_module(self.new)
        self._spec, self._loader = module.__spec__, getattr(module, "__loader__", None)
        return module

    def exec_module(self, module):  # already executed under its new name: keep its own spec and loader
        module.__spec__, module.__loader__ = self._spec, self._loader


class _MovedFinder(importlib.abc.MetaPathFinder):
    def __init__(self, package: str):
        self.package = package

    def find_spec(self, fullname, path=None, target=None):
        prefix = self.package + "."
        if not fullname.startswith(prefix) or fullname[len(prefix):] not in MOVED:
            return None
        new = prefix + MOVED[fullname[len(prefix):]]
        warnings.warn(f"{fullname} moved to {new}; the old name will be removed in 0.3",
                      DeprecationWarning, stacklevel=3)
        return importlib.util.spec_from_loader(fullname, _AliasLoader(new))


def install(package: str) -> None:
    """Make the old module names of ``package`` importable (idempotent)."""
    if not any(isinstance(f, _MovedFinder) and f.package == package for f in sys.meta_path):
        sys.meta_path.append(_MovedFinder(package))
