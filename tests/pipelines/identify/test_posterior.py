"""Posterior identification: the recordings' likelihood fused with the geometry prior, always physical."""

from __future__ import annotations

import numpy as np
import pytest

from assets import Inertial, Pose
from pipelines.identify.inertia import theta_from_physical
from pipelines.identify.posterior import (
    DataTerm,
    identify_posterior,
    pi_from_pseudo_inertia,
    pseudo_inertia,
    pseudo_inertia_from_pi,
    pseudo_inertia_from_theta,
)

GRASP = Pose((0.0, 0.0, 0.05), (1.0, 0.0, 0.0, 0.0))  # the object frame in the tracked frame
X_TRACKED_BODY = GRASP.inverse()


def box(mass: float, size, center=(0.0, 0.0, 0.0)) -> Inertial:
    """A uniform box [kg, m] about its centre."""
    a, b, c = size
    return Inertial(mass, center, np.diag([b * b + c * c, a * a + c * c, a * a + b * b]) * mass / 12)


def two_part_bar(rho_head: float, rho_handle: float):
    """A 2 x 2 x 20 cm bar of two 10 cm halves of the given densities [kg/m^3]: the body and each half's
    pseudo-inertia per unit density (object frame at the bar's centre)."""
    volume = 0.02 * 0.02 * 0.1
    head = box(volume, (0.02, 0.02, 0.1), (0.0, 0.0, 0.05))
    handle = box(volume, (0.02, 0.02, 0.1), (0.0, 0.0, -0.05))
    parts = np.array([pseudo_inertia(p.mass, p.com, p.inertia_matrix()) for p in (head, handle)])
    P = rho_head * parts[0] + rho_handle * parts[1]
    return body_from_pseudo_inertia(P), parts


def body_from_pseudo_inertia(P: np.ndarray) -> Inertial:
    m = P[3, 3]
    c = P[:3, 3] / m
    S = P[:3, :3] - m * np.outer(c, c)
    return Inertial(m, c, np.trace(S) * np.eye(3) - S)


def tracked_pi(body: Inertial) -> np.ndarray:
    T = X_TRACKED_BODY.matrix()
    return pi_from_pseudo_inertia(T @ pseudo_inertia(body.mass, body.com, body.inertia_matrix()) @ T.T)


def data_term(body: Inertial, std: np.ndarray, rng: np.random.Generator | None = None) -> DataTerm:
    """A recording's likelihood of `body` with independent standard deviations `std` [10] on pi (tracked frame),
    its centre drawn from them when `rng` is given."""
    pi = tracked_pi(body)
    if rng is not None:
        pi = pi + std * rng.standard_normal(10)
    return DataTerm(pi, np.diag(1.0 / std**2))


def flat(body: Inertial) -> np.ndarray:
    I = body.inertia_matrix()
    return np.array([body.mass, *body.com, I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2]])


