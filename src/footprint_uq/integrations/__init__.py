"""Bridges to other software (optional extras)."""
