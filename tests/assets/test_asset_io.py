"""Tests for assets.io: asset.json written and read back, and every defect of a document named."""

from __future__ import annotations

import copy
import json
import math

import numpy as np
import pytest

from assets import (
    Asset,
    AssetError,
    Effect,
    Estimate,
    Fit,
    FitMetrics,
    Geometry,
    Joint,
    Material,
    Pose,
    Theta,
    asset_from_json,
    asset_to_json,
    read_asset,
    write_asset,
)


def _door() -> Asset:
    """A revolute part with every optional field filled."""
    inertia = ((0.05, 0.001, 0.0), (0.001, 0.04, 0.0), (0.0, 0.0, 0.02))
    theta = Theta(
        mass=Estimate(2.5, 0.1, source="weighed", interval95=(2.3, 2.7), prior={"mass_kg": 2.4}),
        com=Estimate((0.2, 0.0, 0.3), (0.01, 0.01, 0.01), source="prior"),
        inertia=Estimate(inertia, tuple(tuple(abs(x) * 0.1 for x in row) for row in inertia)),
        friction=Estimate(0.3, 0.05, interval95=(0.2, 0.4)),
        determined=(("axis_inertia", Estimate(0.21, 0.01)),),
    )
    return Asset(
        name="door", kind="revolute", placement=Pose((0.1, 0.2, 0.3), (0.0, 0.0, 0.6, 0.8)), theta=theta,
        geometry=Geometry("meshes/visual.obj", ("meshes/collision_000.obj",), "meshes/base.obj"),
        material=Material("wood", 600.0, 0.4, 0.1, text="oak veneer", source="hint", match_score=0.8),
        joint=Joint("revolute", (0.0, 0.0, 1.0), (0.5, 0.0, 0.0), -0.1, 1.6, damping=0.02, stiffness=0.5,
                    spring_ref=0.1, axis_std_rad=0.01, origin_std_m=(0.001, 0.001, 0.0)),
        effects=(Effect("spring", {"k": 0.5, "q0": 0.1}, {"gain": 0.3}),),
        fit=Fit(FitMetrics(0.01, 0.02, 0.5), FitMetrics(0.002, 0.004, 0.1), 0.5),
        unexplained=({"summary": "late bump", "where": {"t_s": [1.0, 1.2]}, "share": 0.1},),
        flags=({"parameter": "mass", "problem": "outside its prior bounds"},),
        files={"urdf": "door.urdf"}, provenance={"config": {"kind": None}},
    )


def test_write_then_read_gives_the_same_document(tmp_path):
    """Every field, the optional ones included, survives a write and a read unchanged."""
    path = tmp_path / "asset.json"
    write_asset(_door(), path)
    asset = read_asset(path)
    assert json.loads(json.dumps(asset_to_json(asset))) == json.loads(path.read_text())
    assert asset.material.text == "oak veneer" and asset.flags[0]["parameter"] == "mass"
    assert asset.theta.determined[0][0] == "axis_inertia"


def _set(doc, key_path: str, value):
    *parents, last = key_path.split(".")
    node = doc
    for k in parents:
        node = node[int(k)] if isinstance(node, list) else node[k]
    if value is _DELETE:
        del node[last]
    elif isinstance(node, list):
        node[int(last)] = value
    else:
        node[last] = value
    return doc


_DELETE = object()


