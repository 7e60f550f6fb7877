"""Diagnose on a joint: concealed joint effects found through Newton."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.diagnose import Case, record_joint_case, true_joint_model_fit
from pipelines.diagnose import DiagnoseConfig, diagnose_jointed
from pipelines.synth.effects import concealed_joint_effect
from pipelines.synth.held import SensorNoise
from pipelines.synth.jointed import jointed_paper_objects


def test_concealed_door_spring_named_and_quantified(tmp_path):
    """A door closer (spring 3x the effort noise) hidden in 3 s recordings of the cabinet door is named, its
    stiffness within 15 % and its rest angle within 0.1 rad, and the held-out replay error falls."""
    obj = jointed_paper_objects()["cabinet_door"]
    effect = concealed_joint_effect("spring", 3.0, np.random.default_rng(3), obj, SensorNoise())
    trial, holdout, joint, placement, prior = record_joint_case(Case("cabinet_door", effect, 3.0, 3), tmp_path, 3.0)
    diagnosis, refit = diagnose_jointed([trial], holdout, joint, placement, prior, config=DiagnoseConfig(bootstraps=10))
    assert diagnosis.effects[0].name == "spring"
    params = diagnosis.effects[0].params
    # the joint found may point either way along the hinge: q and k q0 flip together
    sign = float(np.sign(np.dot(joint.axis, obj.axis)))
    assert params["k"] == pytest.approx(effect.params["k"], rel=0.15)
    assert sign * params["q0"] == pytest.approx(effect.params["q0"], abs=0.1)
    assert refit is not None and "stiffness" in refit.names
    assert diagnosis.fits["after"].rmse_position_m < 0.5 * diagnosis.fits["before"].rmse_position_m
    # the true spring in the found joint's coordinates (q0's sign follows the axis found) replays as well
    truth = true_joint_model_fit(Case("cabinet_door", effect, 3.0, 3), holdout, joint, placement,
                                 DiagnoseConfig().joint_window_s)
    assert truth.rmse_position_m == pytest.approx(diagnosis.fits["after"].rmse_position_m, rel=0.25)


def test_weak_drawer_damping_quantified_in_diagnose_windows(tmp_path):
    """The bench's drawer with a damping 4.75x the effort noise (case 11, which came back 40 % low in 0.3 s
    windows of 4 s recordings): the Newton refit in the diagnosis's windows of its 8 s recording is within 15 %."""
    from dataclasses import replace

    from pipelines.identify.jointed import JointedConfig, identify_jointed
    from benchmarks.diagnose import make_cases

    case = make_cases(40, 10, 0)[11]
    assert (case.shape, case.effect.name) == ("drawer", "viscous_damping")
    trial, _, joint, placement, prior = record_joint_case(case, tmp_path)
    config = replace(JointedConfig(), window_s=DiagnoseConfig().joint_window_s)
    ident = identify_jointed([trial], joint, placement, prior, None, config, effects=("viscous_damping",))
    assert ident.value("damping") == pytest.approx(case.effect.params["b"], rel=0.15)


def test_friction_by_position_and_direction_localised_in_state():
    """An effort residual carrying extra friction over a stretch of q, or one way only, is localised there
    (q range, sign of q'); white noise alone gives nothing."""
    from pipelines.diagnose.residuals import localise_joint_friction

    rng = np.random.default_rng(0)
    t = np.linspace(0.0, 8.0, 4000)
    q = 0.12 + 0.11 * np.sin(2 * np.pi * 0.4 * t) + 0.01 * np.sin(2 * np.pi * 1.1 * t)
    qd = np.gradient(q, t)
    noise = rng.normal(size=len(t))
    assert localise_joint_friction(q, qd, noise, stride=4, unit="m/s", q_unit="m") == ()
    binding = noise + 1.5 * np.sign(qd) * ((q > 0.15) & (q < 0.2))
    found = localise_joint_friction(q, qd, binding, stride=4, unit="m/s", q_unit="m")
    a, b = found[0]["where"]["q"]
    assert a < 0.2 and b > 0.15 and b - a < 0.12
    directional = noise + 1.0 * (qd > 0)
    found = localise_joint_friction(q, qd, directional, stride=4, unit="m/s", q_unit="m")
    assert [u["where"]["qd"][0] >= 0 for u in found if "qd" in u["where"]] == [True]


