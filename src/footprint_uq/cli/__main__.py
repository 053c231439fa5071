"""``python -m footprint_uq.cli``: the ``footprint-uq`` command."""

from .main import main

main()
