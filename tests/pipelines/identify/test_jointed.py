"""Jointed parts identified through Newton's Featherstone solver from MCAP recordings of synth truth."""

from pathlib import Path

import numpy as np
import pytest

from assets.materials import material_range
from benchmarks.paper_jointed import jointed_truth
from pipelines.identify.jointed import identify_jointed, joint_effort
from pipelines.identify.kind import detect_kind
from pipelines.logs import read_recording
from pipelines.priors import uniform_density_prior
from pipelines.synth.held import SensorNoise
from pipelines.synth.jointed import (
    JointedMotionConfig, JointedObject, jointed_paper_objects, simulate_jointed, write_jointed_recording,
)


def _recording(tmp_path: Path, name: str, seed: int, duration_s: float = 3.0):
    obj = jointed_paper_objects()[name]
    rng = np.random.default_rng(seed)
    motion = simulate_jointed(obj, JointedMotionConfig(duration_s=duration_s), rng)
    return obj, motion, read_recording(write_jointed_recording(tmp_path / f"{name}.mcap", obj, motion, SensorNoise(), rng))


def test_drawer_mass_and_friction_from_a_recording(tmp_path: Path):
    """From a prior 30 % off, the drawer's mass comes back within 3 % and its joint friction within 5 %,
    with a standard deviation that is positive and small; the joint and its encoder agree."""
    obj, motion, recording = _recording(tmp_path, "drawer", 0)
    joint = detect_kind(recording).joint
    assert joint.type == "prismatic"
    np.testing.assert_allclose(joint.q, recording.joints.position[:, 0], atol=2e-3)
    prior = uniform_density_prior(obj.mesh(), material_range(None)).inertial
    prior = type(prior)(0.7 * obj.mass_kg, prior.com, prior.inertia)
    result = identify_jointed([recording], joint, obj.placement(), prior)
    assert result.names == ("mass", "friction", "friction_lag") and result.selected == "newton"
    assert result.value("mass") == pytest.approx(obj.mass_kg, rel=0.03)
    assert result.value("friction") == pytest.approx(obj.friction, rel=0.05)
    assert 0 < result.std("mass") < 0.01 * obj.mass_kg
    assert result.loss_history[-1] <= result.loss_history[0]


def test_cabinet_door_inertia_about_its_axis(tmp_path: Path):
    """A vertical door: the inertia about the hinge within 5 % and the friction within 5 %; its mass cannot be
    seen, so the body keeps the prior's mass and no gravity moment is fitted."""
    obj, _, recording = _recording(tmp_path, "cabinet_door", 1)
    joint = detect_kind(recording).joint
    assert joint.type == "revolute"
    prior = uniform_density_prior(obj.mesh(), material_range(None)).inertial
    result = identify_jointed([recording], joint, obj.placement(), prior)
    truth = jointed_truth(obj)
    assert result.names == ("axis_inertia", "friction", "friction_lag")
    assert result.value("axis_inertia") == pytest.approx(truth["axis_inertia"], rel=0.05)
    assert result.value("friction") == pytest.approx(obj.friction, rel=0.05)
    assert result.inertial.mass == prior.mass
    a = joint.axis
    I = result.inertial.inertia_matrix()
    r = np.asarray(obj.placement().position) + result.inertial.com - joint.origin
    assert a @ I @ a + prior.mass * np.sum(np.cross(a, r) ** 2) == pytest.approx(result.value("axis_inertia"), rel=1e-6)


def test_joint_effort_is_the_wrench_projected_on_the_joint(tmp_path: Path):
    """The handle wrench projected on the hinge equals what the simulation applied to the joint, up to sensor noise."""
    obj, motion, recording = _recording(tmp_path, "oven_door", 2, duration_s=2.0)
    joint = detect_kind(recording).joint
    t, tau = joint_effort(recording, joint)
    a = np.asarray(obj.axis) * np.sign(joint.axis @ obj.axis)
    lever = np.asarray(motion.held.grasp_position_m)[::4][: len(t)] - obj.origin_m
    expected = (np.cross(lever, motion.held.force_n) + motion.held.torque_nm) @ a
    assert np.sqrt(np.mean((tau - expected) ** 2)) < 3e-3


def test_mujoco_drawer_mass_and_friction(tmp_path: Path):
    """A drawer MuJoCo recorded (frictionloss, a soft constraint that holds the drawer below breakaway) comes back
    with its mass within 3 % and its joint friction within 5 %."""
    from pipelines.synth.mujoco_engine import simulate_jointed_mujoco

    obj = jointed_paper_objects()["drawer"]
    rng = np.random.default_rng(1)
    motion = simulate_jointed_mujoco(obj, JointedMotionConfig(duration_s=4.0), rng)
    recording = read_recording(write_jointed_recording(tmp_path / "drawer.mcap", obj, motion, SensorNoise(), rng))
    joint = detect_kind(recording).joint
    prior = uniform_density_prior(obj.mesh(), material_range(None)).inertial
    prior = type(prior)(0.7 * obj.mass_kg, prior.com, prior.inertia)
    result = identify_jointed([recording], joint, obj.placement(), prior)
    assert abs(result.value("mass") / obj.mass_kg - 1) < 0.03
    assert abs(result.value("friction") / obj.friction - 1) < 0.05


