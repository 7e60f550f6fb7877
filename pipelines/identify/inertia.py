"""Physically consistent inertial parameters: the log-Cholesky pseudo-inertia.

Rucker & Wensing, "Smooth Parameterization of Rigid-Body Inertia", RA-L 2022.
The pseudo-inertia J = [[Sigma, h], [h^T, m]] is positive definite exactly when
the body is physical (m > 0, inertia positive definite, triangle inequality).
Writing J = U U^T with U upper triangular and a log on its diagonal gives ten
unconstrained numbers theta for which every value is a physical body:

    theta = (alpha, d1, d2, d3, s12, s23, s13, t1, t2, t3)
    U = e^alpha [[e^d1, s12, s13, t1], [0, e^d2, s23, t2], [0, 0, e^d3, t3], [0, 0, 0, 1]]

so that mass m = e^(2 alpha), COM c = t [m], and the second moment of the mass
about the COM per unit mass is S = U3 U3^T (U3 the upper-left 3x3 block, sans
e^alpha), hence I_com = m (tr(S) 1 - S).
"""

from __future__ import annotations

import numpy as np
import warp as wp

THETA_SIZE = 10


def physical_from_theta(theta: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """(mass [kg], COM [m], inertia about the COM [kg m^2]) from log-Cholesky theta."""
    alpha, d1, d2, d3, s12, s23, s13, t1, t2, t3 = np.asarray(theta, dtype=float)
    U3 = np.array([[np.exp(d1), s12, s13], [0.0, np.exp(d2), s23], [0.0, 0.0, np.exp(d3)]])
    S = U3 @ U3.T
    m = np.exp(2 * alpha)
    return m, np.array([t1, t2, t3]), m * (np.trace(S) * np.eye(3) - S)


def theta_from_physical(mass: float, com, inertia) -> np.ndarray:
    """Inverse of `physical_from_theta`; the body must be strictly physical."""
    I = 0.5 * (np.asarray(inertia, dtype=float) + np.asarray(inertia, dtype=float).T)
    S = (0.5 * np.trace(I) * np.eye(3) - I) / mass
    # upper-triangular factor S = U U^T from a Cholesky of the index-reversed matrix
    P = np.eye(3)[::-1]
    try:
        L = np.linalg.cholesky(P @ S @ P)
    except np.linalg.LinAlgError as exc:
        raise ValueError(f"inertia {I.tolist()} with mass {mass} is not physical (triangle inequality)") from exc
    U = P @ L @ P
    return np.array(
        [0.5 * np.log(mass), np.log(U[0, 0]), np.log(U[1, 1]), np.log(U[2, 2]), U[0, 1], U[1, 2], U[0, 2], *com]
    )


def nearest_physical_inertia(mass: float, inertia, margin: float = 1e-3) -> np.ndarray:
    """The inertia [kg m^2] with its second-moment matrix S = (tr(I)/2 - I)/m clipped to at least
    `margin` x its largest eigenvalue, so `theta_from_physical` accepts it; unchanged when already so."""
    I = 0.5 * (np.asarray(inertia, dtype=float) + np.asarray(inertia, dtype=float).T)
    e, V = np.linalg.eigh((0.5 * np.trace(I) * np.eye(3) - I) / mass)
    floor = margin * max(e.max(), 1e-30)
    if e.min() >= floor:
        return I
    S = V @ np.diag(np.maximum(e, floor)) @ V.T
    return mass * (np.trace(S) * np.eye(3) - S)


def physical_jacobian(theta: np.ndarray, eps: float = 1e-7) -> np.ndarray:
    """d(mass, com[3], inertia[6: xx yy zz xy xz yz]) / d theta, shape [10, 10], central differences."""
    theta = np.asarray(theta, dtype=float)
    J = np.zeros((10, THETA_SIZE))
    for k in range(THETA_SIZE):
        step = np.zeros(THETA_SIZE)
        step[k] = eps
        J[:, k] = (flat_physical(theta + step) - flat_physical(theta - step)) / (2 * eps)
    return J


def flat_physical(theta: np.ndarray) -> np.ndarray:
    """The flat vector (`assets.FLAT_INERTIAL`) from theta, which need not be physical."""
    m, c, I = physical_from_theta(theta)
    return np.array([m, *c, I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2]])


@wp.func
def inertial_from_theta(theta: wp.array2d[float], k: int):
    """Warp twin of `physical_from_theta` for row k: returns mass [kg], COM [m], inertia [kg m^2]."""
    m = wp.exp(2.0 * theta[k, 0])
    U = wp.mat33(
        wp.exp(theta[k, 1]), theta[k, 4], theta[k, 6], 0.0, wp.exp(theta[k, 2]), theta[k, 5], 0.0, 0.0,
        wp.exp(theta[k, 3]),
    )
    S = U * wp.transpose(U)
    tr = S[0, 0] + S[1, 1] + S[2, 2]
    inertia = m * (tr * wp.identity(n=3, dtype=float) - S)
    return m, wp.vec3(theta[k, 7], theta[k, 8], theta[k, 9]), inertia
