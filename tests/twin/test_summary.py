"""A weighing used as a measurement, values outside the prior flagged, and the build's closing words."""

import json

import numpy as np
import pytest
import trimesh

from assets import Estimate, Inertial, Theta
from pipelines.identify import with_weighed_mass
from pipelines.priors import estimate_prior
from twin.build import weighed_where_prior
from twin.summary import bounds_flags, disagreement_flags, doubtful_flags, dominated_flags, summary_lines


def _theta(mass: float, source: str = "measured") -> Theta:
    inertia = np.diag([1e-4, 2e-4, 3e-4])
    return Theta(Estimate(mass, 0.01, source=source), Estimate((0.0, 0.0, 0.0), (0.0,) * 3),
                 Estimate(tuple(map(tuple, inertia)), tuple(map(tuple, inertia * 0.1))),
                 Estimate(0.5, 0.1, source="prior"))


def test_a_weighing_pulls_the_estimate_and_what_the_data_tie_to_the_mass():
    body = Inertial(1.1, (0.01, 0.0, 0.0), np.diag([1e-3, 1e-3, 1e-3]))
    cov = np.diag([0.01, 1e-6, 1e-6, 1e-6, 1e-8, 1e-8, 1e-8, 1e-9, 1e-9, 1e-9])
    cov[0, 1] = cov[1, 0] = 0.5 * np.sqrt(0.01 * 1e-6)  # COM x correlated with the mass
    updated, cov2 = with_weighed_mass(body, cov, 1.0, 0.001)
    assert updated.mass == pytest.approx(1.0, abs=0.002)
    assert updated.com[0] < 0.01  # moved with the mass, as the correlation says
    assert cov2[0, 0] < 0.001**2 * 1.01 and np.all(np.linalg.eigvalsh(cov2) > -1e-18)


def test_the_prior_takes_the_weighing_and_says_when_the_material_cannot_explain_it():
    cube = trimesh.creation.box((0.04, 0.04, 0.04))
    prior = estimate_prior(cube, "pla_printed", weighed=(0.02, 0.0005))
    assert prior.lower[0] < 0.02 < prior.upper[0] and prior.upper[0] - prior.lower[0] < 0.003
    assert prior.details["fusion"]["weighed"]["consistent_with_material"]
    heavy = estimate_prior(cube, "pla_printed", weighed=(0.4, 0.001))  # 6 g/cm^3: no print weighs that
    assert heavy.inertial.mass == 0.4 and not heavy.details["fusion"]["weighed"]["consistent_with_material"]
    assert heavy.lower[4] < heavy.inertial.inertia[0][0] < heavy.upper[4]


def test_a_mass_the_motion_left_to_the_prior_becomes_the_weighing():
    theta = weighed_where_prior(_theta(2.0, source="prior"), (1.5, 0.01))
    assert theta.mass.source == "weighed" and theta.mass.value == 1.5
    assert weighed_where_prior(_theta(2.0), (1.5, 0.01)).mass.value == 2.0  # measured stays measured


def test_a_measured_mass_outside_the_prior_is_flagged_and_said():
    lower, upper = (0.5, -1, -1, -1, 5e-5, 5e-5, 5e-5), (1.0, 1, 1, 1, 5e-4, 5e-4, 5e-4)
    assert bounds_flags(_theta(0.8), lower, upper) == ()
    flags = bounds_flags(_theta(43.0), lower, upper)
    assert [f["parameter"] for f in flags] == ["mass"]
    assert bounds_flags(_theta(43.0, source="prior"), lower, upper) == ()
    doc = {"theta": {"mass": {"source": "measured"}, "friction": {"source": "prior"}}, "flags": list(flags),
           "provenance": {"identify": {"selected": "least_squares", "heldout_fits": {
               "least_squares": {"rmse_position_m": 0.001}, "newton": {"rmse_position_m": 0.002}}}},
           "material": {"text": "EPS foam", "name": "foam_polystyrene", "match_score": 0.95, "source": "hint"}}
    lines = summary_lines(doc)
    assert lines[0].startswith("kept least squares: it predicts the held-out recording best")
    assert "measured: mass" in lines and "prior: friction" in lines
    assert any("'EPS foam' read as foam_polystyrene" in line for line in lines)
    assert lines[-1].startswith("FLAG: mass 43 kg is outside")


def test_what_the_recordings_left_to_the_prior_or_a_mismatch_corrupted_is_flagged_and_said():
    assert dominated_flags(set()) == () and doubtful_flags(()) == () and disagreement_flags((), {}) == ()
    flags = (dominated_flags({"Ixz", "Ixy"}) + doubtful_flags(("mass", "friction"))
             + disagreement_flags(("axis_inertia",), {"axis_inertia": 0.22}))
    doc = {"theta": {"mass": {"source": "measured"}}, "flags": list(flags),
           "provenance": {"identify": {"selected": "posterior", "choice": "posterior: no held-out recording"}}}
    lines = summary_lines(doc)
    assert lines[0] == "kept the posterior: no held-out recording"
    assert lines[-3].startswith("FLAG: inertial: prior-dominated") and lines[-3].endswith("(Ixy, Ixz)")
    assert lines[-2].startswith("FLAG: diagnosis: doubtful") and lines[-2].endswith("(friction, mass)")
    assert lines[-1].startswith("FLAG: identification: doubtful") and lines[-1].endswith("(axis_inertia)")
    assert json.loads(json.dumps(flags))[-1]["apart"] == {"axis_inertia": 0.22}
