"""The posterior of a held free body: the recordings' likelihood fused with the geometry prior, always physical.

Data. The Newton-Euler regression of least squares (least_squares.py) is linear in
pi = (m, m c, I about the tracked origin), so under Gaussian force and torque noise each
recording's likelihood is a Gaussian in pi: centre pi_ls, information F = H M^-1 H, with H the
normal matrix of the rows weighted by the force and torque noise levels (corrected for the
tracker's noise) and M the sandwich's meat over 0.1 s blocks (the filtered noise is correlated
within a block). Recordings multiply: their quadratic forms add.

Prior. The geometry and material prior says the body is the mesh filled with material of a
density drawn from the material's distribution: a log-normal overall density scale e^u about
the prior's (its spread from the bounds C). With parts (the convex parts of the decomposition,
or any segmentation; each a pseudo-inertia per unit density), each part has its own density
e^(u + delta_k), delta_k ~ N(0, part_log_sigma^2) about their common scale, and the part model's pseudo-inertia is linear
in the densities, as in the part-wise estimator of Nadeau, Giamou & Kelly (ICRA 2023). Whatever
the part model leaves unexplained (inserts, a poor segmentation, scan error) is a spread of the
body's 4x4 pseudo-inertia P about the part model's P_A: the affine-invariant log-map
log(P_A^-1/2 P P_A^-1/2), each of its 10 components ~ N(0, shape_sigma^2). Its square is, to
second order, twice Lee, Wensing & Park's entropic (log-det) divergence between P and P_A
("Geometric robot dynamic identification", 2019/2020); it is invariant to the object frame.

Parameterisation. P is the log-Cholesky factor theta of inertia.py (Rucker & Wensing 2022),
so every value the solver tries is a physical body; the densities are their logs. The MAP is a
nonlinear least-squares problem in (theta, u, delta), solved with scipy.optimize.least_squares
(trust region) from the prior and, when it is physical, the least-squares estimate; the lower
cost wins. The Laplace (Gauss-Newton) covariance at the MAP gives 95 % intervals. A parameter
is prior-dominated when the recordings removed less than half of its prior variance.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from assets import FLAT_INERTIAL, Inertial, Pose

from .inertia import THETA_SIZE, flat_physical, physical_jacobian, theta_from_physical

Z95 = 1.959964


@dataclass(frozen=True)
class PosteriorConfig:
    """Spreads of the geometry prior and the solver's limits."""

    shape_sigma: float = 0.25
    """Spread of each of the 10 components of log(P_A^-1/2 P P_A^-1/2): how far the body's pseudo-inertia may
    stray from the (part-wise) uniform-density model. 0.25 lets a principal second moment or a COM offset of
    a quarter of the body's radius of gyration pass at one sigma."""
    part_log_sigma: float = 1.5
    """Spread of a part's log density about the body's: steel (7850 kg/m^3) on rubber (1150) or oak (700) differ
    by 1.9-2.4, so a head and a handle are 1.3-1.6 sigma apart and the recordings' mass and COM decide."""
    mass_log_sigma: float | None = None
    """Spread of the log of the overall density scale; None: from the mass bounds, read as a 95 % range, and
    at least `mass_log_sigma_floor`."""
    mass_log_sigma_floor: float = 0.5
    """Least spread of the log overall density: a named material describes the most visible part, and a
    steel blade in a PVC handle moves the whole body's density by 40 %. The recordings weigh the body through
    gravity far better than this (0.1-2 % here), so the floor costs nothing; a weighing is applied after
    identification (`with_weighed_mass`)."""
    max_evaluations: int = 2000
    """Residual evaluations per start."""
    prior_dominated_share: float = 0.5
    """A parameter whose variance the recordings shrank by less than this share of its prior variance is
    marked prior-dominated."""


@dataclass(frozen=True)
class DataTerm:
    """One recording's Gaussian likelihood in pi (tracked frame, about its origin): centre [10] and
    information [10, 10] (see the module docstring)."""

    pi: np.ndarray
    information: np.ndarray


