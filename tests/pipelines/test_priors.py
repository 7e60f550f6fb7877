"""Priors: the material library and the uniform-density theta0 with its bounds."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from assets.materials import material_names, material_range
from pipelines.priors import uniform_density_prior


def test_material_lookup_normalises_names_and_rejects_unknown():
    """'PLA printed' finds pla_printed; an unknown name lists the choices; None is the wide range."""
    assert material_range("PLA printed").name == "pla_printed"
    with pytest.raises(ValueError, match="choose one of"):
        material_range("unobtainium")
    wide = material_range(None)
    assert wide.density_low < 100 and wide.density_high > 5000
    for name in material_names():
        m = material_range(name)
        assert m.density_low <= m.density <= m.density_high and m.source


def test_uniform_prior_of_a_cube_and_bounds_contain_it():
    """A 4 cm steel cube: mass = density x volume, inertia m a^2 / 6, theta0 inside C."""
    cube = trimesh.creation.box((0.04, 0.04, 0.04))
    prior = uniform_density_prior(cube, material_range("steel"))
    mass = 7850 * 0.04**3
    assert prior.inertial.mass == pytest.approx(mass)
    np.testing.assert_allclose(np.diag(prior.inertial.inertia_matrix()), [mass * 0.04**2 / 6] * 3, rtol=1e-9)
    flat = [prior.inertial.mass, *prior.inertial.com, *np.diag(prior.inertial.inertia_matrix())]
    assert all(lo <= x <= hi for lo, x, hi in zip(prior.lower, flat, prior.upper))


def test_prior_refuses_an_open_mesh():
    """A mesh with a hole has no volume to give a mass."""
    box = trimesh.creation.box((0.04, 0.04, 0.04))
    box.update_faces(np.arange(len(box.faces)) > 0)
    with pytest.raises(ValueError, match="watertight"):
        uniform_density_prior(box, material_range("steel"))
