"""Identify mass, COM and inertia of a held rigid body by differentiable simulation in Newton.

Loss (RigPI): the mean squared tracked-frame pose error over shooting windows,
each channel scaled by its residual level, plus lambda * P(theta, C), the squared
relative violation of the prior's bounds. theta is the log-Cholesky
pseudo-inertia (always physical); every window also gets a correction of its
measured start state, a nuisance parameter of multiple shooting. L-BFGS-B runs
on gradients from the Warp tape.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from typing import Callable

import numpy as np
from scipy.optimize import minimize

from assets import Inertial, Pose

from .inertia import THETA_SIZE, flat_physical, physical_from_theta, physical_jacobian, theta_from_physical
from .rollout import FreeBodyRollout
from .windows import ShootingWindows

PHYSICAL_NAMES = ("mass", "com_x", "com_y", "com_z", "Ixx", "Iyy", "Izz", "Ixy", "Ixz", "Iyz")
# scales of the start-state corrections: position [m], rotation [rad], velocity [m/s], angular velocity [rad/s]
CORRECTION_SCALE = np.array([1e-3] * 3 + [1e-2] * 3)
CORRECTION_RATE_SCALE = np.array([1e-2] * 3 + [1e-1] * 3)


@dataclass(frozen=True)
class IdentifyConfig:
    """Free-body identification settings."""

    window_s: float = 0.1
    """Shooting-window length [s]; short windows keep integrated sensor noise small."""
    substeps: int = 5
    """Newton steps per pose sample."""
    penalty_weight: float = 0.1
    """lambda of the bound penalty (RigPI)."""
    max_iterations: int = 300
    """L-BFGS-B iterations per round."""
    rounds: tuple[str, ...] = ("momentum",)
    """Successive fits, each from the last, with channels rescaled by the last residual level:
    "pose" is the plain pose loss (robust from a far prior, but biased by wrench noise),
    "momentum" the mass- and inertia-scaled one (unbiased; see `eval_tracked_pose_error`)."""
    estimate_start_state: bool = True
    """Fit a start-state correction per window (multiple shooting) instead of trusting the measured one."""
    device: str = "cpu"


@dataclass(frozen=True)
class InertialBounds:
    """Box bounds C on (mass [kg], COM [m] x3, Ixx Iyy Izz [kg m^2]), object frame."""

    lower: tuple[float, ...]
    upper: tuple[float, ...]

    def penalty(self, flat: np.ndarray) -> float:
        """P(theta, C): squared bound violations relative to the bound width."""
        x = np.asarray(flat[:7])
        lo, hi = np.asarray(self.lower), np.asarray(self.upper)
        width = np.maximum(hi - lo, 1e-12)
        v = (np.maximum(lo - x, 0) + np.maximum(x - hi, 0)) / width
        return float(np.sum(v * v))

    def penalty_grad(self, flat: np.ndarray) -> np.ndarray:
        x = np.asarray(flat[:7])
        lo, hi = np.asarray(self.lower), np.asarray(self.upper)
        width = np.maximum(hi - lo, 1e-12)
        g = np.zeros(10)
        g[:7] = 2 * (np.maximum(x - hi, 0) - np.maximum(lo - x, 0)) / width**2
        return g


@dataclass(frozen=True)
class Identification:
    """Result: the identified body, its uncertainty, and how the fit went.

    covariance [10, 10] over (mass, com xyz, Ixx Iyy Izz Ixy Ixz Iyz).
    """

    inertial: Inertial
    theta: np.ndarray
    covariance: np.ndarray
    loss_history: tuple[float, ...]
    iterations: int
    wall_s: float
    window_s: float
    window_count: int
    config: IdentifyConfig

    @property
    def std(self) -> np.ndarray:
        return np.sqrt(np.maximum(np.diag(self.covariance), 0.0))

    def provenance(self) -> dict:
        return {
            "config": asdict(self.config),
            "iterations": self.iterations,
            "wall_s": self.wall_s,
            "window_count": self.window_count,
            "final_loss": self.loss_history[-1] if self.loss_history else None,
        }


def identify_free_body(
    windows: ShootingWindows,
    X_tracked_body: Pose,
    prior: Inertial,
    bounds: InertialBounds,
    config: IdentifyConfig,
    progress: Callable[[int, float], None] | None = None,
) -> Identification:
    """Fit theta (and per-window start corrections) to the recording's shooting windows."""
    t0 = time.perf_counter()
    rollout = FreeBodyRollout(windows, X_tracked_body, device=config.device)
    W = windows.window_count
    theta0 = theta_from_physical(prior.mass, prior.com, prior.inertia_matrix())
    size = float(np.cbrt(max(prior.mass, 1e-9) / 1000.0))  # length scale of the body at water density [m]
    theta_scale = np.array([0.5, 0.5, 0.5, 0.5] + [0.2 * size] * 6)
    n_corr = 12 * W if config.estimate_start_state else 0
    corr_scale = np.tile(np.concatenate([CORRECTION_SCALE, CORRECTION_RATE_SCALE]), W)

    def unpack(z):
        theta = theta0 + z[:THETA_SIZE] * theta_scale
        if not n_corr:
            return theta, None, None
        c = (z[THETA_SIZE:] * corr_scale).reshape(W, 12)
        return theta, c[:, :6], c[:, 6:]

    history: list[float] = []
    residual_count = windows.sample_count * W

    def objective(z, weight, scaled):
        theta, corr, corr_rate = unpack(z)
        loss, g_theta, g_corr, g_rate = rollout.loss_and_grad(theta, corr, corr_rate, weight, scaled)
        flat = flat_physical(theta)
        loss += config.penalty_weight * bounds.penalty(flat)
        g_theta = g_theta + config.penalty_weight * physical_jacobian(theta).T @ bounds.penalty_grad(flat)
        grad = g_theta * theta_scale
        if n_corr:
            grad = np.concatenate([grad, np.concatenate([g_corr, g_rate], axis=1).reshape(-1) * corr_scale])
        history.append(loss)
        if progress:
            progress(len(history), loss)
        return loss, grad

    z = np.zeros(THETA_SIZE + n_corr)
    iterations = 0
    for kind in config.rounds:
        scaled = kind == "momentum"
        weight = channel_weights(rollout.residuals(*unpack(z), momentum_scaled=scaled), residual_count)
        result = minimize(
            objective, z, args=(weight, scaled), jac=True, method="L-BFGS-B",
            options={"maxiter": config.max_iterations, "maxcor": 30, "ftol": 1e-12, "gtol": 1e-9},
        )
        z = result.x
        iterations += int(result.nit)
    theta, corr, corr_rate = unpack(z)
    r = rollout.residuals(theta, corr, corr_rate)
    covariance = window_robust_covariance(rollout, theta, corr, corr_rate, channel_weights(r, residual_count))
    m, c, I = physical_from_theta(theta)
    return Identification(
        inertial=Inertial(m, c, I),
        theta=theta,
        covariance=covariance,
        loss_history=tuple(history),
        iterations=iterations,
        wall_s=time.perf_counter() - t0,
        window_s=windows.window_s,
        window_count=W,
        config=config,
    )