def test_a_gravity_moment_carried_over_reads_as_no_one_way_friction(tmp_path):
    """A clean Newton-made oven door whose trial and held-out recording disagree on the gravity moment by 1.3 %
    (the bench's seed 1068): the trial's fit leaves a torque of one sign along the held-out travel, which times the
    direction of motion looks like friction higher one way. Tested with the model fitted to the held-out rows,
    nothing is there; on a cabinet door, a friction twice the noise higher one way still is."""
    from dataclasses import replace

    from pipelines.diagnose.joint import friction_patterns
    from pipelines.diagnose.residuals import localise_joint_friction
    from pipelines.identify.jointed import JointedConfig, equation_of_motion_rows, joint_body

    config = replace(JointedConfig(), window_s=DiagnoseConfig().joint_window_s)

    def rows_of(shape):
        trial, holdout, joint, placement, prior = record_joint_case(Case(shape, None, 0.0, 1068), tmp_path / shape)
        body = joint_body(joint, placement, prior, config)
        train, rows = (equation_of_motion_rows(r, joint, body, config) for r in (trial, holdout))
        stride = int(rows["rate_hz"] / (2 * config.smoothing_hz))
        own, *_ = np.linalg.lstsq(rows["columns"][::stride], rows["tau"][::stride], rcond=None)
        return train, rows, stride, own, float(np.std(rows["tau"] - rows["columns"] @ own))

    train, rows, stride, own, noise = rows_of("oven_door")
    carried, *_ = np.linalg.lstsq(train["columns"][::stride], train["tau"][::stride], rcond=None)
    assert abs(np.hypot(*carried[1:3]) / np.hypot(*own[1:3]) - 1) > 0.005
    carried_over = localise_joint_friction(rows["q"], rows["qd"], (rows["tau"] - rows["columns"] @ carried) / noise,
                                           stride=stride, unit="rad/s", q_unit="rad")
    assert any("qd" in u["where"] for u in carried_over)
    assert friction_patterns(rows, (), config, 1.0, noise, stride, "revolute") == ()

    _, rows, stride, _, noise = rows_of("cabinet_door")
    assert friction_patterns(rows, (), config, 1.0, noise, stride, "revolute") == ()
    one_way = dict(rows, tau=rows["tau"] + 2 * noise * (rows["qd"] > 0))
    found = friction_patterns(one_way, (), config, 1.0, noise, stride, "revolute")
    assert [u["where"]["qd"][0] >= 0 for u in found if "qd" in u["where"]] == [True]


def test_a_candidate_refit_ends_no_higher_than_the_base_fit_it_nests(tmp_path):
    """The bench's Newton-made oven door with a breakaway 3x its friction (case 42): fitted on its held-out
    recording, the base model's minimum (at +120 % axis inertia) lay below the Stribeck fit's from least squares,
    so the breakaway was rejected as no better an explanation. Started from the base fit too, the fit with the
    breakaway, which contains the base model, ends below it."""
    from dataclasses import replace

    from benchmarks.diagnose import make_cases
    from pipelines.identify.jointed import JointedConfig, identify_jointed

    case = make_cases(40, 10, 0)[42]
    assert (case.shape, case.effect.name) == ("oven_door", "stribeck_friction")
    _, holdout, joint, placement, prior = record_joint_case(case, tmp_path)
    # as the diagnosis fits: Newton fits compared, never swapped for least squares where the two disagree
    config = replace(JointedConfig(), fit_grip=False, disagreement_share=np.inf)
    base = identify_jointed([holdout], joint, placement, prior, None, config)
    breakaway = identify_jointed([holdout], joint, placement, prior, None, config, effects=("stribeck_friction",),
                                 nests=base)
    assert breakaway.loss_history[-1] < base.loss_history[-1]


@pytest.mark.parametrize("index", [22, 37])
def test_a_clean_part_where_it_sticks_leaves_nothing_unexplained(tmp_path, index):
    """Clean Newton-made parts of `twin bench diagnose`: a cabinet door whose reversal held 23 % of the effort
    residual (case 22, once reported) and an oven door held still for 0.16 s that held 67 % (case 37). Where a
    part sticks its friction is whatever holds it, not the smooth tanh: the residual is analysed where it moves,
    and nothing is left to report."""
    from benchmarks.diagnose import make_cases

    case = make_cases(40, 10, 0)[index]
    assert case.effect is None
    trial, holdout, joint, placement, prior = record_joint_case(case, tmp_path)
    diagnosis, _ = diagnose_jointed([trial], holdout, joint, placement, prior, config=DiagnoseConfig(bootstraps=10))
    assert diagnosis.effects == () and diagnosis.unexplained == ()
    # no stretch at all rising above the rest is the cleanest outcome
    shares = [s["share"] for s in diagnosis.residuals["after"].localisation]
    assert max(shares, default=0.0) < DiagnoseConfig().unexplained_share