def test_mujoco_frictions_grip_lag_is_measured_and_newtons_rigid_grip_kept(tmp_path: Path):
    """MuJoCo's frictionloss grips with a lag (q'' = -105 q' at its default solref: 9.5 ms); fitted with it, a MuJoCo
    oven door's inertia about the hinge comes back within 3 % (3-4.5 % high with a rigid grip). The grip found
    holds the truth within 2.5 standard errors on MuJoCo's soft friction and on Newton's rigid one, and the
    Newton-made door's inertia is within the 5 % a door's must be (this draw: -3.0 %, which had sat on a 3 %
    bound and failed it on one machine)."""
    from pipelines.synth.mujoco_engine import simulate_jointed_mujoco

    obj = jointed_paper_objects()["oven_door"]
    prior = uniform_density_prior(obj.mesh(), material_range(None)).inertial
    for simulate, grip_s, within in ((simulate_jointed_mujoco, 1 / 105.3, 0.03), (simulate_jointed, None, 0.05)):
        rng = np.random.default_rng(4)
        motion = simulate(obj, JointedMotionConfig(duration_s=8.0), rng)
        recording = read_recording(write_jointed_recording(tmp_path / "door.mcap", obj, motion, SensorNoise(), rng))
        result = identify_jointed([recording], detect_kind(recording).joint, obj.placement(), prior)
        assert result.value("axis_inertia") == pytest.approx(jointed_truth(obj)["axis_inertia"], rel=within)
        assert result.doubtful == ()  # clean: the Newton fit and least squares agree
        assert abs(result.friction_grip_s() - (grip_s or result.step_s)) < 2.5 * result.std("friction_lag")


def test_least_squares_reads_a_joint_where_it_moves(tmp_path: Path):
    """A breakaway 7x the joint's friction, which no base model has, pulls a least squares over every row to an
    oven door's inertia about the hinge +20-33 % (MuJoCo-made): the effort it takes at each reversal correlates
    with q''. Over the rows where the door moves (`moving_rows`) least squares reads it within 5 %."""
    from pipelines.identify.jointed import equation_of_motion_rows, joint_body, moving_rows, JointedConfig
    from pipelines.synth.held import ConcealedEffect
    from pipelines.synth.mujoco_engine import simulate_jointed_mujoco

    obj = jointed_paper_objects()["oven_door"]
    rng = np.random.default_rng(5)
    breakaway = ConcealedEffect("stribeck_friction", {"f_s": 7 * obj.friction, "f_c": obj.friction, "v_s": 0.1})
    motion = simulate_jointed_mujoco(obj, JointedMotionConfig(duration_s=8.0), rng, effect=breakaway)
    recording = read_recording(write_jointed_recording(tmp_path / "door.mcap", obj, motion, SensorNoise(), rng))
    joint = detect_kind(recording).joint
    prior = uniform_density_prior(obj.mesh(), material_range(None)).inertial
    truth = jointed_truth(obj)["axis_inertia"]
    rows = equation_of_motion_rows(recording, joint, joint_body(joint, obj.placement(), prior), JointedConfig())
    every_row = np.linalg.lstsq(rows["columns"], rows["tau"], rcond=None)[0][0]
    assert every_row > 1.1 * truth  # the fault the rows guard against is in this recording
    result = identify_jointed([recording], joint, obj.placement(), prior)
    assert result.least_squares["axis_inertia"]["value"] == pytest.approx(truth, rel=0.05)
    moving = moving_rows(rows, JointedConfig().least_squares_min_speed)
    assert len(moving["tau"]) > 0.6 * len(rows["tau"])


@pytest.mark.parametrize("with_holdout", [False, True])
def test_a_force_no_model_has_marks_the_body_doubtful_and_least_squares_is_kept(tmp_path: Path, with_holdout: bool):
    """A damping on a MuJoCo-made oven door, left out of the model (`twin bench diagnose --engine mujoco` case 41):
    the Newton fit bends the door's inertia about the hinge 40 % and more to replay its windows, least squares over
    the rows where it moves stays within 5 %. The two disagree, so the quantity is doubtful and least squares is
    kept; a held-out recording cannot judge them, the damping acting there too (the Newton fit replays it better)."""
    from benchmarks.diagnose_cases import determined_quantity, make_mujoco_cases, record_mujoco_joint_case, true_body
    from pipelines.identify.jointed import JointedConfig

    case = make_mujoco_cases(40, 10, 0)[41]
    assert case.effect.name == "viscous_damping" and case.shape == "oven_door"
    trial, holdout, joint, placement, prior = record_mujoco_joint_case(case, tmp_path)
    result = identify_jointed([trial], joint, placement, prior, holdout if with_holdout else None)
    assert result.disagreement["axis_inertia"] > JointedConfig().disagreement_share
    # the gravity moment sits on the threshold (10.3 % apart): flagged or not, nothing else may be
    assert result.doubtful[0] == "axis_inertia" and set(result.doubtful) <= {"axis_inertia", "gravity_moment"}
    assert result.selected == "least_squares"
    truth = determined_quantity(case, true_body(case))
    assert determined_quantity(case, result.inertial) == pytest.approx(truth, rel=0.05)


