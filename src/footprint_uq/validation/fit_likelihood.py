"""The group-level algebra of the budget fit's likelihood, shared by the dense reference and the compact model.

Both ``footprint_uq.validation.fit._Model`` (the dense reference: every per-object array in memory) and
:class:`footprint_uq.validation.fit_compact.CompactModel` (per-group sums from the compiled kernel) reduce the
objects of each calibration group ``g`` to the same sums -- ``M = U^T D^-1 U`` (k, k), ``P = U^T D^-1`` summed
(k, 2), ``b = U^T D^-1 r`` (k,), ``Dsum = sum D^-1`` (2, 2), ``Dr = sum D^-1 r`` (2,), ``rDr`` and the log
determinants ``ld`` of the per-object covariances ``D_i``.  From there the (restricted) log-likelihood of
``C_g = U_g Sigma U_g^T + blockdiag(D_i)`` (Woodbury on the shared part), the generalised-least-squares bias
and the score of the shared terms are the same few small matrix products; they live here, once.  This module
imports numpy only: the reference does not depend on the compiled path.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ["GroupTerms", "GroupLikelihood"]


class GroupTerms(NamedTuple):
    """Intermediate results of one evaluation, reused by the score."""

    K: np.ndarray         # (G, k, k) (I + M Sigma)^-1 Sigma per group
    KP: np.ndarray        # (G, k, 2) K P
    bt: np.ndarray        # (G, k) U^T D^-1 (r - beta)
    beta: np.ndarray      # (2,) bias (zeros without fit_bias)
    Phi: np.ndarray       # (2, 2) X^T C^-1 X
    cov_beta: np.ndarray  # (2, 2) bias covariance (zeros without fit_bias)


class GroupLikelihood:
    """Log-likelihood and score of the variances ``v`` of the free terms from per-group sums.

    Subclasses set ``Sf`` (k, k) fixed parameter covariance, ``A`` (m_shared, k, k) unit covariances of the free
    shared terms, ``n`` objects, ``fit_bias``, ``reml``, ``object_free`` and ``_cache`` (the sums when no
    per-object term is free), and define ``_group_sums(vo, grad)`` (the sums for the per-object variances ``vo``,
    or None when a per-object covariance is singular) and ``_object_score(s, t, Phi_i)`` (score of the
    per-object variances).
    """

    def sigma(self, v) -> np.ndarray:
        """Parameter covariance (k, k) for the variances ``v`` of the free terms."""
        ns = self.A.shape[0]
        return self.Sf + np.tensordot(v[:ns], self.A, 1)

    def evaluate(self, v, grad: bool = True):
        """(log-likelihood, score (m,) or None, bias (2,), bias covariance (2, 2))."""
        v = np.asarray(v, dtype=np.float64)
        s = self._cache if not self.object_free else self._group_sums(v[self.A.shape[0]:], grad)
        if s is None:
            return -np.inf, None, None, None
        ll, t = self._loglik(s, self.sigma(v))
        if t is None:
            return -np.inf, None, None, None
        if not grad:
            return ll, None, t.beta, t.cov_beta
        return ll, self._score(s, t), t.beta, t.cov_beta

    def _loglik(self, s: dict, S: np.ndarray) -> tuple[float, GroupTerms | None]:
        """Log-likelihood from the group sums ``s`` and the parameter covariance ``S`` (None: not positive)."""
        k = S.shape[0]
        Hm = np.eye(k) + s["M"] @ S                      # (G, k, k)
        sign, ldH = np.linalg.slogdet(Hm)
        if np.any(sign <= 0):
            return -np.inf, None
        K = np.swapaxes(np.linalg.solve(np.swapaxes(Hm, 1, 2), np.broadcast_to(S, Hm.shape)), 1, 2)
        KP = K @ s["P"]
        Phi = (s["Dsum"] - np.swapaxes(s["P"], 1, 2) @ KP).sum(0)
        Xr = (s["Dr"] - np.einsum("gka,gk->ga", KP, s["b"])).sum(0)
        beta = np.linalg.solve(Phi, Xr) if self.fit_bias else np.zeros(2)
        bt = s["b"] - np.einsum("gka,a->gk", s["P"], beta)   # U^T D^-1 (r - beta)
        quad = (s["rDr"] - 2 * s["Dr"] @ beta + np.einsum("a,gab,b->g", beta, s["Dsum"], beta)
                - np.einsum("gk,gkl,gl->g", bt, K, bt))
        ll = -0.5 * (np.sum(s["ld"] + ldH) + np.sum(quad) + 2 * self.n * np.log(2 * np.pi))
        if self.fit_bias and self.reml:
            ll -= 0.5 * np.linalg.slogdet(Phi)[1]
        cov_beta = np.linalg.inv(Phi) if self.fit_bias else np.zeros((2, 2))
        return ll, GroupTerms(K, KP, bt, beta, Phi, cov_beta)

    def _score(self, s: dict, t: GroupTerms) -> np.ndarray:
        """Score (m,): the shared terms' from the group sums, then the per-object terms' (subclass)."""
        M = s["M"]
        w = t.bt - np.einsum("gkl,gl->gk", M @ t.K, t.bt)    # U^T C^-1 (r - beta)
        Q = M - M @ t.K @ M                                   # U^T C^-1 U
        g = -0.5 * (np.einsum("jab,gba->j", self.A, Q) - np.einsum("ga,jab,gb->j", w, self.A, w))
        use_reml = self.fit_bias and self.reml
        Phi_i = np.linalg.inv(t.Phi) if use_reml else None
        if use_reml:
            Y = s["P"] - M @ t.KP                             # U^T C^-1 X  (G, k, 2)
            g += 0.5 * np.einsum("gka,jkl,glb,ba->j", Y, self.A, Y, Phi_i)
        if not self.object_free:
            return g
        return np.r_[g, self._object_score(s, t, Phi_i)]
