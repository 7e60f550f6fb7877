"""Identification: parameterisation, tape gradients, least squares and Newton recovery on synthetic truth."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from assets import Inertial, Pose
from pipelines.identify import IdentifyConfig, InertialBounds, identify_free_body, identify_least_squares, make_windows
from pipelines.identify.inertia import physical_from_theta, theta_from_physical
from pipelines.identify.rollout import FreeBodyRollout
from pipelines.synth.held import HeldMotionConfig, SensorNoise, measure, simulate_held

MASS = 0.02
INERTIA = np.diag([4.0e-6, 5.3e-6, 6.1e-6])
GRASP = Pose((0.0, 0.0, 0.02), (1.0, 0.0, 0.0, 0.0))
NO_NOISE = SensorNoise(0, 0, 0, 0, 0, 0)


@pytest.fixture(scope="module")
def recording():
    """A 2.5 s noise-free held motion of a 20 g body, wrench in world axes about the grasp."""
    truth = Inertial(MASS, (0.001, -0.002, 0.0), INERTIA)
    motion = simulate_held(truth, Pose((0.5, 0.0, 0.02)), GRASP, HeldMotionConfig(duration_s=2.5, substeps=4),
                           np.random.default_rng(3))
    tp, pos, quat, tw, f, tq = measure(motion, NO_NOISE, np.random.default_rng(0))
    rot = Slerp(tp, Rotation.from_quat(quat))(np.clip(tw, tp[0], tp[-1]))
    return truth, (tp, pos, quat, tw, rot.apply(f), rot.apply(tq))


def test_log_cholesky_round_trip_and_always_physical():
    """theta <-> (m, c, I) round-trips, and any theta gives a physical body."""
    theta = theta_from_physical(MASS, [0.001, 0.002, -0.003], INERTIA)
    m, c, I = physical_from_theta(theta)
    assert m == pytest.approx(MASS, rel=1e-12)
    np.testing.assert_allclose(I, INERTIA, rtol=1e-10, atol=1e-18)
    rng = np.random.default_rng(0)
    for _ in range(200):
        m, c, I = physical_from_theta(rng.normal(0, 2, 10))
        assert Inertial(m, c, I).physical_violation() is None


def test_a_link_without_a_joint_moves_as_a_free_jointed_body(recording, monkeypatch):
    """The rollouts build their bodies as links: SemiImplicit must move them bit for bit as it moves add_body's
    free-jointed bodies (residuals and tape gradients equal), since the joint only costs launches."""
    import newton

    truth, data = recording
    windows = make_windows(*data, window_s=0.05, substeps=5, t_begin_s=1.0, t_end_s=1.2)
    theta = theta_from_physical(1.3 * MASS, truth.com, 1.2 * INERTIA)[None]
    weight = np.full((windows.sample_count, 6), 1.0)
    link = FreeBodyRollout(windows, GRASP.inverse())
    assert link.model.joint_count == 0
    add_link = newton.ModelBuilder.add_link

    def add_free_jointed(builder, **body):  # what add_body does
        link = add_link(builder, **body)
        builder.add_articulation([builder.add_joint_free(child=link)])
        return link

    monkeypatch.setattr(newton.ModelBuilder, "add_link", add_free_jointed)
    jointed = FreeBodyRollout(windows, GRASP.inverse())
    assert jointed.model.joint_count == windows.window_count
    np.testing.assert_array_equal(link.residuals(theta), jointed.residuals(theta))
    for a, b in zip(link.loss_and_grad(theta, None, None, weight, True),
                    jointed.loss_and_grad(theta, None, None, weight, True)):
        np.testing.assert_array_equal(a, b)


def test_parameter_sets_run_side_by_side(recording):
    """Three parameter sets in one rollout give each set's own residuals, loss and gradient; a forward-only
    rollout (two alternating states) gives the same residuals."""
    truth, data = recording
    windows = make_windows(*data, window_s=0.05, substeps=5, t_begin_s=1.0, t_end_s=1.3)
    thetas = np.stack([theta_from_physical(f * MASS, truth.com, f * INERTIA) for f in (0.8, 1.0, 1.4)])
    weight = np.full((windows.sample_count, 6), 1.0)
    batch = FreeBodyRollout(windows, GRASP.inverse(), sets=3)
    single = FreeBodyRollout(windows, GRASP.inverse())
    together = batch.residuals(thetas)
    forward_only = FreeBodyRollout(windows, GRASP.inverse(), sets=3, requires_grad=False).residuals(thetas)
    np.testing.assert_allclose(forward_only, together, rtol=1e-6, atol=1e-12)
    loss, grad, _, _ = batch.loss_and_grad(thetas, None, None, weight, True)
    for k in range(3):
        alone = single.residuals(thetas[k:k + 1])[:, 0]
        np.testing.assert_allclose(together[:, k], alone, rtol=1e-5, atol=1e-9)
        loss_k, grad_k, _, _ = single.loss_and_grad(thetas[k:k + 1], None, None, weight, True)
        assert loss[k] == pytest.approx(loss_k[0], rel=1e-5)
        np.testing.assert_allclose(grad[k], grad_k[0], rtol=1e-4, atol=1e-6 * np.abs(grad_k).max())
    assert not np.allclose(together[:, 0], together[:, 2])


def test_least_squares_recovers_noise_free_truth(recording):
    """The Newton-Euler regressor recovers mass, COM and inertia from clean data."""
    truth, data = recording
    result = identify_least_squares(*data, GRASP.inverse(), t_begin_s=0.5)
    assert result.inertial.mass == pytest.approx(MASS, rel=5e-3)
    np.testing.assert_allclose(result.inertial.com, truth.com, atol=3e-4)
    np.testing.assert_allclose(np.diag(result.inertial.inertia_matrix()), np.diag(INERTIA), rtol=0.03)


def test_newton_recovers_mass_from_far_guesses(recording):
    """Started at once from 2.5x mass and 2x inertia, and from 0.4x and 0.6x, the Newton fit lands within 1 % and
    5 %; every start lowers its loss."""
    truth, data = recording
    windows = make_windows(*data, window_s=0.1, substeps=5, t_begin_s=0.4)
    starts = [Inertial(2.5 * MASS, (0.0, 0.0, 0.0), 2.0 * INERTIA), Inertial(0.4 * MASS, (0.0, 0.0, 0.0), 0.6 * INERTIA)]
    bounds = InertialBounds((0.002, -0.02, -0.02, -0.02, 1e-7, 1e-7, 1e-7), (0.2, 0.02, 0.02, 0.02, 1e-4, 1e-4, 1e-4))
    result = identify_free_body(windows, GRASP.inverse(), starts, bounds, IdentifyConfig())
    assert result.inertial.mass == pytest.approx(MASS, rel=0.01)
    np.testing.assert_allclose(np.diag(result.inertial.inertia_matrix()), np.diag(INERTIA), rtol=0.05)
    assert result.loss_history[-1] < result.loss_history[0]
    assert len(result.start_losses) == 2 and max(result.start_losses) < 1e-2 * result.loss_history[0]
    assert np.all(result.std > 0)


def test_noise_levels_are_read_from_the_recording():
    """Tracker and wrench noise estimated from the data land within 10 % of what the sensors were given."""
    from pipelines.identify.noise import estimate_noise_levels

    truth = Inertial(MASS, (0.0, 0.0, 0.0), INERTIA)
    motion = simulate_held(truth, Pose((0.5, 0.0, 0.02)), GRASP, HeldMotionConfig(duration_s=2.0, substeps=2),
                           np.random.default_rng(5))
    noise = SensorNoise(force_resolution_n=0.0, torque_resolution_nm=0.0)
    tp, pos, quat, tw, f, tq = measure(motion, noise, np.random.default_rng(1))
    levels = estimate_noise_levels(tp, pos, quat, tw, f, tq)
    assert levels.position_m == pytest.approx(noise.position_sigma_m, rel=0.1)
    assert levels.rotation_rad == pytest.approx(noise.rotation_sigma_rad, rel=0.1)
    assert levels.force_n == pytest.approx(noise.force_sigma_n, rel=0.1)
    assert levels.torque_nm == pytest.approx(noise.torque_sigma_nm, rel=0.1)


def test_paper_optimizer_descends_toward_the_truth(recording):
    """RigPI's own scheme (1/100-scale steps on the plain pose loss) lowers the loss and moves the mass toward truth."""
    truth, data = recording
    windows = make_windows(*data, window_s=0.1, substeps=5, t_begin_s=0.4)
    start = Inertial(1.3 * MASS, (0.0, 0.0, 0.0), 1.3 * INERTIA)
    bounds = InertialBounds((0.002, -0.02, -0.02, -0.02, 1e-7, 1e-7, 1e-7), (0.2, 0.02, 0.02, 0.02, 1e-4, 1e-4, 1e-4))
    result = identify_free_body(windows, GRASP.inverse(), [start], bounds,
                                IdentifyConfig(optimizer="paper", paper_iterations=40))
    assert min(result.loss_history) < 0.5 * result.loss_history[0]
    assert abs(result.inertial.mass / MASS - 1) < 0.15