@dataclass(frozen=True)
class PosteriorResult:
    """The MAP body, its Laplace covariance over (mass, com xyz, Ixx Iyy Izz Ixy Ixz Iyz), what it came from.

    data_share [10]: per flat parameter, 1 - posterior variance / prior variance (1: the recordings alone,
    0: the prior alone); prior_dominated: names (FLAT_INERTIAL) whose share is below the configured one;
    densities: each part's density [kg/m^3] (or the overall scale in kg per unit of the prior's mass when
    no parts were given); start: which start the MAP came from; moved: whether it moved from that start;
    message: the solver's words.
    """

    inertial: Inertial
    covariance: np.ndarray
    theta: np.ndarray
    data_share: np.ndarray
    prior_dominated: tuple[str, ...]
    densities: tuple[float, ...]
    start: str
    moved: bool
    evaluations: int
    cost: float
    message: str
    start_costs: dict = field(default_factory=dict)

    @property
    def std(self) -> np.ndarray:
        return np.sqrt(np.maximum(np.diag(self.covariance), 0.0))

    def interval95(self) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper 95 % bounds of the flat parameters (Laplace approximation)."""
        x = flat_physical(self.theta)
        return x - Z95 * self.std, x + Z95 * self.std

    def provenance(self) -> dict:
        return {
            "start": self.start, "moved": self.moved, "evaluations": self.evaluations, "cost": self.cost,
            "start_costs": self.start_costs, "message": self.message,
            "densities": list(self.densities),
            "data_share": dict(zip(FLAT_INERTIAL, map(float, self.data_share))),
            "prior_dominated": list(self.prior_dominated),
        }


def pseudo_inertia(mass: float, com, inertia) -> np.ndarray:
    """4x4 pseudo-inertia [[integral r r^T dm, m c], [m c^T, m]] of a body (inertia [kg m^2] about its COM)."""
    c = np.asarray(com, dtype=float)
    I = np.asarray(inertia, dtype=float)
    P = np.empty((4, 4))
    P[:3, :3] = 0.5 * np.trace(I) * np.eye(3) - I + mass * np.outer(c, c)
    P[:3, 3] = P[3, :3] = mass * c
    P[3, 3] = mass
    return P


def pseudo_inertia_from_theta(theta: np.ndarray) -> np.ndarray:
    """P = U U^T of the log-Cholesky theta (inertia.py): always symmetric positive definite."""
    alpha, d1, d2, d3, s12, s23, s13, t1, t2, t3 = theta
    U = np.exp(alpha) * np.array([[np.exp(d1), s12, s13, t1], [0.0, np.exp(d2), s23, t2],
                                  [0.0, 0.0, np.exp(d3), t3], [0.0, 0.0, 0.0, 1.0]])
    return U @ U.T


def pi_from_pseudo_inertia(P: np.ndarray) -> np.ndarray:
    """(m, m c, Ixx Iyy Izz Ixy Ixz Iyz about the origin) of a pseudo-inertia, least squares' layout."""
    S = P[:3, :3]
    I = np.trace(S) * np.eye(3) - S
    return np.array([P[3, 3], *P[:3, 3], I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2]])


def pseudo_inertia_from_pi(pi: np.ndarray) -> np.ndarray:
    """Inverse of `pi_from_pseudo_inertia` (need not be positive definite)."""
    Ixx, Iyy, Izz, Ixy, Ixz, Iyz = pi[4:]
    I = np.array([[Ixx, Ixy, Ixz], [Ixy, Iyy, Iyz], [Ixz, Iyz, Izz]])
    P = np.empty((4, 4))
    P[:3, :3] = 0.5 * np.trace(I) * np.eye(3) - I
    P[:3, 3] = P[3, :3] = pi[1:4]
    P[3, 3] = pi[0]
    return P


def _log_map(P: np.ndarray, whiten: np.ndarray) -> np.ndarray:
    """The 10 components of log(W P W) (W = P_A^-1/2) less its scale (the multiple of the identity: how heavy
    the body is, which the density prior says), off-diagonals times sqrt 2 so that their squares sum to the
    squared Frobenius norm."""
    e, V = np.linalg.eigh(whiten @ P @ whiten)
    L = (V * np.log(np.maximum(e, 1e-300))) @ V.T
    L -= np.trace(L) / 4 * np.eye(4)
    iu = np.triu_indices(4)
    return L[iu] * np.where(iu[0] == iu[1], 1.0, np.sqrt(2.0))


def _inverse_sqrt(P: np.ndarray) -> np.ndarray:
    e, V = np.linalg.eigh(0.5 * (P + P.T))
    return (V / np.sqrt(e)) @ V.T