def channel_weights(residual: np.ndarray, count: int) -> np.ndarray:
    """Loss weights [S, 6]: 1 / (count * variance) per sample index within the window.

    Integrated sensor noise makes errors grow along a window; weighting each
    sample index by its spread across windows keeps late samples from
    drowning the informative early ones. Position and rotation channels are pooled.
    """
    var_p = np.mean(residual[..., :3] ** 2, axis=(1, 2))
    var_r = np.mean(residual[..., 3:] ** 2, axis=(1, 2))
    floor_p, floor_r = max(var_p.max(), 1e-30) * 1e-6, max(var_r.max(), 1e-30) * 1e-6
    w = np.stack([1 / np.maximum(var_p, floor_p)] * 3 + [1 / np.maximum(var_r, floor_r)] * 3, axis=1)
    return w / count


def window_robust_covariance(rollout: FreeBodyRollout, theta, corr, corr_rate, weight) -> np.ndarray:
    """Covariance of (mass, com, inertia) clustered by window (sandwich estimator).

    Within a window the residuals are correlated (integrated sensor noise), so
    sigma^2 (J^T J)^-1 would be too narrow; windows are nearly independent, so
    the per-window scores give an honest spread. Start corrections are profiled
    out per window; the Jacobians come from central differences, batched over
    windows because they do not interact.
    """
    W = rollout.windows.window_count
    sqrt_w = np.sqrt(weight)[:, None, :]

    def res(th, c, cr):
        return (rollout.residuals(th, c, cr) * sqrt_w).transpose(1, 0, 2).reshape(W, -1)  # [W, S*6]

    r0 = res(theta, corr, corr_rate)
    eps_theta = 1e-4 * np.maximum(np.abs(theta), 1.0)
    J_theta = np.zeros((W, r0.shape[1], THETA_SIZE))
    for k in range(THETA_SIZE):
        e = np.zeros(THETA_SIZE)
        e[k] = eps_theta[k]
        J_theta[:, :, k] = (res(theta + e, corr, corr_rate) - res(theta - e, corr, corr_rate)) / (2 * e[k])
    profile = corr is not None
    c0 = corr if profile else np.zeros((W, 6))
    cr0 = corr_rate if profile else np.zeros((W, 6))
    J_corr = np.zeros((W, r0.shape[1], 12))
    scales = np.concatenate([CORRECTION_SCALE, CORRECTION_RATE_SCALE]) * 1e-2
    for k in range(12 if profile else 0):
        e = np.zeros((W, 12))
        e[:, k] = scales[k]
        plus = res(theta, c0 + e[:, :6], cr0 + e[:, 6:])
        minus = res(theta, c0 - e[:, :6], cr0 - e[:, 6:])
        J_corr[:, :, k] = (plus - minus) / (2 * scales[k])
    H = np.zeros((THETA_SIZE, THETA_SIZE))
    scores = np.zeros((W, THETA_SIZE))
    for w in range(W):
        Jc = J_corr[w]
        # project out what the window's own start correction can absorb
        Jt = J_theta[w] - Jc @ np.linalg.pinv(Jc) @ J_theta[w] if profile else J_theta[w]
        H += Jt.T @ Jt
        scores[w] = Jt.T @ r0[w]
    H_inv = np.linalg.pinv(H)
    meat = scores.T @ scores * W / max(W - THETA_SIZE, 1)
    cov_theta = H_inv @ meat @ H_inv
    Jp = physical_jacobian(theta)
    return Jp @ cov_theta @ Jp.T
