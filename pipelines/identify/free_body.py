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

from assets import COM, MASS, MOMENTS, PRODUCTS, Inertial, Pose, symmetric_from_flat

from .inertia import THETA_SIZE, flat_physical, physical_from_theta, physical_jacobian, theta_from_physical
from .rollout import FreeBodyRollout
from .windows import ShootingWindows, clustered_covariance

# scales of the start-state corrections: position [m], rotation [rad], velocity [m/s], angular velocity [rad/s]
CORRECTION_SCALE = np.array([1e-3] * 3 + [1e-2] * 3)
CORRECTION_RATE_SCALE = np.array([1e-2] * 3 + [1e-1] * 3)


@dataclass(frozen=True)
class IdentifyConfig:
    """Free-body identification settings."""

    window_s: float = 0.1
    """Shooting-window length [s]; short windows keep integrated sensor noise small."""
    substeps: int = 2
    """Newton steps per pose sample (2.5 ms at 200 Hz: estimates move under 0.1 % from 1 ms)."""
    penalty_weight: float = 0.1
    """lambda of the bound penalty (RigPI)."""
    max_iterations: int = 30
    """Levenberg-Marquardt iterations (each: one batched Jacobian by forward differences)."""
    tolerance: float = 1e-4
    """A start stops when an iteration lowers its loss by less than this fraction."""
    starts: int = 2
    """Levenberg-Marquardt starts, run side by side: the caller's (least squares in a build), the
    prior's theta0, then draws from the prior's bounds."""
    smoothing_hz: float | None = 12.0
    """Zero-phase low-pass of poses and wrench before windowing, as least squares does: the
    start states and targets then carry little tracker noise, which would otherwise bias a
    momentum-scaled loss towards small mass and inertia. None: raw samples (the paper's way)."""
    seed: int = 0
    """Seed of the draws from the prior."""
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
    start_losses: list[float] | None = None

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
            "start_losses": self.start_losses,
        }


def identify_free_body(
    windows: ShootingWindows,
    X_tracked_body: Pose,
    starts: list[Inertial],
    bounds: InertialBounds,
    config: IdentifyConfig,
    progress: Callable[[int, float], None] | None = None,
) -> Identification:
    """Fit theta (and per-window start corrections) to the recording's shooting windows.

    Levenberg-Marquardt runs from every start at once, each start a set of Newton
    worlds in one batch; the start that ends lowest is kept. The paper optimizer
    runs from the first start only.
    """
    t0 = time.perf_counter()
    thetas = np.stack([theta_from_physical(s.mass, s.com, s.inertia_matrix()) for s in starts])
    if config.optimizer == "paper":
        thetas = thetas[:1]
    W, S, K = windows.window_count, windows.sample_count, len(thetas)
    jacobian = FreeBodyRollout(windows, X_tracked_body, sets=K * JACOBIAN_SETS, device=config.device,
                               requires_grad=False)
    if config.optimizer == "paper":
        rollout = FreeBodyRollout(windows, X_tracked_body, device=config.device)
        theta, history = paper_gradient_descent(rollout, thetas[0], bounds, config, progress)
        corr = rate = np.zeros((W, 6))
        weight = np.full((S, 6), 1.0 / (S * W))
        start_losses = None
    else:
        rollout = FreeBodyRollout(windows, X_tracked_body, sets=K, device=config.device)
        weight = channel_weights(rollout.residuals(thetas)[:, 0], S * W)
        fit = levenberg_marquardt(rollout, jacobian, thetas, None, None, bounds, config, weight, progress)
        # The weights came from the first start's residuals; a far start would set them badly, so
        # every start is refined once more with weights from the best fit's (uncorrected) residuals.
        best = int(np.argmin(fit[4]))
        weight = channel_weights(rollout.residuals(fit[0])[:, best], S * W)
        done = len(fit[3][best]) - 1
        refit = levenberg_marquardt(rollout, jacobian, *fit[:3], bounds, config, weight,
                                    progress and (lambda it, loss: progress(done + it, loss)))
        best = int(np.argmin(refit[4]))
        theta, corr, rate = (x[best] for x in refit[:3])
        history = fit[3][best] + refit[3][best][1:]
        start_losses = refit[4].tolist()
    point = [np.repeat(x[None], K, axis=0) for x in (theta, corr, rate)]  # the Jacobian rollout holds K points
    gram, jtr = window_normal_equations(jacobian, *point, weight)
    covariance = window_robust_covariance(gram[0], jtr[0], theta)
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
        start_losses=start_losses,
    )


