"""validate_exports reloads real files in MuJoCo, Newton, yourdfpy and usd-core."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from assets import Asset, Estimate, Geometry, Material, Pose, Theta
from exporters import ExportPaths, export_all
from pipelines.validate import ValidationError, ValidationReport, validate_exports

EXTENTS_M = np.array([0.06, 0.04, 0.03])
MASS_KG = 0.02


def make_asset(out_dir: Path) -> Asset:
    """A 0.02 kg box (two convex halves) with an off-origin COM, a full tensor and a non-identity placement."""
    meshes = out_dir / "meshes"
    meshes.mkdir(parents=True, exist_ok=True)
    trimesh.creation.box(extents=EXTENTS_M).export(meshes / "visual.obj")
    for i, sign in enumerate((-1.0, 1.0)):
        T = np.eye(4)
        T[0, 3] = sign * EXTENTS_M[0] / 4
        trimesh.creation.box(extents=(EXTENTS_M[0] / 2, *EXTENTS_M[1:]), transform=T).export(
            meshes / f"collision_{i:03d}.obj"
        )
    a, b, c = EXTENTS_M
    moments = MASS_KG / 12.0 * np.array([b * b + c * c, a * a + c * c, a * a + b * b])
    R = Rotation.from_euler("xyz", [0.3, -0.5, 0.8]).as_matrix()
    I = R @ np.diag(moments) @ R.T
    theta = Theta(
        mass=Estimate(MASS_KG, 0.001),
        com=Estimate((0.003, -0.002, 0.004), (1e-4, 1e-4, 1e-4)),
        inertia=Estimate(tuple(map(tuple, I)), tuple(map(tuple, 0.05 * np.abs(I)))),
        friction=Estimate(0.6, 0.05),
    )
    return Asset(
        name="box",
        kind="free",
        placement=Pose((0.4, -0.1, 0.05), tuple(Rotation.from_euler("zyx", [0.7, 0.2, -0.1]).as_quat())),
        theta=theta,
        geometry=Geometry("meshes/visual.obj", ("meshes/collision_000.obj", "meshes/collision_001.obj")),
        material=Material("wood", 600.0, 0.6, 0.1),
    )


@pytest.fixture
def exported(tmp_path: Path) -> tuple[Asset, Path, ExportPaths]:
    asset = make_asset(tmp_path)
    return asset, tmp_path, export_all(asset, tmp_path)


def test_every_loader_reads_the_exports_to_1e6(exported):
    """All six loaders load the files and agree with theta to 1e-6; the report survives JSON."""
    asset, out_dir, paths = exported
    report = validate_exports(asset, out_dir, paths)
    assert isinstance(report, ValidationReport) and report.ok
    loaders = [c.loader for c in report.checks]
    assert loaders == ["mujoco", "newton.add_mjcf", "yourdfpy", "newton.add_urdf", "pxr.UsdPhysics", "newton.add_usd"]
    for check in report.checks:
        assert check.ok and check.error is None, check
        assert check.max_error < 1e-6
        assert check.mass == pytest.approx(MASS_KG, rel=1e-6)
        assert np.allclose(check.inertia, asset.theta.inertia.value, rtol=0, atol=1e-12)
    by_name = {c.loader: c for c in report.checks}
    assert by_name["mujoco"].placement_error < 1e-12 and by_name["newton.add_usd"].friction_error < 1e-6
    assert by_name["yourdfpy"].friction is None and by_name["newton.add_urdf"].position is None
    doc = json.loads(json.dumps(report.to_json()))
    assert doc["ok"] is True and len(doc["checks"]) == 6
    assert doc["object_size_m"] == pytest.approx(float(np.linalg.norm(EXTENTS_M)))


def test_wrong_mass_in_mjcf_raises_naming_the_file(exported):
    """Editing the mass in the written MJCF makes both MJCF loaders disagree and validate raise."""
    asset, out_dir, paths = exported
    text = paths.mjcf.read_text()
    edited = re.sub(r'mass="[^"]+"', 'mass="0.021"', text, count=1)
    assert edited != text
    paths.mjcf.write_text(edited)
    with pytest.raises(ValidationError) as info:
        validate_exports(asset, out_dir, {"mjcf": paths.mjcf.name})
    err = info.value
    assert err.path == paths.mjcf
    assert "mass 0.05" in err.message and str(paths.mjcf) in str(err)
    assert [c.ok for c in err.report.checks] == [False, False]
    assert err.report.checks[0].mass_error == pytest.approx(0.05)


def test_missing_collision_mesh_is_a_load_failure(exported):
    """A deleted convex part fails every URDF loader instead of loading a body with one collider."""
    asset, out_dir, paths = exported
    (out_dir / "meshes" / "collision_001.obj").unlink()
    report = validate_exports(asset, out_dir, {"urdf": paths.urdf, "report": "report.html"}, strict=False)
    assert not report.ok
    assert all(not c.ok and c.error for c in report.checks)
    assert "collision" in report.checks[0].error


def test_wrong_friction_in_usd_is_reported(exported):
    """A changed dynamicFriction in the USD material is caught by UsdPhysics and Newton's add_usd."""
    asset, out_dir, paths = exported
    text = paths.usd.read_text()
    paths.usd.write_text(text.replace("float physics:dynamicFriction = 0.6", "float physics:dynamicFriction = 0.9"))
    report = validate_exports(asset, out_dir, {"usd": paths.usd}, strict=False)
    assert [c.ok for c in report.checks] == [False, False]
    assert all(c.friction_error == pytest.approx(0.5, rel=1e-6) for c in report.checks)


