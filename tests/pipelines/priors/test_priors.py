"""Priors: the material library, solid / shell / printed geometry priors, theta0 with its bounds, fusion."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from assets.materials import LIBRARY_PATH, _check_entry, find_material, material_names, material_range
from pipelines.priors import (
    PriorConfig,
    VlmGuess,
    estimate_prior,
    infill_moments,
    inner_moments,
    shell_moments,
    solid_moments,
    uniform_density_prior,
)


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


def test_library_covers_thirty_sourced_materials_of_every_kind():
    """At least 30 entries over all asked-for kinds, each with density, static and kinetic friction and a source."""
    names = material_names()
    assert len(names) >= 30
    categories = {material_range(n).category for n in names}
    assert {"3d-printing", "wood", "metal", "plastic", "glass", "ceramic", "paper", "food", "foam", "rubber",
            "fabric"} <= categories
    printed = [n for n in names if material_range(n).structure == "printed"]
    assert {"pla_printed", "petg_printed", "abs_printed", "tpu_printed"} <= set(printed)
    for name in names:
        m = material_range(name)
        k, k_lo, k_hi = m.kinetic()
        assert m.friction_kinetic is not None and k_lo <= k <= k_hi and k <= m.friction
        assert len(m.source) > 10
        if m.structure != "solid":
            assert m.solid_density is not None


def test_aliases_and_lenient_lookup():
    """Common names a VLM may answer map to entries; an unknown one gives None, not an error."""
    assert find_material("Aluminum").name == "aluminium"
    assert find_material("PLA").name == "pla_printed"
    assert find_material("styrofoam").name == "foam_polystyrene"
    assert find_material("unobtainium") is None and find_material(None) is None


def test_library_entry_errors_name_the_file_and_field():
    """A range whose low exceeds its central value is refused naming materials.json and the field."""
    with pytest.raises(ValueError, match=r"materials\.json.*'bad'.*'density'"):
        _check_entry("bad", {"density": [100, 200, 300], "friction": [0.5, 0.4, 0.6], "source": "x"})
    with pytest.raises(ValueError, match="shell needs 'wall_m'"):
        _check_entry("bad", {"density": [100, 50, 300], "friction": [0.5, 0.4, 0.6], "source": "x",
                             "structure": "shell"})
    assert json.loads(LIBRARY_PATH.read_text())["unknown"]["source"]


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
    with pytest.raises(ValueError, match="watertight"):
        estimate_prior(box, "steel")


def test_hollow_cube_matches_the_analytic_shell():
    """A 4 cm cube with 2 mm walls: volume a^3 - b^3 and inertia (a^5 - b^5) / 6 per unit density."""
    a, t = 0.04, 0.002
    b = a - 2 * t
    cube = trimesh.creation.box((a, a, a))
    solid = solid_moments(cube)
    inner, gone = inner_moments(cube, [t, 0.03])
    shell = shell_moments(solid, inner)
    assert shell.volume == pytest.approx(a**3 - b**3, rel=1e-9)
    np.testing.assert_allclose(shell.unit_inertia(), np.eye(3) * (a**5 - b**5) / 6, rtol=1e-9, atol=1e-15)
    assert gone.volume == 0.0  # 3 cm walls leave nothing inside a 4 cm cube


def test_printed_cube_is_walls_plus_a_fraction_of_the_inside():
    """Infill f: volume a^3 - (1 - f) b^3, inertia (a^5 - (1 - f) b^5) / 6; f = 1 is the solid."""
    a, t, f = 0.04, 0.0012, 0.2
    b = a - 2 * t
    cube = trimesh.creation.box((a, a, a))
    solid = solid_moments(cube)
    (inner,) = inner_moments(cube, [t])
    printed = infill_moments(solid, inner, f)
    assert printed.volume == pytest.approx(a**3 - (1 - f) * b**3, rel=1e-9)
    assert printed.unit_inertia()[0, 0] == pytest.approx((a**5 - (1 - f) * b**5) / 6, rel=1e-9)
    assert infill_moments(solid, inner, 1.0).volume == pytest.approx(a**3, rel=1e-12)
    with pytest.raises(ValueError, match="infill"):
        infill_moments(solid, inner, 1.5)


def test_non_convex_shell_through_the_signed_distance_grid():
    """An L-shaped bar (not convex) with 2 mm walls: inner body within 1.5 % of the two eroded boxes."""
    L = trimesh.boolean.union([trimesh.creation.box(bounds=[(-0.03, -0.01, -0.01), (0.03, 0.01, 0.01)]),
                               trimesh.creation.box(bounds=[(0.01, -0.01, -0.01), (0.03, 0.05, 0.01)])])
    assert L.is_volume and not L.is_convex
    t = 0.002
    (inner,) = inner_moments(L, [t], resolution=48)
    exact = 0.056 * 0.016 * 0.016 + 0.016 * 0.040 * 0.016  # the eroded arms; the arc at the inner corner adds 0.06 %
    assert inner.volume == pytest.approx(exact, rel=0.015)
    assert shell_moments(solid_moments(L), inner).volume == pytest.approx(L.volume - exact, rel=0.03)


def test_printed_prior_holds_rigpi_cube_and_keeps_the_uniform_body():
    """RigPI's 20 g printed 4 cm cube lies in C; theta0 lies in C; the uniform body at theta0's mass is kept."""
    cube = trimesh.creation.box((0.04, 0.04, 0.04))
    prior = estimate_prior(cube, "pla_printed")
    truth = [0.02, 0.0, 0.0, 0.0, *(3 * [5.33e-6])]
    theta0 = [prior.inertial.mass, *prior.inertial.com, *np.diag(prior.inertial.inertia_matrix())]
    assert all(lo <= x <= hi for lo, x, hi in zip(prior.lower, truth, prior.upper))
    assert all(lo <= x <= hi for lo, x, hi in zip(prior.lower, theta0, prior.upper))
    assert prior.structure == "printed" and 0.015 < prior.inertial.mass < 0.04
    assert prior.uniform.mass == pytest.approx(prior.inertial.mass)
    assert prior.uniform.inertia[0][0] == pytest.approx(prior.inertial.mass * 0.04**2 / 6, rel=1e-9)
    assert prior.inertial.inertia[0][0] > prior.uniform.inertia[0][0]  # walls carry mass outwards
    record = prior.provenance()
    assert record["fusion"]["vlm"] is None and record["structure"] == "printed"
    assert record["fusion"]["geometry"]["mass_kg"] == pytest.approx(prior.inertial.mass)
    json.dumps(record)


def test_solid_material_prior_is_the_density_interval_times_volume():
    """A steel cube's C spans the 99 % interval of the density's log-normal, theta0 at the central density."""
    cube = trimesh.creation.box((0.04, 0.04, 0.04))
    prior = estimate_prior(cube, "steel", config=PriorConfig(credible=0.95))
    volume = 0.04**3
    assert prior.inertial.mass == pytest.approx(7850 * volume, rel=2e-3)
    assert prior.lower[0] == pytest.approx(7750 * volume, rel=5e-3)
    assert prior.upper[0] == pytest.approx(8050 * volume, rel=5e-3)


def test_vlm_guess_pulls_the_mass_towards_it_within_the_geometry():
    """A heavy guess moves theta0 up, but less than all the way; a confident one moves it further."""
    cube = trimesh.creation.box((0.04, 0.04, 0.04))
    offline = estimate_prior(cube, "pla_printed").inertial.mass
    unsure = estimate_prior(cube, "pla_printed", VlmGuess(mass_kg=0.06, confidence=0.3)).inertial.mass
    sure = estimate_prior(cube, "pla_printed", VlmGuess(mass_kg=0.06, confidence=1.0)).inertial.mass
    assert offline < unsure < sure < 0.06


def test_vlm_material_and_hollow_answer_shape_the_prior():
    """Without a given material the VLM's is used; its 'hollow, 1 mm walls' adds a shell fill that lightens it."""
    cube = trimesh.creation.box((0.04, 0.04, 0.04))
    solid = estimate_prior(cube, None, VlmGuess(material="aluminum", density_kg_m3=2700, confidence=0.9))
    assert solid.material.name == "aluminium" and solid.details["fusion"]["material_from"] == "vlm"
    hollow = estimate_prior(cube, None, VlmGuess(material="aluminium", structure="hollow", density_kg_m3=2700,
                                                 wall_thickness_m=0.001, confidence=0.9))
    assert "shell" in hollow.structure and hollow.inertial.mass < 0.5 * solid.inertial.mass
    assert estimate_prior(cube, None, VlmGuess(material="moonrock", mass_kg=0.1)).material.name == "unknown"