@pytest.mark.parametrize("key_path, value, fault", [
    ("theta", _DELETE, r"theta: missing"),
    ("theta.mass", _DELETE, r"theta\.mass: missing"),
    ("theta.mass.value", _DELETE, r"theta\.mass\.value: missing"),
    ("theta.mass.value", -1.0, r"theta\.mass\.value: expected a mass > 0, got -1"),
    ("theta.mass.value", "heavy", r"theta\.mass\.value: expected a number, got a string"),
    ("theta.mass.value", True, r"theta\.mass\.value: expected a number, got a boolean"),
    ("theta.mass.value", math.nan, r"theta\.mass\.value: expected a finite number, got nan"),
    ("theta.mass.std", -0.1, r"theta\.mass\.std: expected a number >= 0, got -0\.1"),
    ("theta.mass.source", "guess", r"theta\.mass\.source: expected one of \('measured', 'prior', 'weighed'\)"),
    ("theta.com.value", [0.1, 0.2], r"theta\.com\.value: expected 3 numbers, got 2"),
    ("theta.inertia.value.0.1", 0.5, r"theta\.inertia\.value: not symmetric"),
    ("theta.inertia.value.2.2", -0.02, r"theta\.inertia\.value: inertia not positive definite"),
    ("theta.inertia.value.2.2", 0.2, r"theta\.inertia\.value: inertia breaks the triangle inequality"),
    ("theta.friction.value", math.inf, r"theta\.friction\.value: expected a finite number, got inf"),
    ("theta.axis_inertia", 5, r"theta\.axis_inertia: expected an object, got a number"),
    ("placement.quaternion_xyzw", [0, 0, 0, 2], r"placement\.quaternion_xyzw: norm 2, expected a unit quaternion"),
    ("placement.position", None, r"placement\.position: expected 3 numbers, got null"),
    ("kind", "floating", r"kind: expected one of \('free', 'sliding', 'prismatic', 'revolute'\), got 'floating'"),
    ("kind", "free", r"joint: kind 'free' takes no joint"),
    ("kind", "prismatic", r"joint\.type: 'revolute', but kind is 'prismatic'"),
    ("joint", _DELETE, r"joint: kind 'revolute' needs a joint"),
    ("joint.axis", [0, 0, 0], r"joint\.axis: norm 0, expected a unit vector"),
    ("joint.lower", 2.0, r"joint\.lower: 2 is not below joint\.upper 1\.6"),
    ("joint.hinge", 1, r"joint: unknown key 'hinge'"),
    ("material.density", 0, r"material\.density: expected a number > 0"),
    ("material", [], r"material: expected an object, got a list"),
    ("geometry.collision", "a.obj", r"geometry\.collision: expected a list, got a string"),
    ("geometry.collision.0", 7, r"geometry\.collision\.0: expected a non-empty string, got a number"),
    ("effects.0.params", None, r"effects\.0\.params: expected an object, got null"),
    ("fit.final.loss", math.nan, r"fit\.final\.loss: expected a number, got nan"),
    ("fit.window_s", 0, r"fit\.window_s: expected a number > 0"),
    ("flags", {}, r"flags: expected a list, got an object"),
    ("schema", "twin.asset/0", r"schema: expected 'twin\.asset/1', got 'twin\.asset/0'"),
    ("name", "", r"name: expected a non-empty string"),
])
def test_every_defect_is_an_asset_error_naming_the_file_and_the_key(tmp_path, key_path, value, fault):
    """A missing key, a wrong type, a non-finite or unphysical value: an AssetError '<path>: <key path>: ...'
    on one line, never a KeyError, TypeError or AttributeError."""
    doc = _set(copy.deepcopy(asset_to_json(_door())), key_path, value)
    path = tmp_path / "asset.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(AssetError, match=rf"^{path}: {fault}") as err:
        read_asset(path)
    assert "\n" not in str(err.value)
    with pytest.raises(AssetError, match=rf"^asset\.json: {fault}"):
        asset_from_json(doc)


@pytest.mark.parametrize("text, fault", [
    ("[]", r"expected an object, got a list"),
    ("5", r"expected an object, got a number"),
    ("{", r"not valid JSON"),
    (b"\xff\xfe{}", r"not valid JSON"),
    ("[" * 100000 + "]" * 100000, r"not valid JSON"),
])
def test_documents_that_are_no_asset_are_asset_errors(tmp_path, text, fault):
    """Not JSON, not UTF-8, nested past Python's recursion limit, or no object at the top."""
    path = tmp_path / "asset.json"
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    with pytest.raises(AssetError, match=rf"^{path}: {fault}"):
        read_asset(path)
    with pytest.raises(AssetError, match=r"no_such\.json: cannot read"):
        read_asset(tmp_path / "no_such.json")


def test_a_free_asset_without_optional_parts_reads(tmp_path):
    """Only the contract's required keys: joint, fit, effects and the rest are optional."""
    doc = asset_to_json(_door())
    doc["kind"] = "free"
    for key in ("joint", "fit", "effects", "unexplained", "flags", "files", "provenance"):
        del doc[key]
    del doc["theta"]["axis_inertia"]
    asset = asset_from_json(doc)
    assert asset.joint is None and asset.fit is None and asset.effects == () and asset.flags == ()
    np.testing.assert_allclose(asset.theta.inertial().inertia_matrix(), _door().theta.inertial().inertia_matrix())
