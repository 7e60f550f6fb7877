"""Identify mass, COM and inertia of a held rigid body by differentiable simulation in Newton.

Loss (RigPI): the squared tracked-frame pose error over shooting windows, scaled
by the body's mass and inertia (see `eval_tracked_pose_error`) and weighted per
sample by its spread, plus lambda * P(theta, C), the squared relative violation
of the prior's bounds. theta is the log-Cholesky pseudo-inertia (always
physical); every window also gets a correction of its measured start state, a
nuisance parameter of multiple shooting. Levenberg-Marquardt steps use the
gradient from the Warp tape and Gauss-Newton curvature from batched central
differences, with each window's correction eliminated in closed form.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from typing import Callable, Literal

import numpy as np

from assets import Inertial, Pose

from .inertia import THETA_SIZE, flat_physical, physical_from_theta, physical_jacobian, theta_from_physical
from .rollout import FreeBodyRollout
from .windows import ShootingWindows

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
    max_iterations: int = 30
    """Levenberg-Marquardt iterations (each: one batched Jacobian by central differences)."""
    optimizer: Literal["gauss-newton", "paper"] = "gauss-newton"
    """gauss-newton: momentum-scaled loss, Levenberg-Marquardt with window corrections (default).
    paper: RigPI's own scheme, for comparison: plain pose loss, gradient steps of ~1/100 of each
    parameter's scale, windows started from the measured states."""
    paper_iterations: int = 200
    """Gradient steps of the paper optimizer."""
    device: str = "cpu"


