"""Validation against labelled field data: pairs, coverage, and the budget fit (``fit``)."""
