"""Jointed parts scanned in their furniture: rendered from the front, closed from what is seen of them."""

from dataclasses import replace

import numpy as np
import pytest

from pipelines.priors import estimate_prior
from pipelines.reconstruct import reconstruct
from pipelines.scan import read_scan
from pipelines.synth.furniture import FurnitureConfig, furniture_carcass, render_furniture_scan
from pipelines.synth.jointed import jointed_paper_objects

# a scan from the front only leaves most azimuths unseen, as it must
pytestmark = pytest.mark.filterwarnings("ignore:.*gap in azimuth")

# 240x180 keeps the drawer's 16 mm front several pixels wide at 1.5 m; 12 views, low noise (the bench's "low")
CONFIG = FurnitureConfig(render=replace(FurnitureConfig().render, width=240, height=180, fx=225.0, fy=225.0,
                                        view_count=12))


@pytest.fixture(scope="module", params=["drawer", "cabinet_door", "oven_door"])
def scanned(request, tmp_path_factory):
    obj = jointed_paper_objects()[request.param]
    root = render_furniture_scan(obj, tmp_path_factory.mktemp(request.param), CONFIG, np.random.default_rng(0))
    return obj, read_scan(root)


def test_carcass_holds_the_part_without_overlap():
    import trimesh

    for obj in jointed_paper_objects().values():
        part = obj.mesh()
        part.apply_translation(obj.position_m)
        carcass = furniture_carcass(obj)
        assert carcass.is_watertight and carcass.bounds[0, 2] == pytest.approx(0.0)
        union = trimesh.boolean.union([carcass, part], engine="manifold")
        assert union.volume == pytest.approx(carcass.volume + part.volume, rel=1e-6)  # no overlap


def test_masks_mark_the_part_and_depth_the_scene(scanned):
    obj, scan = scanned
    for frame in scan.frames:
        assert frame.mask.any()
        assert (frame.depth_m[~frame.mask] > 0).mean() > 0.2  # carcass and floor in depth, unmasked (sky above)


def test_part_is_closed_from_its_front(scanned):
    obj, scan = scanned
    rec = reconstruct(scan)
    truth = obj.mesh()
    truth.apply_translation(obj.position_m)
    support = rec.stats["support"]
    assert not support["rests"]
    assert rec.mesh.is_watertight
    assert rec.mesh.volume == pytest.approx(truth.volume, rel=0.15)
    assert np.linalg.norm(rec.mesh.center_mass - truth.center_mass) < 0.010
    extent = rec.stats["extent"]
    assert "front_outline" in extent["seen"]
    if obj.name == "drawer":  # its depth can only come from the chest
        assert "thickness_m" in extent["assumed"]
    else:  # the door's back lies against the carcass face, whose step shows its thickness
        assert "thickness" in extent["seen"] and not extent["assumed"]
    # no material is known for these boxes (their densities, 0.8-2.0 t/m^3, name none): the wide prior
    mesh = rec.mesh.copy()
    mesh.apply_translation(-mesh.center_mass)
    prior = estimate_prior(mesh, None)
    assert prior.lower[0] <= obj.mass_kg <= prior.upper[0]


def test_a_narrow_front_tilted_by_noise_is_set_right_by_the_carcass(tmp_path):
    """The drawer's 16 mm front at the bench's "high" depth noise (scan seed 3) fits a plane tilted 25 deg,
    whose outline band misses the chest's face: started again facing the cameras, the front is found and the
    COM lands within 10 mm (it was 157 mm off)."""
    obj = jointed_paper_objects()["drawer"]
    config = replace(FurnitureConfig(), render=replace(FurnitureConfig().render, depth_noise_base_m=0.0015,
                                                       depth_noise_quadratic_per_m=0.0045))
    rec = reconstruct(read_scan(render_furniture_scan(obj, tmp_path / "drawer", config, np.random.default_rng(3))))
    truth = obj.mesh()
    truth.apply_translation(obj.position_m)
    assert abs(rec.stats["extent"]["front_normal"][0]) > 0.999  # the chest faces -x
    assert np.linalg.norm(rec.mesh.center_mass - truth.center_mass) < 0.010


def test_a_two_millimetre_step_read_through_depth_noise_that_moves_in_patches(tmp_path):
    """The oven door stands 2 mm proud of its oven; under the sensor-like depth noise (about 2.5 mm,
    correlated over 16 pixels: the bench's "sensor" level, scan seed 0) the step read pixel for pixel across
    each mask's border gives the volume within 15 % (the bands about the voted outline read 2.37 mm, +18.5 %)."""
    obj = jointed_paper_objects()["oven_door"]
    config = replace(FurnitureConfig(), render=replace(FurnitureConfig().render, depth_noise_base_m=0.00126,
                                                       depth_noise_quadratic_per_m=0.00293,
                                                       depth_noise_smoothing_px=8.0))
    rec = reconstruct(read_scan(render_furniture_scan(obj, tmp_path / "oven", config, np.random.default_rng(0))))
    assert rec.stats["extent"]["thickness_from"] == "carcass step"
    assert rec.mesh.volume == pytest.approx(obj.mesh().volume, rel=0.15)
