"""What a least-squares fit says about its own precision.

A fit's residuals are not independent: along one replayed stretch of the ball's track, or one
second of a drive's motion, an error in the model shows in many residuals alike. So the
uncertainty of each fitted value is the sandwich (cluster-robust) estimate over such groups,
not the textbook one, which would take every residual as news and come out too small.
"""

from __future__ import annotations

import numpy as np
from scipy import sparse
from scipy.optimize import OptimizeResult


def robust_weights(residuals: np.ndarray, f_scale: float) -> tuple[np.ndarray, np.ndarray]:
    """How scipy's ``soft_l1`` loss weighs each residual: (the factor on the Jacobian's rows,
    the factor on the residuals) that make the weighted problem's Gauss-Newton step its own."""
    z = (residuals / f_scale) ** 2
    rho1 = (1 + z) ** -0.5
    jac_scale = (1 + z) ** -0.75
    return jac_scale, rho1 / jac_scale


def cluster_covariance(result: OptimizeResult, clusters: np.ndarray, f_scale: float) -> np.ndarray:
    """The covariance of a ``soft_l1`` least-squares result's parameters, residuals grouped
    by ``clusters`` (one label per residual): groups are taken as independent, the residuals
    within one are not.

    Directions the data do not fix come out with infinite variance.
    """
    _, f_weight = robust_weights(result.fun, f_scale)
    jac = result.jac  # scipy returns it already weighted for the loss
    jac = jac.toarray() if sparse.issparse(jac) else np.asarray(jac)
    weighted = result.fun * f_weight
    bread = jac.T @ jac
    labels, index = np.unique(clusters, return_inverse=True)
    scores = np.zeros((len(labels), jac.shape[1]))
    np.add.at(scores, index, jac * weighted[:, None])
    meat = scores.T @ scores * len(labels) / max(len(labels) - 1, 1)
    scale = np.sqrt(np.diag(bread))
    unknown = scale <= 1e-12 * max(float(scale.max(initial=0.0)), 1e-300)
    scale[unknown] = 1.0
    inverse = np.linalg.pinv(bread / np.outer(scale, scale), rcond=1e-12) / np.outer(scale, scale)
    covariance = inverse @ meat @ inverse
    covariance[unknown, :] = covariance[:, unknown] = 0.0
    covariance[unknown, unknown] = np.inf
    return covariance