def test_clustered_covariance_spans_low_passed_residuals():
    """Rows low-passed at 8 Hz on a 200 Hz grid, as a jointed part's least squares has them: clustered in
    0.3 s blocks the covariance matches the spread over 300 noise draws within 15 %, where sigma^2 (A^T A)^-1
    reports about a third of it."""
    from pipelines.identify.windows import clustered_covariance, lowpass

    rng = np.random.default_rng(3)
    t = np.arange(0.0, 8.0, 1 / 200)
    A = np.stack([np.sin(2 * np.pi * 0.7 * t), np.cos(2 * np.pi * 1.1 * t), np.ones_like(t)], 1)
    bread = np.linalg.pinv(A.T @ A)
    block = np.floor(t / 0.3).astype(int)
    estimates, clustered, naive = [], [], []
    for _ in range(300):
        b = A @ [1.0, -0.5, 0.2] + lowpass(rng.normal(0, 1, len(t)), 8.0, 200.0)
        x = bread @ A.T @ b
        r = b - A @ x
        scores = np.stack([A[block == g].T @ r[block == g] for g in range(block.max() + 1)])
        estimates.append(x)
        clustered.append(np.sqrt(np.diag(clustered_covariance(bread, scores))))
        naive.append(np.sqrt(np.diag(r @ r / (len(t) - 3) * bread)))
    spread = np.std(estimates, axis=0, ddof=1)
    np.testing.assert_allclose(np.mean(clustered, axis=0), spread, rtol=0.15)
    assert np.all(np.mean(naive, axis=0) < 0.5 * spread)
