"""Bad inputs as users make them: each ends in one line `twin: error: <file>: <problem>`, a non-zero exit,
and an existing OUT left exactly as it was."""

import json
import shutil
from dataclasses import replace
from pathlib import Path

import h5py
import numpy as np
import pytest

from pipelines.logs import read_recording
from pipelines.synth.recording import write_recording
from twin.cli import main

SAMPLE = Path(__file__).resolve().parents[2] / "samples" / "cube"
PUSH_NAME = "motion_surface=abs_shape=rect1_a=0_v=10_i=0.000_s=0.000_t=0.698"


@pytest.fixture(scope="module")
def d(tmp_path_factory) -> Path:
    """A folder of broken inputs beside good ones, and an OUT from an earlier build holding a user's note."""
    d = tmp_path_factory.mktemp("bad")
    shutil.copytree(SAMPLE / "scan", d / "scan")
    shutil.copy(SAMPLE / "trial.mcap", d / "trial.mcap")
    (d / "notes.txt").write_text("not a mesh")
    (d / "empty_dir").mkdir()
    (d / "mine").mkdir()
    (d / "mine" / "notes.txt").write_text("my notes")
    (d / "report.pdf").write_text("a user's file")
    (d / "random.mcap").write_bytes(bytes(np.random.default_rng(0).integers(0, 256, 4096, dtype=np.uint8)))
    (d / "truncated.mcap").write_bytes((SAMPLE / "trial.mcap").read_bytes()[:50_000])
    (d / "table.csv").write_text("t,x\n")

    import trimesh

    box = trimesh.creation.box((0.05, 0.04, 0.03))
    box.export(d / "box.obj")
    trimesh.creation.box((50.0, 40.0, 30.0)).export(d / "box_mm.stl")
    trimesh.creation.box((0.001, 0.001, 0.001)).export(d / "speck.stl")
    open_box = box.copy()
    open_box.update_faces(np.arange(len(open_box.faces)) > 1)
    open_box.export(d / "open.stl")
    (d / "garbage.ply").write_bytes(b"ply\nformat ascii 1.0\nelement vertex 99999999999\nend_header\n1 2")

    def scan_copy(name: str, edit) -> None:
        shutil.copytree(SAMPLE / "scan", d / name)
        edit(d / name)

    def transforms(edit):
        def apply(root: Path):
            doc = json.loads((root / "transforms.json").read_text())
            edit(doc)
            (root / "transforms.json").write_text(json.dumps(doc))
        return apply

    scan_copy("scan_huge_fx", transforms(lambda doc: doc.update(fl_x=10**400)))
    scan_copy("scan_huge_unit", transforms(lambda doc: doc.update(depth_unit_scale_factor=10**400)))
    scan_copy("scan_huge_matrix", transforms(lambda doc: doc["frames"][0]["transform_matrix"][0].__setitem__(0, 10**400)))
    scan_copy("scan_no_frames", transforms(lambda doc: doc.update(frames=[])))
    scan_copy("scan_bad_json", lambda root: (root / "transforms.json").write_text("{\"fl_x\": 600,"))
    scan_copy("scan_missing_depth", lambda root: (root / "depth" / "frame_00003.png").unlink())

    def bomb(root: Path):  # a PNG header claiming 100000 x 100000 pixels
        import struct
        import zlib
        header = struct.pack(">IIBBBBB", 100000, 100000, 16, 0, 0, 0, 0)
        chunk = b"IHDR" + header
        data = b"\x89PNG\r\n\x1a\n" + struct.pack(">I", len(header)) + chunk + struct.pack(">I", zlib.crc32(chunk))
        (root / "depth" / "frame_00002.png").write_bytes(data + b"\x00" * 64)
    scan_copy("scan_bomb", bomb)

    def damaged_mask(root: Path):
        path = root / "masks" / "frame_00001.png"
        raw = bytearray(path.read_bytes())
        raw[40:80] = b"\xff" * 40
        path.write_bytes(bytes(raw[:120]))
    scan_copy("scan_bad_mask", damaged_mask)
    scan_copy("scan_bad_object_json", lambda root: (root / "object.json").write_text("[1, 2]"))

    rec = read_recording(SAMPLE / "trial.mcap")
    raw = rec.wrench_raw
    huge = replace(raw, force=np.full_like(raw.force, 1e300))
    write_recording(d / "huge_wrench.mcap", pose=rec.pose, wrench=huge)
    late = replace(raw, t_s=raw.t_s + 1000.0)
    write_recording(d / "apart.mcap", pose=rec.pose, wrench=late)

    for name, doc in (("five", 5), ("null", None), ("tip_empty", {"object_pose": [[0, 0, 0, 0], [1, 0, 0, 0]],
                                                                 "tip_pose": {}, "ft_wrench": [[0, 0, 0, 0]]})):
        folder = d / f"push_{name}"
        folder.mkdir()
        (folder / f"{PUSH_NAME}.json").write_text(json.dumps(doc))
    (d / "push_h5").mkdir()
    with h5py.File(d / "push_h5" / f"{PUSH_NAME}.h5", "w") as f:
        f["object_pose"] = np.zeros((5, 4))
        f.create_group("tip_pose")
        f["ft_wrench"] = np.zeros((5, 4))

    for name, doc in (("no_theta", {"schema": "twin.asset/1", "name": "cube", "kind": "free"}), ("list", [])):
        (d / f"asset_{name}").mkdir()
        (d / f"asset_{name}" / "asset.json").write_text(json.dumps(doc))

    out = d / "out"  # an earlier build's output, with a note the user added since
    out.mkdir()
    (out / "asset.json").write_text(json.dumps({"schema": "twin.asset/1", "files": {}}))
    (out / "notes.txt").write_text("added by the user")
    return d


