"""Diagnose on a joint: concealed joint effects found through Newton."""

from __future__ import annotations

import numpy as np
import pytest

from pipelines.diagnose import DiagnoseConfig, diagnose_jointed
from pipelines.synth.held import SensorNoise
from pipelines.synth.jointed import jointed_paper_objects
from twin.bench.diagnose import (
    Case,
    concealed_joint_effect,
    record_joint_case,
    true_joint_model_fit,
)


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
    from twin.bench.diagnose import make_cases

    case = make_cases(40, 10, 0)[11]
    assert (case.shape, case.effect.name) == ("drawer", "viscous_damping")
    trial, _, joint, placement, prior = record_joint_case(case, tmp_path)
    config = replace(JointedConfig(), window_s=DiagnoseConfig().joint_window_s)
    ident = identify_jointed([trial], joint, placement, prior, None, config, effects=("viscous_damping",))
    assert ident.value("damping") == pytest.approx(case.effect.params["b"], rel=0.15)