@dataclass(frozen=True)
class InertialBounds:
    """Box bounds C on (mass [kg], COM [m] x3, Ixx Iyy Izz [kg m^2]), object frame."""

    lower: tuple[float, ...]
    upper: tuple[float, ...]

    def violation(self, flat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Signed bound violations relative to the bound width [7], and d(violation)/d(flat) on the diagonal.

        P(theta, C) = sum of squared violations (RigPI's penalty).
        """
        x = np.asarray(flat[:7])
        lo, hi = np.asarray(self.lower), np.asarray(self.upper)
        width = np.maximum(hi - lo, 1e-12)
        v = (np.minimum(x - lo, 0) + np.maximum(x - hi, 0)) / width
        return v, ((x < lo) | (x > hi)) / width


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
    start: Inertial,
    bounds: InertialBounds,
    config: IdentifyConfig,
    progress: Callable[[int, float], None] | None = None,
) -> Identification:
    """Fit theta (and per-window start corrections) to the recording's shooting windows from `start`."""
    t0 = time.perf_counter()
    rollout = FreeBodyRollout(windows, X_tracked_body, device=config.device)
    theta = theta_from_physical(start.mass, start.com, start.inertia_matrix())
    if config.optimizer == "paper":
        theta, history = paper_gradient_descent(rollout, theta, bounds, config, progress)
        corr = rate = None
        weight = np.full((windows.sample_count, 6), 1.0 / (windows.sample_count * windows.window_count))
    else:
        weight = channel_weights(rollout.residuals(theta), windows.sample_count * windows.window_count)
        theta, corr, rate, history = gauss_newton(rollout, theta, bounds, config, weight, progress)
    covariance = window_robust_covariance(rollout, theta, corr, rate, weight)
    m, c, I = physical_from_theta(theta)
    return Identification(
        inertial=Inertial(m, c, I),
        theta=theta,
        covariance=covariance,
        loss_history=tuple(history),
        iterations=len(history) - 1,
        wall_s=time.perf_counter() - t0,
        window_s=windows.window_s,
        window_count=windows.window_count,
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


def window_jacobians(rollout: FreeBodyRollout, theta, corr, corr_rate, weight):
    """Weighted residuals r [W, n] and their Jacobians w.r.t. theta [W, n, 10] and the start corrections
    [W, n, 12] (each window's own), by central differences batched over windows: they do not interact."""
    W = rollout.windows.window_count
    sqrt_w = np.sqrt(weight)[:, None, :]
    c0 = np.zeros((W, 6)) if corr is None else corr
    cr0 = np.zeros((W, 6)) if corr_rate is None else corr_rate

    def res(th, c, cr):
        return (rollout.residuals(th, c, cr) * sqrt_w).transpose(1, 0, 2).reshape(W, -1)

    r0 = res(theta, c0, cr0)
    eps_theta = 1e-4 * np.maximum(np.abs(theta), 1.0)
    J_theta = np.zeros((W, r0.shape[1], THETA_SIZE))
    for k in range(THETA_SIZE):
        e = np.zeros(THETA_SIZE)
        e[k] = eps_theta[k]
        J_theta[:, :, k] = (res(theta + e, c0, cr0) - res(theta - e, c0, cr0)) / (2 * e[k])
    J_corr = np.zeros((W, r0.shape[1], 12))
    steps = np.concatenate([CORRECTION_SCALE, CORRECTION_RATE_SCALE]) * 1e-2
    for k in range(12):
        e = np.zeros((W, 12))
        e[:, k] = steps[k]
        plus = res(theta, c0 + e[:, :6], cr0 + e[:, 6:])
        minus = res(theta, c0 - e[:, :6], cr0 - e[:, 6:])
        J_corr[:, :, k] = (plus - minus) / (2 * steps[k])
    return r0, J_theta, J_corr


def window_robust_covariance(rollout: FreeBodyRollout, theta, corr, corr_rate, weight) -> np.ndarray:
    """Covariance of (mass, com, inertia) clustered by window (sandwich estimator).

    Within a window the residuals are correlated (integrated sensor noise), so
    sigma^2 (J^T J)^-1 would be too narrow; windows are nearly independent, so
    the per-window scores give an honest spread. Start corrections are profiled
    out per window.
    """
    r0, J_theta, J_corr = window_jacobians(rollout, theta, corr, corr_rate, weight)
    W = len(r0)
    H = np.zeros((THETA_SIZE, THETA_SIZE))
    scores = np.zeros((W, THETA_SIZE))
    for w in range(W):
        Jc = J_corr[w]
        # project out what the window's own start correction can absorb
        Jt = J_theta[w] - Jc @ np.linalg.pinv(Jc) @ J_theta[w]
        H += Jt.T @ Jt
        scores[w] = Jt.T @ r0[w]
    H_inv = np.linalg.pinv(H)
    meat = scores.T @ scores * W / max(W - THETA_SIZE, 1)
    cov_theta = H_inv @ meat @ H_inv
    Jp = physical_jacobian(theta)
    return Jp @ cov_theta @ Jp.T


def gauss_newton(rollout, theta, bounds: InertialBounds, config: IdentifyConfig, weight, progress=None):
    """Levenberg-Marquardt on theta with each window's start correction solved alongside (variable projection).

    Returns theta, corrections, correction rates and the loss history.
    """
    W = rollout.windows.window_count
    corr, rate = np.zeros((W, 6)), np.zeros((W, 6))
    lam, history = 1e-3, []
    sqrt_pen = np.sqrt(config.penalty_weight)

    def penalty_residual(th):
        return sqrt_pen * bounds.violation(flat_physical(th))[0]

    def total_loss(th, c, cr):
        r = rollout.residuals(th, c, cr) * np.sqrt(weight)[:, None, :]
        return float(np.sum(r * r) + np.sum(penalty_residual(th) ** 2))

    loss = total_loss(theta, corr, rate)
    history.append(loss)
    for it in range(config.max_iterations):
        # Gradient from the Warp tape through the Newton rollout; Gauss-Newton curvature from
        # batched central differences (ten parameters, windows independent).
        _, J_theta, J_corr = window_jacobians(rollout, theta, corr, rate, weight)
        _, g_theta, g_corr, g_rate = rollout.loss_and_grad(theta, corr, rate, weight, True)
        g_c = 0.5 * np.concatenate([g_corr, g_rate], axis=1)  # [W, 12]
        H = np.zeros((THETA_SIZE, THETA_SIZE))
        g = 0.5 * g_theta
        solves = []
        for w in range(W):
            Hcc = J_corr[w].T @ J_corr[w] + 1e-12 * np.eye(12)
            Hct = J_corr[w].T @ J_theta[w]
            Hcc_inv = np.linalg.pinv(Hcc)
            solves.append((Hcc_inv, Hct))
            # eliminate the window's correction (Schur complement)
            H += J_theta[w].T @ J_theta[w] - Hct.T @ Hcc_inv @ Hct
            g -= Hct.T @ Hcc_inv @ g_c[w]
        v, dv = bounds.violation(flat_physical(theta))
        pr = sqrt_pen * v
        Jp = sqrt_pen * dv[:, None] * physical_jacobian(theta)[:7]
        H += Jp.T @ Jp
        g += Jp.T @ pr
        improved = False
        for _ in range(10):
            step = -np.linalg.solve(H + lam * np.diag(np.diag(H) + 1e-12), g)
            dc = np.stack([-Hcc_inv @ (g_c[w] + Hct @ step) for w, (Hcc_inv, Hct) in enumerate(solves)])
            new_corr, new_rate = corr + dc[:, :6], rate + dc[:, 6:]
            new_loss = total_loss(theta + step, new_corr, new_rate)
            if new_loss < loss:
                theta, corr, rate, improved = theta + step, new_corr, new_rate, True
                lam = max(lam / 3, 1e-7)
                break
            lam *= 4
        if not improved:
            break
        rel = (loss - new_loss) / max(loss, 1e-300)
        loss = new_loss
        history.append(loss)
        if progress:
            progress(it + 1, loss)
        if rel < 1e-7:
            break
    return theta, corr, rate, history




def paper_gradient_descent(rollout, theta, bounds: InertialBounds, config: IdentifyConfig, progress=None):
    """RigPI's refinement: the plain pose loss (mean squared position and rotation error) plus
    lambda * P(theta, C), descended in the physical parameters (mass, COM, inertia), each step
    moving every parameter by 1/100 of its scale against its gradient's sign; tape gradients;
    windows from measured states.

    Returns the best theta seen and the loss per step.
    """
    W, S = rollout.windows.window_count, rollout.windows.sample_count
    weight = np.full((S, 6), 1.0 / (S * W))
    flat = flat_physical(theta)
    scale = np.abs(flat)
    scale[1:4] = np.cbrt(flat[0] / 1000.0)  # COM: the body's size at water density [m]
    scale[7:] = np.mean(scale[4:7])
    best, best_loss, history = theta, np.inf, []
    for step in range(config.paper_iterations):
        loss, g_theta, _, _ = rollout.loss_and_grad(theta, None, None, weight, False)
        flat = flat_physical(theta)
        v, dv = bounds.violation(flat)
        loss += config.penalty_weight * float(v @ v)
        history.append(loss)
        if progress:
            progress(step + 1, loss)
        if loss < best_loss:
            best, best_loss = theta, loss
        # d loss / d flat through the parameterisation: theta is a smooth function of the physical values
        J = physical_jacobian(theta)  # d flat / d theta
        g_flat = np.linalg.lstsq(J.T, g_theta, rcond=None)[0]
        g_flat[:7] += config.penalty_weight * 2 * v * dv
        direction = np.sign(g_flat)
        for _ in range(20):
            trial = flat - 0.01 * scale * direction
            I = np.array([[trial[4], trial[7], trial[8]], [trial[7], trial[5], trial[9]], [trial[8], trial[9], trial[6]]])
            if trial[0] > 0 and Inertial(trial[0], trial[1:4], I).physical_violation() is None:
                theta = theta_from_physical(trial[0], trial[1:4], I)
                break
            direction = 0.5 * direction
    return best, history