@pytest.mark.parametrize("seed", [2, 5])
def test_the_equation_of_motion_rows_stop_short_of_where_the_low_pass_rings(tmp_path: Path, seed: int):
    """A recording cut while the door swings: q'' from the zero-phase low-passed q and the low-passed effort ring
    near the cut. With the true body, the rows' last 0.1 s fit as well as the rows within, as the diagnosis reads
    them (20 samples trimmed left 2-3x the residual there, read as an unexplained stretch at the recording's end)."""
    from pipelines.identify.jointed import JointedConfig, equation_of_motion_rows, joint_body

    obj, _, recording = _recording(tmp_path, "cabinet_door", seed)
    joint = detect_kind(recording).joint
    prior = uniform_density_prior(obj.mesh(), material_range(None)).inertial
    rows = equation_of_motion_rows(recording, joint, joint_body(joint, obj.placement(), prior), JointedConfig())
    residual = rows["tau"] - rows["columns"] @ [jointed_truth(obj)["axis_inertia"], obj.friction]
    n = int(0.1 * rows["rate_hz"])
    assert abs(rows["qd"][-1]) > 0.5  # cut mid-swing [rad/s]
    within = residual[n:-n][np.abs(rows["qd"][n:-n]) > 0.3 * np.sqrt(np.mean(rows["qd"] ** 2))]
    assert np.sqrt(np.mean(residual[-n:] ** 2)) < 1.5 * np.sqrt(np.mean(within ** 2))


def test_a_recording_too_short_for_the_rows_is_refused_by_name(tmp_path: Path):
    """0.35 s of motion, less than the rows' two trimmed ends: one ValueError naming the file, not an empty fit."""
    obj, _, recording = _recording(tmp_path, "drawer", 0, duration_s=0.75)
    prior = uniform_density_prior(obj.mesh(), material_range(None)).inertial
    with pytest.raises(ValueError, match=r"drawer\.mcap: too short"):
        identify_jointed([recording], detect_kind(recording).joint, obj.placement(), prior)


def test_a_heavy_doors_friction_is_not_read_from_its_gravity_load_out_of_time(tmp_path: Path):
    """A wrench stamped t acted at t (DESIGN.md); a sensor's reading is its period's mean, stamped at the mean time
    of what it averages. On a 2.5 kg oven door, whose gravity moment (4.3 N m) changes by 4.3 N m per radian, an
    effort that reaches the rollout out of time reads as a torque along or against the motion. Made by MuJoCo at a
    0.125 ms step (near continuous time), the door's 0.15 N m friction came back 7 % high with each reading held
    from its stamp (half a period late), 3 % low with each Featherstone step taking the effort at its centre (half
    a step early for semi-implicit Euler), and 0.7 % high taken at its start (0.7 % at MuJoCo's 0.5 ms step too)."""
    from pipelines.synth.mujoco_engine import MujocoSettings, simulate_jointed_mujoco

    size = (0.5, 0.02, 0.35)
    obj = JointedObject(name="oven_door", joint_type="revolute", size_m=size, mass_kg=2.5,
                        position_m=(0.55, -0.1, 0.3), axis=(1.0, 0.0, 0.0),
                        origin_m=(0.55, -0.11, 0.3 - size[2] / 2), handle_m=(0.0, -size[1] / 2, size[2] / 2 - 0.03),
                        friction=0.15, travel=(-1.2, 0.0))
    rng = np.random.default_rng(2002)
    motion = simulate_jointed_mujoco(obj, JointedMotionConfig(), rng, MujocoSettings(substeps=16))
    recording = read_recording(write_jointed_recording(tmp_path / "door.mcap", obj, motion, SensorNoise(),
                                                       np.random.default_rng(0)))
    prior = uniform_density_prior(obj.mesh(), material_range(None)).inertial
    result = identify_jointed([recording], detect_kind(recording).joint, obj.placement(), prior)
    assert result.value("friction") == pytest.approx(obj.friction, rel=0.02)
    assert result.value("axis_inertia") == pytest.approx(jointed_truth(obj)["axis_inertia"], rel=0.05)