def _good(d: Path, *more: str) -> list[str]:
    return ["build", str(d / "scan"), "--logs", str(d / "trial.mcap"), "-o", str(d / "out"), *more]


def _with_source(source: str, *more: str):
    return lambda d: ["build", str(d / source), "--logs", str(d / "trial.mcap"), "-o", str(d / "out"), *more]


def _with_logs(logs: str, *more: str):
    return lambda d: ["build", str(d / "scan"), "--logs", str(d / logs), "-o", str(d / "out"), *more]


# (name, argv from the folder d, what the line must name)
ROWS = [
    ("source missing", _with_source("nowhere"), "nowhere: SOURCE not found"),
    ("source a text file", _with_source("notes.txt"), "notes.txt: not a scan folder or a mesh file"),
    ("source an empty folder", _with_source("empty_dir"), "empty_dir: not a scan folder"),
    ("logs missing", _with_logs("nowhere.mcap"), "nowhere.mcap: recording not found"),
    ("logs a csv", _with_logs("table.csv"), "table.csv: not a recording"),
    ("logs a folder without mcap", _with_logs("empty_dir"), "empty_dir: a folder given to --logs"),
    ("holdout missing", lambda d: _good(d, "--holdout", str(d / "gone.mcap")), "gone.mcap: recording not found"),
    ("base mesh missing", lambda d: _good(d, "--base-mesh", str(d / "base.obj")), "base.obj: base mesh not found"),
    ("material unknown", lambda d: _good(d, "--material", "unobtainium"), "--material: unknown material"),
    ("material with no library entry", lambda d: _good(d, "--material", "carbon fibre"), "--material:"),
    ("topic absent", lambda d: _good(d, "--topic", "pose=/vicon/x"), "trial.mcap: no topic /vicon/x"),
    ("topic role unknown", lambda d: _good(d, "--topic", "force=/ft"), "--topic force=/ft: unknown role"),
    ("topic malformed", lambda d: _good(d, "--topic", "/ft"), "--topic '/ft': expected ROLE=VALUE"),
    ("frame role unknown", lambda d: _good(d, "--frame", "pose=gripper"), "--frame pose=gripper: unknown role"),
    ("window zero", lambda d: _good(d, "--window-s", "0"), "--window-s 0.0"),
    ("window not a number", lambda d: _good(d, "--window-s", "nan"), "--window-s nan"),
    ("iterations zero", lambda d: _good(d, "--max-iterations", "0"), "--max-iterations 0"),
    ("push speed negative", lambda d: _good(d, "--push-min-speed", "-1"), "--push-min-speed -1.0"),
    ("mass zero", lambda d: _good(d, "--mass", "0"), "--mass 0.0"),
    ("mass negative", lambda d: _good(d, "--mass", "-2"), "--mass -2.0"),
    ("mass std above mass", lambda d: _good(d, "--mass", "1", "2"), "--mass 1.0 2.0"),
    ("mass three numbers", lambda d: _good(d, "--mass", "1", "2", "3"), "--mass 1.0 2.0 3.0"),
    ("rotation not unit", lambda d: _good(d, "--wrench-rotation", "0", "0", "0", "0"), "--wrench-rotation"),
    ("vlm without model", lambda d: _good(d, "--vlm", "http://127.0.0.1:9/v1"), "needs --vlm-model"),
    ("mesh units for a scan", lambda d: _good(d, "--mesh-units", "mm"), "--mesh-units mm: only for a mesh"),
    ("out an existing file", lambda d: ["build", str(d / "scan"), "--logs", str(d / "trial.mcap"), "-o",
                                        str(d / "report.pdf")], "report.pdf: exists and is not a folder"),
    ("out a user's folder", lambda d: ["build", str(d / "scan"), "--logs", str(d / "trial.mcap"), "-o",
                                       str(d / "mine")], "mine: folder holds files twin did not write"),
    ("out unwritable", lambda d: ["build", str(d / "scan"), "--logs", str(d / "trial.mcap"), "-o", "/proc/twin"],
     "/proc/twin: cannot create it"),
    ("scan with a mesh source", _with_source("box.obj", "--scan", "scan"), "--scan needs scan folders"),
    ("mesh in millimetres", _with_source("box_mm.stl"), "box_mm.stl:"),
    ("mesh a speck", _with_source("speck.stl"), "speck.stl:"),
    ("mesh not watertight", _with_source("open.stl"), "open.stl:"),
    ("mesh garbage", _with_source("garbage.ply"), "garbage.ply:"),
    ("transforms fl_x 400 digits", _with_source("scan_huge_fx"), "transforms.json:"),
    ("transforms depth unit 400 digits", _with_source("scan_huge_unit"), "transforms.json:"),
    ("transforms matrix entry 400 digits", _with_source("scan_huge_matrix"), "transforms.json"),
    ("transforms no frames", _with_source("scan_no_frames"), "transforms.json:"),
    ("transforms cut short", _with_source("scan_bad_json"), "transforms.json:"),
    ("depth image missing", _with_source("scan_missing_depth"), "frame_00003.png"),
    ("depth png bomb", _with_source("scan_bomb"), "frame_00002.png"),
    ("mask png damaged", _with_source("scan_bad_mask"), "frame_00001.png"),
    ("object.json a list", _with_source("scan_bad_object_json"), "object.json:"),
    ("mcap random bytes", _with_logs("random.mcap"), "random.mcap:"),
    ("mcap truncated", _with_logs("truncated.mcap"), "truncated.mcap:"),
    ("wrench of 1e300 N", _with_logs("huge_wrench.mcap"), "huge_wrench.mcap:"),
    ("pose and wrench never overlap", _with_logs("apart.mcap"), "apart.mcap:"),
    ("push trial holding 5", lambda d: _with_logs(f"push_five/{PUSH_NAME}.json", "--kind", "sliding")(d), ".json:"),
    ("push trial holding null", lambda d: _with_logs(f"push_null/{PUSH_NAME}.json", "--kind", "sliding")(d),
     ".json:"),
    ("push trial tip_pose {}", lambda d: _with_logs(f"push_tip_empty/{PUSH_NAME}.json", "--kind", "sliding")(d),
     ".json:"),
    ("push h5 tip_pose a group", lambda d: _with_logs(f"push_h5/{PUSH_NAME}.h5", "--kind", "sliding")(d), ".h5:"),
    ("diagnose asset.json without theta", lambda d: ["diagnose", str(d / "asset_no_theta"), "--logs",
                                                      str(d / "trial.mcap")], "asset.json:"),
    ("diagnose asset.json a list", lambda d: ["diagnose", str(d / "asset_list"), "--logs", str(d / "trial.mcap")],
     "asset.json:"),
    ("diagnose no asset.json", lambda d: ["diagnose", str(d / "empty_dir"), "--logs", str(d / "trial.mcap")],
     "asset.json: not found"),
    ("inspect missing file", lambda d: ["inspect", str(d / "nowhere.mcap")], "nowhere.mcap:"),
    ("inspect not mcap", lambda d: ["inspect", str(d / "notes.txt")], "notes.txt:"),
    ("synth into a user's folder", lambda d: ["synth", "-o", str(d / "mine")], "mine: folder exists and is not empty"),
]


def _snapshot(folder: Path) -> dict:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_the_table_has_forty_rows_or_more():
    assert len(ROWS) >= 40 and len({name for name, _, _ in ROWS}) == len(ROWS)


@pytest.mark.parametrize("name,argv,expected", ROWS, ids=[r[0] for r in ROWS])
def test_bad_input_is_one_line_and_out_is_untouched(d, capsys, name, argv, expected):
    protected = {p: _snapshot(d / p) for p in ("out", "mine")}
    siblings = sorted(p.name for p in d.iterdir())
    rc = main(argv(d))
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip() and not line.startswith("twin: warning: ")]
    assert rc == 1, err
    assert len(lines) == 1 and lines[0].startswith("twin: error: "), err
    assert expected in lines[0], lines[0]
    assert {p: _snapshot(d / p) for p in protected} == protected
    assert sorted(p.name for p in d.iterdir()) == siblings  # no temporary folder left beside OUT
