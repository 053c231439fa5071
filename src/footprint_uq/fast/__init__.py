"""Compiled (numba) code: the scalar core every fast path calls, and the kernels built on it.

:mod:`footprint_uq.fast.core` holds the per-point math written once -- lens distortion and its
Jacobian, the lens's valid domain, damped undistortion with the principal-branch check -- as
small numba functions inlined into their callers.  The numpy reference
(:mod:`footprint_uq.cameras`) calls the same functions for the iterative parts, so that every
path gives the same answer, including "no answer".
"""
