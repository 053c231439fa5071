"""The ``footprint-uq`` command line: one module per command; :mod:`.main` is the registry."""

from .main import main

__all__ = ["main"]