def prior_starts(prior: Inertial, bounds: InertialBounds, count: int, seed: int) -> list[Inertial]:
    """`count` starts from the prior's spread: theta0 itself, then draws inside C (mass log-uniform,
    COM uniform, principal moments scaled by up to 1.5x either way), each kept only if physical."""
    rng = np.random.default_rng(seed)
    lo, hi = np.asarray(bounds.lower), np.asarray(bounds.upper)
    out, tries = [prior][:count], 0
    while len(out) < count and tries < 100 * count:
        tries += 1
        m = float(np.exp(rng.uniform(np.log(lo[MASS]), np.log(hi[MASS]))))
        c = rng.uniform(lo[COM], hi[COM])
        d, R = prior.principal()
        I = R @ np.diag(d * (m / prior.mass) * np.exp(rng.uniform(-0.4, 0.4, 3))) @ R.T
        candidate = Inertial(m, c, I)
        if candidate.physical_violation() is None:
            out.append(candidate)
    return out


def channel_weights(residual: np.ndarray, count: int) -> np.ndarray:
    """Loss weights [S, 6]: 1 / (count * variance) per sample index within the window.

    residual [S, W, 6]. Integrated sensor noise makes errors grow along a window;
    weighting each sample index by its spread across windows keeps late samples from
    drowning the informative early ones. Position and rotation channels are pooled.
    """
    var_p = np.mean(residual[..., :3] ** 2, axis=(1, 2))
    var_r = np.mean(residual[..., 3:] ** 2, axis=(1, 2))
    floor_p, floor_r = max(var_p.max(), 1e-30) * 1e-6, max(var_r.max(), 1e-30) * 1e-6
    w = np.stack([1 / np.maximum(var_p, floor_p)] * 3 + [1 / np.maximum(var_r, floor_r)] * 3, axis=1)
    return w / count


# parameter sets per point in a Jacobian rollout: the point, then theta and the 12 start corrections
# each moved one step forward and one back
JACOBIAN_SETS = 1 + 2 * (THETA_SIZE + 12)


def window_normal_equations(rollout: FreeBodyRollout, theta, corr, corr_rate, weight):
    """Per point and window, the Gauss-Newton blocks of the weighted residuals in theta (first 10 columns)
    and the window's own 12 start corrections: J^T J [K, W, 22, 22] and J^T r [K, W, 22], by central
    differences, all in one rollout of `rollout.sets` = K * JACOBIAN_SETS parameter sets (windows do
    not interact).

    theta [K, 10]; corr, corr_rate [K, W, 6].
    """
    K, W = len(theta), rollout.windows.window_count
    P, n = JACOBIAN_SETS, THETA_SIZE + 12
    eps_theta = 1e-4 * np.maximum(np.abs(theta), 1.0)  # [K, 10]
    eps_corr = np.concatenate([CORRECTION_SCALE, CORRECTION_RATE_SCALE]) * 1e-2
    th = np.repeat(theta[:, None], P, axis=1)  # [K, P, 10]: point, +steps, -steps
    th[:, 1:1 + THETA_SIZE] += eps_theta[:, :, None] * np.eye(THETA_SIZE)
    th[:, 1 + n:1 + n + THETA_SIZE] -= eps_theta[:, :, None] * np.eye(THETA_SIZE)
    c = np.concatenate([corr, corr_rate], axis=-1)[:, None].repeat(P, axis=1)  # [K, P, W, 12]
    c[:, 1 + THETA_SIZE:1 + n] += (eps_corr[:, None] * np.eye(12))[None, :, None, :]
    c[:, 1 + n + THETA_SIZE:] -= (eps_corr[:, None] * np.eye(12))[None, :, None, :]
    steps = np.concatenate([eps_theta, np.broadcast_to(eps_corr, (K, 12))], axis=1)
    return rollout.normal_equations(th.reshape(K * P, THETA_SIZE), c[..., :6].reshape(K * P, W, 6),
                                    c[..., 6:].reshape(K * P, W, 6), steps, weight)


def window_robust_covariance(gram, jtr, theta) -> np.ndarray:
    """Covariance of (mass, com, inertia) clustered by window (sandwich estimator), from one point's
    per-window J^T J [W, 22, 22] and J^T r [W, 22] (see `window_normal_equations`).

    Within a window the residuals are correlated (integrated sensor noise), so
    sigma^2 (J^T J)^-1 would be too narrow; windows are nearly independent, so
    the per-window scores give an honest spread. Start corrections are profiled
    out per window.
    """
    t, c = slice(0, THETA_SIZE), slice(THETA_SIZE, None)
    # eliminate what each window's own start correction can absorb (Schur complement)
    Hcc_inv = np.linalg.pinv(gram[:, c, c])
    Hct = gram[:, c, t]
    H = np.sum(gram[:, t, t] - Hct.transpose(0, 2, 1) @ Hcc_inv @ Hct, axis=0)
    scores = jtr[:, t] - np.einsum("wci,wcd,wd->wi", Hct, Hcc_inv, jtr[:, c])
    cov_theta = clustered_covariance(np.linalg.pinv(H), scores, THETA_SIZE)
    Jp = physical_jacobian(theta)
    return Jp @ cov_theta @ Jp.T


