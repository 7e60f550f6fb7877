"""Objects named as users write them export to files every loader reads, under names each format accepts."""

from __future__ import annotations

import os
import re
import unicodedata
import xml.etree.ElementTree as ET
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import trimesh
from test_exporters import FRICTION, MASS_KG, make_asset

from assets import Asset, Joint
from exporters import FormatNames, export_all
from exporters.names import (
    MAX_STEM_BYTES,
    base_name,
    file_stem,
    joint_name,
    mjcf_name,
    urdf_name,
    usd_prim_name,
    xml_comment_text,
)

LOADED = ["cabinet door", "Müller's mug (v2)", "ハンマー", "drawer #3 / left", "1st box", "CON", ""]
"""Exported and read back by every loader (slow: Newton's importers)."""

NAMES = LOADED + [
    "a.b", "  ", "\t\n", "con", "Con.txt", "com1", "LPT9.tar.gz", "com¹", "CONIN$", "aux .txt", "nul.", "..", ".",
    ".hidden", "-rf", "ドライバー", "straße", "Ørsted œuvre", "ﬁle ①", "ＡＢＣ", "日本 2", "world", "World",
    "cube", "cabinet_door", "_private", "a__b", "mug-1 (red)", "x--y-", "-->", "a\x00b\x7f", "a\u202eb",
    "line\u2028break", "emoji 🔨 hammer", "family 👨\u200d👩\u200d👧", "x" * 300, "ü" * 200, "e\u0301", "é",
    'a/b\\c:d*e?f"g<h>i|j#k%l@m', "\ud800 lone surrogate",
]  # fmt: skip
"""Checked by the name functions alone."""

SAFE = ["cube", "cabinet_door", "box", "_private", "A1", "a__b"]
"""Names every function leaves as they are, so outputs written before keep their names."""

IDENTIFIER = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
WINDOWS_RESERVED = {"CON", "PRN", "AUX", "NUL", "CONIN$", "CONOUT$"} | {
    f"{port}{n}" for port in ("COM", "LPT") for n in (*"0123456789", "¹", "²", "³")
}


@pytest.mark.parametrize("name", NAMES)
def test_identifiers_are_ascii_and_valid_usd_identifiers(name: str):
    """Prim, body, link and joint names are [A-Za-z_][A-Za-z0-9_]* (what Sdf accepts everywhere, what Newton's
    label paths and ROS frames need), and MJCF and URDF never name a body 'world'."""
    from pxr import Sdf

    for identifier in (usd_prim_name(name), mjcf_name(name), urdf_name(name)):
        assert IDENTIFIER.match(identifier) and Sdf.Path.IsValidIdentifier(identifier), identifier
    for body in (mjcf_name(name), urdf_name(name)):
        assert body != "world"
        assert IDENTIFIER.match(joint_name(body)) and IDENTIFIER.match(base_name(body))


@pytest.mark.parametrize("name", NAMES)
def test_file_stems_are_safe_on_every_file_system(name: str, tmp_path: Path):
    """No character Windows, macOS or Linux refuse (nor "#", "%", "@"), no control or bidirectional-override
    characters, no reserved device name, no leading dot or dash, no trailing dot or space, NFC, bounded; the
    three files can be created and listed back under exactly that name."""
    stem = file_stem(name)
    assert stem and stem == stem.strip() and not stem.endswith(".") and stem[0] not in ".-"
    assert not set(stem) & set('/\\:*?"<>|#%@')
    assert all(unicodedata.category(c) not in ("Cc", "Cs", "Zl", "Zp") for c in stem)
    assert all(unicodedata.category(c) != "Cf" for c in stem if c not in "\u200c\u200d")
    assert stem.partition(".")[0].rstrip(" ").upper() not in WINDOWS_RESERVED
    assert stem == unicodedata.normalize("NFC", stem) and len(stem.encode("utf-8")) <= MAX_STEM_BYTES
    for ext in (".urdf", ".xml", ".usda"):
        (tmp_path / f"{stem}{ext}").write_text("x")
    assert sorted(os.listdir(tmp_path)) == sorted(f"{stem}{ext}" for ext in (".urdf", ".xml", ".usda"))


@pytest.mark.parametrize("name", NAMES)
def test_every_name_function_is_idempotent(name: str):
    """A derived name derives to itself, so the derivation can be applied again without drifting."""
    for derive in (usd_prim_name, mjcf_name, urdf_name, file_stem):
        assert derive(derive(name)) == derive(name), derive


@pytest.mark.parametrize("name", SAFE)
def test_safe_names_are_kept(name: str):
    """'cube' or 'cabinet_door' keep their file, body and prim names."""
    assert FormatNames.of(name) == FormatNames(name, name, name, name, name)


@pytest.mark.parametrize(
    ("name", "identifier", "stem"),
    [
        ("cabinet door", "cabinet_door", "cabinet door"),
        ("Müller's mug (v2)", "Muller_s_mug_v2", "Müller's mug (v2)"),
        ("drawer #3 / left", "drawer_3_left", "drawer _3 _ left"),
        ("1st box", "_1st_box", "1st box"),
        ("CON", "CON", "CON_"),
        ("con.tar", "con_tar", "con_.tar"),
        ("", "object", "object"),
        ("  ", "object", "object"),
        ("ハンマー", "object_aa26263e", "ハンマー"),  # the hash is SHA-256's: the same on every machine
        ("日本 2", "_2_367cd00e", "日本 2"),
        ("straße Øl", "strasse_Ol", "straße Øl"),
        ("ＡＢＣ ①", "ABC_1", "ＡＢＣ ①"),
        (".hidden", "hidden", "_.hidden"),
        ("-rf", "rf", "_-rf"),
        ("a\u202eb", "a_b", "a_b"),
    ],
)
def test_names_derive_as_documented(name: str, identifier: str, stem: str):
    """Accents transliterate, punctuation runs become one '_', nothing-left-in-ASCII gets a hash."""
    names = FormatNames.of(name)
    assert (names.name, names.usd, names.mjcf, names.urdf, names.file) == (name, identifier, identifier,
                                                                           identifier, stem)


