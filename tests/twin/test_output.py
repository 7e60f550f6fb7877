"""Output folders: a user's files survive every -o, twin's own are replaced only when the new ones are complete."""

import json
import os
import stat
from pathlib import Path

import pytest

from twin.output import INTERRUPTED, MANIFEST, OutputError, check_output, staged_output, written_by_twin


def _user_folder(root: Path) -> Path:
    out = root / "mine"
    (out / "sub").mkdir(parents=True)
    (out / "notes.txt").write_text("my notes")
    (out / "sub" / "data.csv").write_text("1,2")
    return out


def _write_build(tmp: Path, collision_count: int = 2, text: str = "new") -> None:
    (tmp / "asset.json").write_text(json.dumps({"schema": "twin.asset/1", "files": {"urdf": "cube.urdf"}}))
    (tmp / "cube.urdf").write_text(text)
    (tmp / "meshes").mkdir()
    for k in range(collision_count):
        (tmp / "meshes" / f"collision_{k:03d}.obj").write_text(text)


def _siblings(root: Path) -> list[str]:
    return sorted(p.name for p in root.iterdir())


def test_a_folder_of_the_users_is_refused_and_left_alone(tmp_path):
    out = _user_folder(tmp_path)
    with pytest.raises(OutputError, match="files twin did not write"):
        with staged_output(out) as tmp:
            _write_build(tmp)
    assert (out / "notes.txt").read_text() == "my notes" and (out / "sub" / "data.csv").exists()
    assert _siblings(tmp_path) == ["mine"]


def test_force_writes_beside_the_users_files_and_the_manifest_lists_only_twins(tmp_path):
    out = _user_folder(tmp_path)
    with staged_output(out, force=True) as tmp:
        _write_build(tmp)
    assert (out / "notes.txt").read_text() == "my notes" and (out / "sub" / "data.csv").read_text() == "1,2"
    assert (out / "cube.urdf").read_text() == "new"
    owned = written_by_twin(out)
    assert "notes.txt" not in owned and "sub/data.csv" not in owned and "meshes/collision_001.obj" in owned


def test_an_interrupt_python_swallowed_still_keeps_the_new_output_out(tmp_path):
    out = tmp_path / "out"
    with staged_output(out) as tmp:
        _write_build(tmp, text="old")
    INTERRUPTED.set()  # as the signal handler leaves it when its KeyboardInterrupt was raised in a callback
    try:
        with pytest.raises(KeyboardInterrupt):
            with staged_output(out) as tmp:
                _write_build(tmp, text="new")
    finally:
        INTERRUPTED.clear()
    assert (out / "cube.urdf").read_text() == "old" and _siblings(tmp_path) == ["out"]


def test_a_rebuild_replaces_twins_files_keeps_the_users_and_drops_stale_ones(tmp_path):
    out = tmp_path / "out"
    with staged_output(out) as tmp:
        _write_build(tmp, collision_count=3, text="old")
    (out / "notes.txt").write_text("added later by the user")
    with staged_output(out) as tmp:
        _write_build(tmp, collision_count=1, text="new")
    assert (out / "notes.txt").read_text() == "added later by the user"
    assert (out / "cube.urdf").read_text() == "new"
    assert sorted(p.name for p in (out / "meshes").iterdir()) == ["collision_000.obj"]
    assert _siblings(tmp_path) == ["out"]


@pytest.mark.parametrize("raised", [RuntimeError("stage failed"), KeyboardInterrupt()])
def test_a_failed_or_interrupted_build_leaves_out_as_it_was_and_no_temporary_folder(tmp_path, raised):
    out = tmp_path / "out"
    with staged_output(out) as tmp:
        _write_build(tmp, text="first")
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    with pytest.raises(type(raised)):
        with staged_output(out) as tmp:
            _write_build(tmp, text="second")
            raise raised
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before
    assert _siblings(tmp_path) == ["out"]


def test_an_existing_file_and_an_unwritable_place_are_refused_before_any_work(tmp_path):
    target = tmp_path / "report.pdf"
    target.write_text("keep me")
    with pytest.raises(OutputError, match="not a folder"):
        check_output(target)
    assert target.read_text() == "keep me"
    with pytest.raises(OutputError, match="cannot create"):
        check_output(Path("/proc/twin-out"))


def test_folders_follow_the_users_umask(tmp_path):
    previous = os.umask(0o022)
    try:
        with staged_output(tmp_path / "out") as tmp:
            _write_build(tmp)
    finally:
        os.umask(previous)
    assert stat.S_IMODE((tmp_path / "out").stat().st_mode) == 0o755


def test_the_working_directory_as_out(tmp_path, monkeypatch):
    out = tmp_path / "here"
    out.mkdir()
    monkeypatch.chdir(out)
    with staged_output(Path(".")) as tmp:
        _write_build(tmp)
    assert (out / "cube.urdf").exists() and (out / MANIFEST).exists()
    assert _siblings(tmp_path) == ["here"]


def test_an_output_from_before_the_manifest_is_recognised_by_its_asset_json(tmp_path):
    out = tmp_path / "old"
    out.mkdir()
    (out / "asset.json").write_text(json.dumps({"schema": "twin.asset/1", "files": {"mjcf": "cube.xml"}}))
    assert {"asset.json", "cube.xml", "meshes", "report.html"} <= set(written_by_twin(out))
    (out / "asset.json").write_text(json.dumps({"schema": "something/else"}))
    assert written_by_twin(out) is None


def test_a_manifest_never_reaches_outside_its_folder(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    precious = tmp_path / "precious.txt"
    precious.write_text("outside")
    (out / MANIFEST).write_text(json.dumps({"schema": "twin.output/1", "files": ["../precious.txt", "/etc/hosts"]}))
    with staged_output(out) as tmp:
        _write_build(tmp)
    assert precious.read_text() == "outside"


def test_synth_refuses_an_existing_folder_without_force(tmp_path):
    out = tmp_path / "sample"
    out.mkdir()
    (out / "truth.json").write_text("{}")
    with pytest.raises(OutputError, match="not empty"):
        check_output(out, replace_own=False)
    check_output(out, force=True, replace_own=False)


def test_a_sample_made_by_synth_is_never_a_builds_output(tmp_path):
    sample = tmp_path / "sample"
    with staged_output(sample, replace_own=False, made_by="synth") as tmp:
        (tmp / "trial.mcap").write_text("recording")
    assert written_by_twin(sample, "synth") == ("trial.mcap",) and written_by_twin(sample) is None
    with pytest.raises(OutputError, match="files twin did not write"):
        check_output(sample)


def test_force_never_replaces_a_users_file_that_bears_one_of_twins_names(tmp_path):
    out = _user_folder(tmp_path)
    (out / "cube.urdf").write_text("the user's own robot")
    with pytest.raises(OutputError, match="cube.urdf: exists and twin did not write it"):
        with staged_output(out, force=True) as tmp:
            _write_build(tmp)
    assert (out / "cube.urdf").read_text() == "the user's own robot" and not (out / MANIFEST).exists()
    assert sorted(p.name for p in out.iterdir()) == ["cube.urdf", "notes.txt", "sub"]
    assert _siblings(tmp_path) == ["mine"]
