"""Build the bundled drawer's assets from its mesh and two recordings, as `twin build` does, and hold them to
the truth the sample was made with.

The drawer (samples/drawer: RigPI's drawer on its slide, pulled by a robot, Newton's engine) is built from its
part mesh with a cabinet as the fixed base: the kind of motion is found from the trial, the Featherstone fit
measures the mass and the joint friction (the COM and inertia stay the geometry prior's, which one slide cannot
tell), the exports are written and read back, and the held-out recording is replayed in Newton and in MuJoCo.
`twin diagnose` then runs the diagnosis again on the built output, from the part the build recorded.

    python examples/build_drawer.py [OUT]          # builds into OUT (default: a temporary folder) and prints
    python examples/build_drawer.py --test         # and asserts it (tests/test_examples.py)
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import trimesh

from twin.build import BuildConfig, DiagnoseRunConfig, build, diagnose_output

SAMPLE = Path(__file__).resolve().parents[1] / "samples" / "drawer"


def main(out: Path | None = None, test: bool = False) -> None:
    with tempfile.TemporaryDirectory(prefix="twin-example-") as tmp:
        out = out or Path(tmp) / "out"
        cabinet = Path(tmp) / "cabinet.obj"
        trimesh.creation.box((0.5, 0.4, 0.3), transform=trimesh.transformations.translation_matrix((0.9, 0, 0.3))
                             ).export(cabinet)
        build(BuildConfig(source=SAMPLE / "part.obj", logs=(SAMPLE / "trial.mcap",), holdout=SAMPLE / "heldout.mcap",
                          base_mesh=cabinet, output=out), log=print)
        doc = json.loads((out / "asset.json").read_text())
        files_present = all((out / doc["files"][k]).is_file() for k in ("urdf", "mjcf", "usd", "report"))
        # `twin diagnose` later, on the same recordings: the part as the build recorded it, the same diagnosis
        diagnose_output(DiagnoseRunConfig(out, (SAMPLE / "trial.mcap",), SAMPLE / "heldout.mcap"), log=print)
        again = json.loads((out / "asset.json").read_text())["provenance"]["diagnose"]
    truth = json.loads((SAMPLE / "truth.json").read_text())
    theta, joint, replay = doc["theta"], doc["joint"], doc["provenance"]["heldout_replay"]
    mass_err = theta["mass"]["value"] / truth["mass"] - 1
    friction_err = theta["friction"]["value"] / truth["joint"]["friction"] - 1
    print(f"{doc['kind']} joint; mass {theta['mass']['value']:.4f} kg ({theta['mass']['source']}, {100 * mass_err:+.2f} %), "
          f"friction {theta['friction']['value']:.4f} N ({theta['friction']['source']}, {100 * friction_err:+.2f} %)")
    print(f"held-out replay RMS: Newton {replay['newton']['rmse_position_m'] * 1e3:.3f} mm, "
          f"MuJoCo (the exported MJCF) {replay['mujoco']['rmse_position_m'] * 1e3:.3f} mm; effects {doc['effects']}")
    if test:
        assert doc["kind"] == "prismatic" and joint["type"] == "prismatic" and 0 < joint["axis_std_rad"] < 0.01
        assert theta["mass"]["source"] == "measured" and abs(mass_err) < 0.03, theta["mass"]
        assert theta["friction"]["source"] == "measured" and abs(friction_err) < 0.05, theta["friction"]
        assert theta["com"]["source"] == "prior" and theta["inertia"]["source"] == "prior"
        lo, hi = theta["inertia"]["interval95"]
        assert all(lo[k][k] <= truth["inertia"][k][k] <= hi[k][k] for k in range(3)), theta["inertia"]
        travel = doc["provenance"]["kind"]["joint"]["observed_travel"]
        assert joint["lower"] < travel[0] and joint["upper"] > travel[1]
        assert len(doc["provenance"]["validation"]) == 5 and files_present
        assert replay["mujoco"]["rmse_position_m"] < 0.005 and replay["newton"]["rmse_position_m"] < 0.005
        assert doc["effects"] == [], "a clean drawer's diagnosis names nothing"
        built = doc["provenance"]["diagnose"]
        assert (again["scores"], again["fits"]) == (built["scores"], built["fits"]), "the same part, the same diagnosis"
        identify = doc["provenance"]["identify"]
        kept = {"newton": "Newton fit: ", "least_squares": "least-squares fit: "}[identify["selected"]]
        assert identify["choice"].startswith(kept) and "two standard errors" in identify["choice"], identify["choice"]


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", nargs="?", type=Path, help="output folder (default: a temporary one)")
    parser.add_argument("--test", action="store_true", help="assert the build against the sample's truth")
    args = parser.parse_args()
    main(args.out, args.test)