def test_world_is_renamed_only_where_it_is_reserved():
    """MuJoCo's body 0 and the URDF world frame are 'world'; USD has no such name."""
    assert (mjcf_name("world"), urdf_name("world"), usd_prim_name("world")) == ("world_", "world_", "world")


def test_composed_and_decomposed_spellings_are_one_name():
    """'é' typed as one character or as e + combining accent gives the same names (macOS decomposes file names)."""
    assert FormatNames.of("caf\u00e9 ハ") == replace(FormatNames.of("cafe\u0301 ハ"), name="caf\u00e9 ハ")


def test_distinct_names_stay_distinct():
    """Names that differ in letters or digits, not only in punctuation, keep different names in every format."""
    names = ["ハンマー", "ドライバー", "日本 2", "日本 3", "x" * 300, "x" * 299 + "y", "ü" * 200, "ü" * 199 + "ö",
             "cube", "cube 2", "Müller", "Mutter", "cabinet door", "cabinet doors"]
    for derive in (usd_prim_name, mjcf_name, urdf_name, file_stem):
        assert len({derive(n) for n in names}) == len(names), derive


@pytest.mark.parametrize("name", ["x--y-", "-->", "a\x00b\x0c", "line\nbreak", "\ud800", "Müller's mug (v2)"])
def test_comment_text_keeps_xml_well_formed(name: str):
    """The name as written goes into a comment of the URDF and MJCF; no name may break the XML."""
    root = ET.Element("robot")
    root.append(ET.Comment(f" object name: {xml_comment_text(name)} "))
    text = ET.tostring(root, encoding="unicode")
    parser = ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
    parser.feed(text.encode("utf-8"))
    assert parser.close()[0].text == f" object name: {xml_comment_text(name)} "
    if name == "Müller's mug (v2)":
        assert xml_comment_text(name) == name


def _assert_files_named_after(paths, out_dir: Path, name: str) -> None:
    """NAME.urdf, NAME.xml, NAME.usda with NAME the file stem, and the name as written inside each."""
    from pxr import Usd

    stem = file_stem(name)
    assert (paths.urdf, paths.mjcf, paths.usd) == tuple(out_dir / f"{stem}{ext}" for ext in (".urdf", ".xml", ".usda"))
    comment = f"<!-- object name: {xml_comment_text(name)} -->"
    assert comment in paths.urdf.read_text() and comment in paths.mjcf.read_text()
    stage = Usd.Stage.Open(str(paths.usd))
    prim = stage.GetDefaultPrim()
    assert prim.GetName() == usd_prim_name(name)
    assert prim.GetCustomDataByKey("twin:name") == name and prim.GetDocumentation() == name


@pytest.mark.parametrize("name", LOADED)
def test_free_body_named_freely_reads_back_in_every_loader(name: str, tmp_path: Path):
    """MuJoCo, Newton (MJCF, URDF, USD), yourdfpy and UsdPhysics all find the body and read its values."""
    from pipelines.validate import validate_exports

    asset = make_asset(tmp_path, name=name)
    paths = export_all(asset, tmp_path)
    _assert_files_named_after(paths, tmp_path, name)
    report = validate_exports(asset, tmp_path, paths)
    assert report.ok and len(report.checks) == 6
    assert all(c.ok for c in report.checks), report.failures()
    assert asset.name == name


def _revolute(asset: Asset, out_dir: Path) -> Asset:
    trimesh.creation.box(extents=(0.5, 0.5, 0.02)).export(out_dir / "meshes" / "base.obj")
    axis = np.array([0.2, -0.3, 0.93])
    joint = Joint("revolute", tuple(axis / np.linalg.norm(axis)), (0.35, -0.12, 0.02), -0.05, 0.9, damping=0.03)
    return replace(asset, kind="revolute", joint=joint, geometry=replace(asset.geometry, base="meshes/base.obj"))


@pytest.mark.parametrize("name", LOADED)
def test_revolute_part_named_freely_reads_back_in_every_loader(name: str, tmp_path: Path):
    """A door named freely: MuJoCo (its MJCF, and its URDF through MuJoCo's URDF compiler), Newton (MJCF, URDF,
    USD), yourdfpy and UsdPhysics find the part and its joint by the derived names."""
    import mujoco

    from pipelines.validate import validate_exports, validate_jointed_exports

    part = _revolute(make_asset(tmp_path, name=name), tmp_path)
    paths = export_all(part, tmp_path)
    _assert_files_named_after(paths, tmp_path, name)
    readings = validate_jointed_exports(part, tmp_path, paths)
    assert set(readings) == {"mujoco (mjcf)", "newton (mjcf)", "yourdfpy (urdf)", "newton (urdf)", "newton (usd)"}
    assert all(r["type"] == "revolute" and r["friction"] == pytest.approx(FRICTION) for r in readings.values())
    assert validate_exports(part, tmp_path, {"usd": paths.usd}).ok  # UsdPhysics and Newton on the body prim

    model = mujoco.MjModel.from_xml_path(str(paths.urdf))  # the base link is static: MuJoCo fuses it into world
    body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, urdf_name(name))
    joint = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, joint_name(urdf_name(name)))
    assert body > 0 and joint >= 0 and model.jnt_bodyid[joint] == body
    assert model.body_mass[body] == pytest.approx(MASS_KG, rel=1e-9)
    assert model.jnt_type[joint] == mujoco.mjtJoint.mjJNT_HINGE