def test_friction_fused_with_the_vlm_guess():
    """The library's friction alone without a VLM; with one, between the two and narrower than the library's."""
    cube = trimesh.creation.box((0.04, 0.04, 0.04))
    rubber = material_range("rubber")
    offline = estimate_prior(cube, "rubber")
    assert offline.friction == (rubber.friction, rubber.friction_low, rubber.friction_high)
    fused = estimate_prior(cube, "rubber", VlmGuess(friction_static=0.6, friction_kinetic=0.5, confidence=0.8))
    assert 0.6 < fused.friction[0] < rubber.friction
    assert fused.friction[2] - fused.friction[1] < rubber.friction_high - rubber.friction_low
    assert fused.friction_kinetic[0] < rubber.kinetic()[0]


def test_a_wildly_wrong_guess_is_discounted_by_the_heavy_tailed_likelihood():
    """A guess 30x too heavy drags theta0 less under the Student-t likelihood than under a log-normal one."""
    cube = trimesh.creation.box((0.04, 0.04, 0.04))
    guess = VlmGuess(mass_kg=0.6, confidence=0.8)
    robust = estimate_prior(cube, "pla_printed", guess).inertial.mass
    gaussian = estimate_prior(cube, "pla_printed", guess, PriorConfig(vlm_tail_dof=float("inf"))).inertial.mass
    offline = estimate_prior(cube, "pla_printed").inertial.mass
    assert offline < robust < gaussian and robust < 1.5 * offline


def test_bench_priors_bounds_hold_rigpi_truths_and_fusion_beats_the_paper_vlm(capsys):
    """`twin bench priors`: C holds all six truths; each fused cube prior is closer than the VLM answer it fused."""
    from benchmarks.priors import bench_priors

    rows = bench_priors()
    priors = [r for r in rows if "mass_in_bounds" in r]
    assert {r["object"] for r in priors} == {"cube", "sphere", "apple", "drawer", "cabinet_door", "oven_door"}
    assert all(r["mass_in_bounds"] and r["inertia_in_bounds"] for r in priors)
    vlm = {r["answer"]: abs(r["mass_error_pct"]) for r in rows if r["prior"] == "(b) paper VLM" and "mass_kg" in r}
    fused = {r["answer"]: abs(r["mass_error_pct"]) for r in rows if r["prior"] == "(c) fused" and "mass_kg" in r}
    assert set(vlm) == set(fused) == {"Gemini", "Intern-S1"} and all(fused[m] < vlm[m] for m in vlm)
    assert "| cube | (c) fused | Gemini |" in capsys.readouterr().out
