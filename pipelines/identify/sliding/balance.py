"""Friction without a simulation: the quasi-static estimate, the wrench balance of steady windows, the turn
check, and which measurement of mu to report."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from assets.conventions import GRAVITY_MAGNITUDE_M_S2 as GRAVITY_M_S2

from ..windows import local_twist
from .body import PlanarBody, SlidingConfig, support_points
from .fit import SlidingFit
from .windows import ForceBias, PushWindows, planar_travel, push_windows, scatter_about_quadratic, window_thirds


def quasi_static_friction(recording, body: PlanarBody, config: SlidingConfig, bias: ForceBias,
                          mass_kg: float) -> float:
    """The lab's estimate, mu = steady pushing force / (m g).

    "Steady pushing": the object slides and the pusher presses (force above a
    quarter of its 90th percentile); the median horizontal force over those
    samples. It ignores inertia and the force that turns the object, so it
    reads high while the object accelerates and low while it turns.
    """
    windows = push_windows(recording, body, config, bias)
    f = np.linalg.norm(windows.window_force, axis=-1).ravel()
    pressing = f > 0.25 * np.percentile(f, 90)
    return float(np.median(f[pressing]) / (mass_kg * GRAVITY_M_S2))


@dataclass(frozen=True)
class WrenchBalance:
    """Result of `wrench_balance_friction`: mu and its standard deviation (least squares over the
    windows' balances), mu per window, and the RMS of the balance left [N] (moments over the face's half
    diagonal), the measure of how well Coulomb friction under uniform pressure explains the pushes."""

    mu: float
    std: float
    per_window: np.ndarray
    residual_n: float

    def provenance(self) -> dict:
        return {"mu": self.mu, "std": self.std, "per_window": self.per_window.tolist(), "residual_n": self.residual_n}


def steady_windows(windows: PushWindows, body: PlanarBody, config: SlidingConfig) -> np.ndarray:
    """Per window, whether the object slides throughout it: it travels at least config.moving_speed_m_s on
    average and ten times the tracker's scatter about a quadratic in time, at least half a third of its
    travel over each third, and at its start and end at least half its mean speed (travel: x, y and the
    heading as an arc at the face's half diagonal)."""
    m = windows.measured
    scatter = scatter_about_quadratic(m[..., :2])
    arc = float(np.hypot(*body.half_extents_m[:2]))
    span_s = windows.span_s
    whole = planar_travel(m[-1] - m[0], arc)
    thirds = np.all([planar_travel(m[b] - m[a], arc) >= whole / 6 for a, b in window_thirds(m.shape[0])], axis=0)
    start, end = windows.start[:, 3:6], _end_twist(windows, config)
    mean_speed = whole / span_s
    return ((whole >= np.maximum(config.moving_speed_m_s * span_s, 10.0 * scatter)) & thirds
            & (planar_travel(start, arc) >= 0.5 * mean_speed) & (planar_travel(end, arc) >= 0.5 * mean_speed))


def _end_twist(windows: PushWindows, config: SlidingConfig) -> np.ndarray:
    """x, y rates [m/s] and yaw rate [rad/s] at each window's end [W, 3], by the quadratic fit that gives its
    start's (`local_twist`), one-sided over as many samples as the start's centred one."""
    S = windows.sample_count
    t = np.arange(S + 1) * windows.sample_period_s
    out = []
    for m in np.moveaxis(windows.measured, 1, 0):
        rot = Rotation.from_rotvec(np.c_[np.zeros((S + 1, 2)), m[:, 2]])
        twist = local_twist(t, np.c_[m[:, :2], np.zeros(S + 1)], rot, S, 2 * config.twist_half_width)
        out.append([twist[0], twist[1], twist[5]])
    return np.asarray(out)


def wrench_balance_friction(windows: PushWindows, body: PlanarBody, config: SlidingConfig) -> WrenchBalance | None:
    """mu from each window's balance of the pushing wrench, the momentum change and Coulomb friction.

    Over a window, the mean pushing force and its moment about the COM, less the change of momentum, equal
    mu times the friction wrench that the window's mean twist (from its measured end poses) draws from the
    support grid of the simulation (uniform pressure): linear in mu, solved by least squares. It needs no
    simulation, so unlike a force-driven rollout it does not balance on the knife edge of a slow push (a
    Coulomb object under a force a little below or above mu m g sticks or accelerates), and it holds for
    pushes that turn the object, where steady force over m g (`quasi_static_friction`) does not.
    Only windows in which the object slides throughout (`steady_windows`) are used: a window's mean twist
    stands for its friction only then (a push in strokes, which stops the object, has few or none). None
    when there is no such window.
    """
    balance = _balance_rows(windows, body, config)
    if balance is None:
        return None
    X, y = balance
    mu = float(np.sum(X * y) / np.sum(X * X))
    residual = y - mu * X
    dof = max(X.size - 1, 1)
    std = float(np.sqrt(np.sum(residual**2) / dof / np.sum(X * X)))
    per_window = np.sum(X * y, axis=1) / np.sum(X * X, axis=1)
    return WrenchBalance(mu, std, per_window, float(np.sqrt(np.mean(residual**2))))


def wrench_balance_error(windows: PushWindows, body: PlanarBody, config: SlidingConfig, mu: float) -> float | None:
    """RMS [N] by which friction `mu` misses the steady windows' wrench balance (moments over the face's half
    diagonal): the pushing wrench predicted from the measured motion, where a force-driven replay of a slow
    push cannot predict the motion. None without a steady window."""
    balance = _balance_rows(windows, body, config)
    if balance is None:
        return None
    X, y = balance
    return float(np.sqrt(np.mean((y - mu * X) ** 2)))


def _pushing_moment(windows: PushWindows) -> tuple[np.ndarray, np.ndarray]:
    """Per window, the mean moment of the pushing force about the measured COM [N m], and the mean of its size."""
    com = np.repeat(windows.measured[:-1, :, :2], windows.substeps, axis=0)
    arm, f = windows.contact - com, windows.window_force
    moment = arm[..., 0] * f[..., 1] - arm[..., 1] * f[..., 0]
    return moment.mean(axis=0), np.abs(moment).mean(axis=0)


@dataclass(frozen=True)
class TurnCheck:
    """Result of `turn_check`, per window: the turn [rad], the pushing moment and the mean friction moment the
    turn requires [N m], whether friction would have to drive the turn (no mu explains the window at the
    body's I_zz), and the I_zz at which the required friction moment is zero [kg m^2] (an I_zz beyond it, the
    other way from the body's, would let friction oppose the turn; inf where none would)."""

    turn_rad: np.ndarray
    pushing_nm: np.ndarray
    friction_nm: np.ndarray
    drives_turn: np.ndarray
    izz_balance_kgm2: np.ndarray


def turn_check(windows: PushWindows, body: PlanarBody, config: SlidingConfig, margin: float = 0.1) -> TurnCheck:
    """Whether each window's turn can come from its pushing moment at any friction coefficient.

    Over a window the friction moment about the COM is the change of angular momentum less the pushing moment.
    Coulomb friction under a pressure symmetric about the COM opposes the turn at every instant (the unit-slip
    map is monotone: the friction moments of the points r and -r sum against the rotation), so in a window in
    which the object turns one way and the required friction moment has the turn's sign, by more than `margin`
    of the mean pushing moment's size, no mu explains it: the pushing moment's arm (contact point, force
    direction), the COM or the pressure's symmetry is off. "Turns one way": each third of the window turns the
    way the whole does, which turns ten times the heading's scatter about a quadratic in time (an object that
    does not turn can hold any moment below its friction's).
    """
    yaw = windows.measured[..., 2]
    turn = yaw[-1] - yaw[0]
    scatter = scatter_about_quadratic(yaw)
    one_way = np.all([np.sign(yaw[b] - yaw[a]) == np.sign(turn) for a, b in window_thirds(len(yaw))], axis=0)
    pushing, size = _pushing_moment(windows)
    spin_up = (_end_twist(windows, config)[:, 2] - windows.start[:, 5]) / windows.span_s
    friction = body.izz_kgm2 * spin_up - pushing
    drives = one_way & (np.abs(turn) >= 10 * scatter) & (friction * np.sign(turn) > margin * size)
    with np.errstate(divide="ignore", invalid="ignore"):
        balance = np.where(pushing / spin_up > 0, pushing / spin_up, np.inf)
    return TurnCheck(turn, pushing, friction, drives, balance)


def _balance_rows(windows: PushWindows, body: PlanarBody, config: SlidingConfig):
    """Per steady window, the friction wrench per unit mu (X) and the momentum change less the pushing wrench
    (y), world x, y [N] and the moment over the face's half diagonal [N]; None without a steady window."""
    hx, hy, _ = body.half_extents_m
    grid = support_points(body, config)
    normal_n = body.mass_kg * GRAVITY_M_S2 / len(grid)
    lever_m = float(np.hypot(hx, hy))
    span_s = windows.span_s
    steady = np.flatnonzero(steady_windows(windows, body, config))
    if not len(steady):
        return None
    ends = _end_twist(windows, config)
    moments, _ = _pushing_moment(windows)
    rows, targets = [], []
    for w in steady:
        m = windows.measured[:, w]
        v, omega = (m[-1, :2] - m[0, :2]) / span_s, (m[-1, 2] - m[0, 2]) / span_s
        yaw = 0.5 * (m[0, 2] + m[-1, 2])
        c, s_ = np.cos(yaw), np.sin(yaw)
        r = grid @ np.array([[c, s_], [-s_, c]])  # support points about the COM, world axes
        slip = v[None] + omega * np.c_[-r[:, 1], r[:, 0]]
        u = slip / np.maximum(np.linalg.norm(slip, axis=1), 1e-12)[:, None]
        friction = np.r_[-normal_n * u.sum(0), -normal_n * np.sum(r[:, 0] * u[:, 1] - r[:, 1] * u[:, 0]) / lever_m]
        start, end = windows.start[w, 3:6], ends[w]
        f = windows.window_force[:, w]
        change = np.r_[body.mass_kg * (end[:2] - start[:2]), body.izz_kgm2 * (end[2] - start[2]) / lever_m] / span_s
        rows.append(friction)
        targets.append(change - np.r_[f.mean(0), moments[w] / lever_m])
    return np.asarray(rows), np.asarray(targets)


def measured_friction(fit: SlidingFit, balance: WrenchBalance | None) -> tuple[float, float, str] | None:
    """mu, its standard deviation and what measured it; None when neither the sliding fit nor the wrench
    balance measured it.

    The sliding fit, where it determined mu and its simulation slides in at least as many windows as the
    balance has steady ones. Else the balance: a fit that sticks throughout only bounds mu, and one that slides
    in fewer windows than the object slid steadily reads mu from the few at its stick-slip threshold, where
    the balance reads it from every steady window (a quasi-static push: the MIT rect1 on delrin slid steadily
    in 5 windows, the fit slid in 1 and read mu 15 % above the balance's 0.308)."""
    steady = len(balance.per_window) if balance is not None else 0
    if fit.determined[0] and fit.sliding_windows >= steady:
        return float(fit.theta[0]), float(fit.std[0]), "sliding fit"
    if balance is not None:
        return balance.mu, balance.std, "wrench balance"
    return None