def test_missing_file_and_no_files_raise(exported, tmp_path: Path):
    """A listed file that does not exist, or no listed file at all, raises ValidationError."""
    asset, out_dir, paths = exported
    elsewhere = tmp_path / "moved"
    shutil.move(str(paths.urdf), elsewhere)
    with pytest.raises(ValidationError, match="file not found"):
        validate_exports(asset, out_dir, {"urdf": paths.urdf})
    with pytest.raises(ValidationError, match="no exported files"):
        validate_exports(asset, out_dir, {"report": "report.html"})


def test_a_joint_breakaway_the_mjcf_cannot_carry_acts_in_the_mujoco_replay(tmp_path):
    """A MuJoCo drawer with Stribeck breakaway (f_s 1.2 f_c): the exported MJCF with the true body and its
    `stribeck_friction` replays the held-out recording closer than the MJCF's Coulomb friction alone does
    (0.38 against 0.55 mm; a drawer build's replay went from 0.83 to 0.47 mm with its own estimate)."""
    from assets import Effect
    from benchmarks.paper_jointed import mjcf_heldout_replay
    from pipelines.identify.kind import detect_kind
    from pipelines.logs import read_recording
    from pipelines.synth.held import ConcealedEffect, SensorNoise
    from pipelines.synth.jointed import JointedMotionConfig, jointed_paper_objects, write_jointed_recording
    from pipelines.synth.mujoco_engine import simulate_jointed_mujoco

    obj = jointed_paper_objects()["drawer"]
    params = {"f_s": 1.2 * obj.friction, "f_c": obj.friction, "v_s": 0.024}
    rng = np.random.default_rng(3)
    recordings = {}
    for trial in ("trial", "heldout"):
        motion = simulate_jointed_mujoco(obj, JointedMotionConfig(duration_s=4.0), rng,
                                         effect=ConcealedEffect("stribeck_friction", params))
        recordings[trial] = read_recording(write_jointed_recording(tmp_path / f"{trial}.mcap", obj, motion,
                                                                   SensorNoise(), rng))
    joint = detect_kind(recordings["trial"]).joint
    errors = {label: mjcf_heldout_replay(tmp_path / label, obj, joint, obj.inertial(), obj.friction,
                                         recordings["heldout"], effects)
              for label, effects in (("coulomb", ()), ("stribeck", (Effect("stribeck_friction", params),)))}
    assert errors["stribeck"] < 0.8 * errors["coulomb"]


def test_the_tracker_noise_floor_of_a_push_replay_is_its_noise_and_not_its_stops():
    """Windows of a block that slides at 0.1 m/s and stops dead mid-window: with white tracker noise of sigma
    per axis, the floor is sqrt(2) sigma (the RMS of a 2-D error) within 10 %; without noise, the stops alone
    give almost none."""
    from pipelines.validate.replay import tracker_scatter_m

    rng = np.random.default_rng(0)
    samples, windows, period, sigma = 51, 8, 0.01, 2e-4
    t = period * np.arange(samples)[:, None]
    stop = rng.uniform(0.1, 0.4, windows)[None, :]
    travel = 0.1 * np.minimum(t, stop)
    track = np.stack([travel * 0.6, travel * 0.8], axis=-1)
    assert tracker_scatter_m(track) < 0.1 * sigma
    noisy = track + rng.normal(0.0, sigma, track.shape)
    assert tracker_scatter_m(noisy) == pytest.approx(np.sqrt(2) * sigma, rel=0.1)