def test_pseudo_inertia_layouts_agree():
    """theta, (mass, com, inertia) and least squares' pi give the same pseudo-inertia."""
    body = Inertial(0.3, (0.01, -0.02, 0.03), np.array([[2e-4, 1e-5, 0.0], [1e-5, 3e-4, 2e-6], [0.0, 2e-6, 4e-4]]))
    P = pseudo_inertia(body.mass, body.com, body.inertia_matrix())
    np.testing.assert_allclose(pseudo_inertia_from_theta(theta_from_physical(body.mass, body.com, body.inertia)), P,
                               rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(pseudo_inertia_from_pi(pi_from_pseudo_inertia(P)), P, atol=1e-15)
    assert body_from_pseudo_inertia(P).mass == pytest.approx(0.3)


def test_follows_the_data_where_excited_and_the_prior_where_not():
    """Strong mass and COM evidence moves them; the unexcited inertia stays at the prior's shape and is flagged."""
    truth = box(0.5, (0.05, 0.08, 0.2), (0.002, -0.003, 0.01))
    prior = box(0.8, (0.05, 0.08, 0.2))  # uniform at the material's density: 60 % heavy, COM at the centre
    std = np.array([1e-4, 1e-5, 1e-5, 1e-5] + [1.0] * 6)  # static-like: weight and COM only
    result = identify_posterior([data_term(truth, std)], X_TRACKED_BODY, prior, (0.5, 1.2))
    assert result.inertial.mass == pytest.approx(0.5, rel=1e-3)
    np.testing.assert_allclose(result.inertial.com, truth.com, atol=2e-4)
    # the shape per unit mass is the prior's: moments scale with the measured mass
    np.testing.assert_allclose(np.diag(result.inertial.inertia_matrix()),
                               np.diag(prior.inertia_matrix()) * 0.5 / 0.8, rtol=0.05)
    assert "mass" not in result.prior_dominated and {"Ixy", "Ixz", "Iyz"} <= set(result.prior_dominated)
    assert result.moved and result.inertial.physical_violation() is None


def test_matches_the_data_when_they_determine_everything():
    """With precise evidence on all ten parameters the posterior is the data's estimate and nothing is flagged."""
    truth = Inertial(0.25, (0.004, 0.0, -0.02), np.array([[9e-4, 2e-5, 0.0], [2e-5, 8e-4, 0.0], [0.0, 0.0, 3e-4]]))
    prior = box(0.3, (0.1, 0.1, 0.06))
    std = np.array([1e-6] * 4 + [1e-9] * 6)
    result = identify_posterior([data_term(truth, std)], X_TRACKED_BODY, prior, (0.1, 1.0))
    np.testing.assert_allclose(flat(result.inertial), flat(truth), rtol=1e-4, atol=1e-8)
    assert result.prior_dominated == ()
    assert np.all(result.data_share > 0.99)


def test_part_densities_explain_a_steel_head_on_a_rubber_handle():
    """Mass and COM evidence alone fix the two densities, and with them the inertia the uniform prior misses."""
    truth, parts = two_part_bar(7850.0, 1150.0)
    prior = body_from_pseudo_inertia(4500.0 * parts.sum(axis=0))  # uniform, COM at the centre
    std = np.array([1e-5, 1e-6, 1e-6, 1e-6] + [1e-3] * 6)
    uniform = identify_posterior([data_term(truth, std)], X_TRACKED_BODY, prior, (0.5, 3.0))
    with_parts = identify_posterior([data_term(truth, std)], X_TRACKED_BODY, prior, (0.5, 3.0), parts=parts)
    np.testing.assert_allclose(with_parts.densities, (7850.0, 1150.0), rtol=0.2)
    error = lambda r: abs(r.inertial.inertia_matrix()[0, 0] / truth.inertia_matrix()[0, 0] - 1)  # noqa: E731
    assert error(with_parts) < 0.1 < 0.5 < error(uniform)  # +6 % with the parts, +95 % without


def test_intervals_cover_the_truth():
    """Over 40 noise draws the 95 % intervals of the flat parameters hold the truth at least 90 % of the time."""
    truth, parts = two_part_bar(7850.0, 1150.0)
    prior = body_from_pseudo_inertia(4500.0 * parts.sum(axis=0))
    pi = tracked_pi(truth)
    std = np.abs(pi) * np.array([1e-3, 2e-2, 2e-2, 2e-3] + [0.3] * 6) + 1e-9
    rng = np.random.default_rng(7)
    covered = []
    for _ in range(40):
        result = identify_posterior([data_term(truth, std, rng)], X_TRACKED_BODY, prior, (0.5, 3.0), parts=parts)
        lo, hi = result.interval95()
        covered.append((flat(truth) >= lo) & (flat(truth) <= hi))
    assert np.mean(covered) >= 0.9


def test_never_raises_and_says_what_it_did():
    """No information, non-finite information and an unphysical extra start still give a physical body."""
    prior = box(0.4, (0.05, 0.05, 0.1))
    empty = DataTerm(np.zeros(10), np.zeros((10, 10)))
    result = identify_posterior([empty], X_TRACKED_BODY, prior, (0.2, 0.8))
    np.testing.assert_allclose(flat(result.inertial), flat(prior), rtol=1e-6, atol=1e-12)
    assert set(result.prior_dominated) == {"mass", "com_x", "com_y", "com_z", "Ixx", "Iyy", "Izz", "Ixy", "Ixz",
                                           "Iyz"}
    broken = DataTerm(np.full(10, np.nan), np.full((10, 10), np.inf))
    unphysical = Inertial(0.4, (0.0, 0.0, 0.0), np.diag([1e-4, 1e-4, 5e-4]))  # breaks the triangle inequality
    result = identify_posterior([broken], X_TRACKED_BODY, prior, (0.2, 0.8), extra_starts={"ls": unphysical})
    assert result.inertial.physical_violation() is None and "ls" not in result.start_costs
    assert "prior" in result.message


def held_recording(path, body: Inertial, grasp: Pose, duration_s: float, rng: np.random.Generator):
    """A held body turned and moved by smooth sinusoids, its wrench from the Newton-Euler equations (no
    simulation), 200 Hz poses and 1 kHz wrench with an ATI-class sensor's noise, written as MCAP and read back."""
    from scipy.spatial.transform import Rotation

    from assets.conventions import GRAVITY_M_S2
    from assets.recording import PoseTrack, WrenchTrack
    from pipelines.identify.least_squares import newton_euler_regressor
    from pipelines.logs import read_recording
    from pipelines.synth.recording import write_recording

    freq = np.array([[0.7, 1.1, 1.6], [0.9, 1.3, 0.5]])  # [Hz] per axis: translation, rotation
    amp = np.array([[0.05, 0.04, 0.03], [0.9, 0.8, 1.0]])  # [m], [rad]

    def pose(t):
        s = np.sin(2 * np.pi * freq[:, None, :] * t[None, :, None]) * amp[:, None, :]  # [2, N, 3]
        return s[0] + np.array([0.5, 0.0, 0.3]), Rotation.from_rotvec(s[1])

    t_w = np.arange(0.0, duration_s, 1e-3)
    h = 1e-4
    (p0, R0), (p1, R1), (pm, Rm) = pose(t_w), pose(t_w + h), pose(t_w - h)
    acc = (p1 - 2 * p0 + pm) / h**2
    omega = (R1 * Rm.inv()).as_rotvec() / (2 * h)
    omega_next = (pose(t_w + 2 * h)[1] * R0.inv()).as_rotvec() / (2 * h)
    omega_prev = (R0 * pose(t_w - 2 * h)[1].inv()).as_rotvec() / (2 * h)
    alpha = (omega_next - omega_prev) / (2 * h)
    inv = R0.inv()
    A = newton_euler_regressor(inv.apply(acc - GRAVITY_M_S2), inv.apply(omega), inv.apply(alpha))
    wrench = A @ tracked_pi_of(body, grasp)  # in tracked axes about its origin
    noise = np.array([1 / 80] * 3 + [1 / 2000] * 3)
    wrench = wrench + noise * rng.standard_normal(wrench.shape)
    t_p = np.arange(0.0, duration_s, 5e-3)
    position, rotation = pose(t_p)
    position = position + 2e-4 * rng.standard_normal(position.shape)
    quat = (rotation * Rotation.from_rotvec(2e-3 * rng.standard_normal((len(t_p), 3)))).as_quat()
    write_recording(path, pose=PoseTrack(t_p, position, quat, "world", "gripper", "/tracker/pose"),
                    wrench=WrenchTrack(t_w, wrench[:, :3], wrench[:, 3:], "/ft_sensor/wrench", "gripper"))
    return read_recording(path)


def tracked_pi_of(body: Inertial, grasp: Pose) -> np.ndarray:
    """pi of `body` in the tracked (grasp) frame, `grasp` the tracked frame in the object frame."""
    T = grasp.inverse().matrix()
    return pi_from_pseudo_inertia(T @ pseudo_inertia(body.mass, body.com, body.inertia_matrix()) @ T.T)


def test_identify_held_keeps_the_posterior_and_says_why(tmp_path):
    """A noisy 4 s held recording: identify_held keeps the physical posterior near the truth and says why."""
    from pipelines.identify import IdentifyConfig, InertialBounds, identify_held

    truth = box(0.05, (0.03, 0.04, 0.05), (0.002, 0.0, -0.003))
    grasp = Pose((0.0, 0.0, 0.025), (1.0, 0.0, 0.0, 0.0))
    recording = held_recording(tmp_path / "held.mcap", truth, grasp, 4.0, np.random.default_rng(2))
    prior = box(0.08, (0.03, 0.04, 0.05))  # the material's density guessed 60 % high
    bounds = InertialBounds((0.04, -0.015, -0.02, -0.025, 1e-6, 1e-6, 1e-6), (0.16, 0.015, 0.02, 0.025, 1e-4, 1e-4, 1e-4))
    held = identify_held([recording], None, grasp.inverse(), prior, bounds, IdentifyConfig(), method="ls")
    assert held.selected == "posterior" and held.choice.startswith("posterior")
    assert held.inertial.mass == pytest.approx(0.05, rel=0.01)
    np.testing.assert_allclose(held.inertial.com, truth.com, atol=5e-4)
    np.testing.assert_allclose(np.diag(held.inertial.inertia_matrix()), np.diag(truth.inertia_matrix()), rtol=0.1)
    assert held.provenance()["posterior"]["start"] in ("prior", "least_squares")
    assert "posterior" in held.fits and held.inertial.physical_violation() is None
