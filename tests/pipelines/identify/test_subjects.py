"""A build records its subject in asset.json and `twin diagnose` reads it back: the round trip is exact."""

from __future__ import annotations

import json

import numpy as np
import pytest

from assets import Inertial, Pose
from pipelines.identify import (
    HeldBody, JointedConfig, JointedPart, JointFit, PlanarBody, PushedBody, SlidingConfig, subject_from_json,
)

BODY = Inertial(0.8, (0.01, -0.02, 0.003), ((2e-3, 1e-5, 0.0), (1e-5, 3e-3, 2e-5), (0.0, 2e-5, 4e-3)))
PLACEMENT = Pose((0.4, 0.1, 0.3), (0.0, 0.0, np.sin(0.3), np.cos(0.3)))


def _joint(joint_type: str) -> JointFit:
    return JointFit(joint_type, np.array([0.0, 0.6, 0.8]), 1e-3, np.array([0.5, 0.0, 0.2]), np.array([1e-4, 2e-4, 0.0]),
                    Pose((0.6, 0.1, 0.25), (0.1, 0.0, 0.0, np.sqrt(0.99))), np.linspace(0.0, 1.0, 11),
                    np.linspace(-0.1, 0.9, 11), 2e-4, 1e-3)


@pytest.mark.parametrize("subject", [
    HeldBody(PLACEMENT, BODY, 0.1),
    PushedBody(PlanarBody((0.05, 0.04, 0.02), 0.8, 3e-4, mass_rel_std=0.2, izz_rel_std=0.3), 0.4,
               SlidingConfig(support="corners", fit_mass=True)),
    JointedPart(_joint("revolute"), PLACEMENT, BODY, JointedConfig(window_s=0.5)),
    JointedPart(_joint("prismatic"), PLACEMENT, BODY, JointedConfig()),
], ids=["free", "sliding", "revolute", "prismatic"])
def test_a_subject_read_back_from_asset_json_is_the_one_written(subject):
    back = subject_from_json(json.loads(json.dumps(subject.to_json())))
    assert type(back) is type(subject)
    if isinstance(subject, HeldBody):
        assert np.allclose(back.X_tracked_body.matrix(), subject.X_tracked_body.matrix(), atol=1e-15)
        assert back.uniform == subject.uniform and back.window_s == subject.window_s
    elif isinstance(subject, PushedBody):
        assert back == subject
    else:
        j, k = back.joint, subject.joint
        assert j.type == k.type and j.tracked_at_zero == k.tracked_at_zero
        for name in ("axis", "origin", "origin_std_m"):
            assert np.array_equal(getattr(j, name), getattr(k, name))
        assert np.array_equal(j.q, [k.q.min(), k.q.max()])  # the samples are not recorded, only the travel
        q = np.array([-0.05, 0.3, 0.7])
        assert np.allclose(j.tracked_position(q), k.tracked_position(q), atol=1e-15)
        assert (back.placement, back.prior, back.config) == (subject.placement, subject.prior, subject.config)


def test_a_record_of_no_known_kind_is_refused():
    with pytest.raises(ValueError, match="subject kind"):
        subject_from_json({"kind": "floating"})