def levenberg_marquardt(rollout, jacobian, thetas, corr, rate, bounds: InertialBounds, config: IdentifyConfig,
                        weight, progress=None):
    """Levenberg-Marquardt on theta [K, 10] from K starts at once (`rollout.sets` = K, `jacobian.sets` =
    K * JACOBIAN_SETS), each window's start correction [K, W, 6] and rate (None: zero) solved alongside
    and eliminated in closed form (Schur complement).

    Gradients come from the Warp tape, Gauss-Newton curvature from one batched central-difference
    rollout per iteration. Returns every start's theta, corrections, correction rates, loss history
    and final loss.
    """
    K, W = thetas.shape[0], rollout.windows.window_count
    theta = thetas.copy()
    corr = np.zeros((K, W, 6)) if corr is None else corr.copy()
    rate = np.zeros((K, W, 6)) if rate is None else rate.copy()
    lam = np.full(K, 1e-3)
    sqrt_w = np.sqrt(weight)[:, None, None, :]
    sqrt_pen = np.sqrt(config.penalty_weight)

    def total_loss(th, c, cr):
        r = rollout.residuals(th, c, cr) * sqrt_w
        pen = np.array([np.sum(bounds.violation(flat_physical(t))[0] ** 2) for t in th])
        return np.einsum("skwc,skwc->k", r, r) + config.penalty_weight * pen

    loss = total_loss(theta, corr, rate)
    histories = [[float(x)] for x in loss]
    active = np.ones(K, bool)
    for it in range(config.max_iterations):
        gram, _ = window_normal_equations(jacobian, theta, corr, rate, weight)
        _, g_theta, g_corr, g_rate = rollout.loss_and_grad(theta, corr, rate, weight, True)
        g_c = 0.5 * np.concatenate([g_corr, g_rate], axis=-1)  # [K, W, 12]
        Hcc_inv = np.linalg.pinv(gram[..., THETA_SIZE:, THETA_SIZE:] + 1e-12 * np.eye(12))
        Hct = gram[..., THETA_SIZE:, :THETA_SIZE]  # [K, W, 12, 10]
        HciHct = Hcc_inv @ Hct
        H = gram[..., :THETA_SIZE, :THETA_SIZE].sum(axis=1) - np.einsum("kwci,kwcj->kij", Hct, HciHct)
        g = 0.5 * g_theta - np.einsum("kwci,kwc->ki", HciHct, g_c)
        for k in range(K):
            v, dv = bounds.violation(flat_physical(theta[k]))
            Jp = sqrt_pen * dv[:, None] * physical_jacobian(theta[k])[:7]
            H[k] += Jp.T @ Jp
            g[k] += Jp.T @ (sqrt_pen * v)
        pending, new_loss = active.copy(), loss.copy()
        for _ in range(10):
            if not pending.any():
                break
            step = np.zeros_like(theta)
            for k in np.flatnonzero(pending):
                step[k] = -np.linalg.solve(H[k] + lam[k] * np.diag(np.diag(H[k]) + 1e-12), g[k])
            dc = -np.einsum("kwcd,kwd->kwc", Hcc_inv, g_c + np.einsum("kwci,ki->kwc", Hct, step))
            dc[~pending] = 0.0
            trial = total_loss(theta + step, corr + dc[..., :6], rate + dc[..., 6:])
            better = pending & (trial < loss)
            theta[better] += step[better]
            corr[better] += dc[better][..., :6]
            rate[better] += dc[better][..., 6:]
            new_loss[better] = trial[better]
            lam[better] = np.maximum(lam[better] / 3, 1e-7)
            lam[pending & ~better] *= 4
            pending &= ~better
        moved = active & ~pending
        rel = (loss - new_loss) / np.maximum(loss, 1e-300)
        for k in np.flatnonzero(moved):
            histories[k].append(float(new_loss[k]))
        loss = new_loss
        active = moved & (rel >= config.tolerance)
        if progress:
            progress(it + 1, float(loss.min()))
        if not active.any():
            break
    return theta, corr, rate, histories, loss


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
    scale[COM] = np.cbrt(flat[MASS] / 1000.0)  # COM: the body's size at water density [m]
    scale[PRODUCTS] = np.mean(scale[MOMENTS])
    best, best_loss, history = theta, np.inf, []
    for step in range(config.paper_iterations):
        loss, g_theta, _, _ = rollout.loss_and_grad(theta[None], None, None, weight, False)
        loss, g_theta = float(loss[0]), g_theta[0]
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
        g_flat[:MOMENTS.stop] += config.penalty_weight * 2 * v * dv  # the bounds cover mass, COM, moments
        direction = np.sign(g_flat)
        for _ in range(20):
            trial = flat - 0.01 * scale * direction
            I = symmetric_from_flat(trial)
            if trial[MASS] > 0 and Inertial(trial[MASS], trial[COM], I).physical_violation() is None:
                theta = theta_from_physical(trial[MASS], trial[COM], I)
                break
            direction = 0.5 * direction
    return best, history