def _nearest_positive(P: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """P with its eigenvalues (in units where each coordinate is of order one, `scale` [4]) floored at 1e-6 of
    the largest: the part model can leave the cone for extreme densities."""
    D = np.diag(1.0 / scale)
    e, V = np.linalg.eigh(D @ P @ D)
    if e.min() > 1e-6 * e.max():
        return P
    Q = (V * np.maximum(e, 1e-6 * e.max())) @ V.T
    return np.diag(scale) @ Q @ np.diag(scale)


def data_term_from_least_squares(pi: np.ndarray, normal: np.ndarray, meat: np.ndarray) -> DataTerm:
    """A recording's `DataTerm` from least squares' estimate pi, its (corrected) normal matrix H and the
    sandwich meat M: information H M^-1 H (the inverse of the sandwich covariance)."""
    H = 0.5 * (normal + normal.T)
    info = H @ np.linalg.pinv(0.5 * (meat + meat.T)) @ H
    return DataTerm(np.asarray(pi, dtype=float), 0.5 * (info + info.T))


def identify_posterior(
    data: list[DataTerm],
    X_tracked_body: Pose,
    prior: Inertial,
    mass_bounds: tuple[float, float],
    parts: np.ndarray | None = None,
    config: PosteriorConfig = PosteriorConfig(),
    extra_starts: dict | None = None,
) -> PosteriorResult:
    """The MAP body and its Laplace covariance (see the module docstring).

    data: the recordings' likelihoods (`data_term_from_least_squares`), pi in the tracked frame;
    X_tracked_body: the object frame in the tracked frame; prior: the prior body (uniform density at the
    prior's mass), object frame; mass_bounds: the prior's mass range [kg], read as a 95 % range;
    parts: [K, 4, 4] pseudo-inertias per unit density of the body's parts [m^5, m^4, m^3] in the object
    frame, or None (one uniform body); extra_starts: {name: Inertial} tried besides the prior (physical ones
    only). Never raises on finite inputs: a failed solve keeps the best start and says so in `message`.
    """
    from scipy.optimize import least_squares

    P_prior = pseudo_inertia(prior.mass, prior.com, prior.inertia_matrix())
    if parts is None or len(parts) == 0:
        part_P = (P_prior / prior.mass)[None]
        correction = np.zeros((4, 4))
    else:
        part_P = np.asarray(parts, dtype=float).reshape(-1, 4, 4)
        # what the parts miss of the prior body at uniform density: equal densities give the prior exactly
        correction = P_prior / prior.mass * part_P[:, 3, 3].sum() - part_P.sum(axis=0)
    volumes = part_P[:, 3, 3]
    free_parts = len(part_P) if len(part_P) > 1 else 0
    lo, hi = mass_bounds
    sigma_m = config.mass_log_sigma or max(float(np.log(max(hi, lo * (1 + 1e-9)) / lo)) / (2 * Z95),
                                           config.mass_log_sigma_floor)
    size = np.sqrt(max(np.trace(P_prior[:3, :3]) / prior.mass, 1e-18))
    scale4 = np.sqrt(prior.mass) * np.array([size, size, size, 1.0])

    T = X_tracked_body.matrix()  # object frame -> tracked frame, for points
    chol = []
    for term in data:
        info = np.nan_to_num(term.information, nan=0.0, posinf=0.0, neginf=0.0)
        e, V = np.linalg.eigh(0.5 * (info + info.T))
        keep = e > max(e.max(), 0.0) * 1e-14
        chol.append(((V[:, keep] * np.sqrt(e[keep])).T, np.nan_to_num(term.pi, posinf=0.0, neginf=0.0)))

    def part_model(delta):
        """The part model's pseudo-inertia at relative densities e^delta (its scale is free) and the densities."""
        rho = np.exp(delta)
        P = np.einsum("k,kij->ij", rho, part_P) + float(rho @ volumes / volumes.sum()) * correction
        return _nearest_positive(P, scale4), rho

    def residuals(x, which=("data", "prior")):
        theta, delta = x[:THETA_SIZE], x[THETA_SIZE:] if free_parts else np.zeros(1)
        P = pseudo_inertia_from_theta(theta)
        out = []
        if "data" in which:
            pi = pi_from_pseudo_inertia(T @ P @ T.T)
            out += [R @ (pi - centre) for R, centre in chol]
        if "prior" in which:
            out.append(_log_map(P, _inverse_sqrt(part_model(delta)[0])) / config.shape_sigma)
            out.append(np.array([(2 * theta[0] - np.log(prior.mass)) / sigma_m]))  # log mass, density prior
            if free_parts:
                out.append(delta / config.part_log_sigma)
        return np.concatenate(out)

    def start_vector(body: Inertial):
        return np.concatenate([theta_from_physical(body.mass, body.com, body.inertia_matrix()), np.zeros(free_parts)])

    starts = {"prior": start_vector(prior)}
    for name, body in (extra_starts or {}).items():
        try:
            if body is not None and body.physical_violation() is None:
                starts[name] = start_vector(body)
        except (ValueError, np.linalg.LinAlgError):
            continue  # a start that is not strictly physical is left out

    best, best_cost, messages, start_costs, evaluations = None, np.inf, [], {}, 0
    best_name, best_x0 = "prior", starts["prior"]
    for name, x0 in starts.items():
        with np.errstate(all="ignore"):
            cost0 = 0.5 * float(np.sum(residuals(x0) ** 2))
        try:
            with np.errstate(all="ignore"):
                sol = least_squares(residuals, x0, method="trf", x_scale="jac", max_nfev=config.max_evaluations,
                                    xtol=1e-10, ftol=1e-10, gtol=1e-10)
            x, cost, nfev, msg = sol.x, float(sol.cost), int(sol.nfev), sol.message
        except (ValueError, np.linalg.LinAlgError, FloatingPointError) as exc:
            x, cost, nfev, msg = x0, cost0, 0, f"the solver failed ({exc}); its start kept"
        if not np.all(np.isfinite(x)) or not np.isfinite(cost):
            x, cost, msg = x0, cost0, "the solver reached non-finite values; its start kept"
        evaluations += nfev
        start_costs[name] = {"start": cost0, "end": cost}
        messages.append(f"from {name}: {msg}")
        if best is None or cost < best_cost:
            best, best_cost, best_name, best_x0 = x, cost, name, x0

    theta = best[:THETA_SIZE]
    covariance, data_share = _laplace(best, residuals, theta)
    m, c, I = _physical(theta)
    _, rho = part_model(best[THETA_SIZE:] if free_parts else np.zeros(1))
    rho = rho * m / float(rho @ volumes)  # the densities that give the body's mass [kg/m^3; kg per unit without parts]
    dominated = tuple(n for n, s in zip(FLAT_INERTIAL, data_share) if s < config.prior_dominated_share)
    return PosteriorResult(
        inertial=Inertial(m, c, I), covariance=covariance, theta=theta, data_share=data_share,
        prior_dominated=dominated, densities=tuple(map(float, rho)), start=best_name,
        moved=bool(np.max(np.abs(best - best_x0)) > 0), evaluations=evaluations, cost=float(best_cost),
        message="; ".join(messages), start_costs=start_costs,
    )


def _physical(theta):
    from .inertia import physical_from_theta

    return physical_from_theta(theta)


def _laplace(x, residuals, theta):
    """Gauss-Newton covariance of the flat parameters at the MAP, and the data's share of each one's precision
    (1 - posterior variance / prior-only variance), by central differences."""
    n = len(x)
    steps = 1e-6 * np.maximum(np.abs(x), 1e-2)

    def jac(which):
        cols = []
        for k in range(n):
            e = np.zeros(n)
            e[k] = steps[k]
            cols.append((residuals(x + e, which) - residuals(x - e, which)) / (2 * steps[k]))
        return np.stack(cols, axis=1)

    with np.errstate(all="ignore"):
        J_all, J_prior = jac(("data", "prior")), jac(("prior",))
    J_all, J_prior = np.nan_to_num(J_all), np.nan_to_num(J_prior)
    cov_all = _inverse_gram(J_all)[:THETA_SIZE, :THETA_SIZE]
    cov_prior = _inverse_gram(J_prior)[:THETA_SIZE, :THETA_SIZE]
    G = physical_jacobian(theta)
    post = G @ cov_all @ G.T
    prior = G @ cov_prior @ G.T
    share = 1.0 - np.diag(post) / np.maximum(np.diag(prior), 1e-300)
    return 0.5 * (post + post.T), np.clip(share, 0.0, 1.0)


def _inverse_gram(J: np.ndarray) -> np.ndarray:
    """(J^T J)^-1 from the singular values of J itself (forming J^T J would square a condition number that
    precise and vague evidence side by side easily take past 1e8), directions with none left out."""
    _, sv, Vt = np.linalg.svd(J, full_matrices=False)
    keep = sv > sv.max() * 1e-13 if sv.size else np.zeros(0, bool)
    return (Vt[keep].T / sv[keep] ** 2) @ Vt[keep]
