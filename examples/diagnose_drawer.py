"""Find the physics a drawer's model leaves out: a viscous damping hidden in its slide is named and measured.

RigPI's drawer is pulled back and forth on its slide for 8 s, twice (a trial and a held-out recording, Newton's
engine, the sensors' noise), with a damping b q' that twin's base model (mass and Coulomb friction) does not
have, its force at the drawer's mean speed 6x the effort noise. The diagnosis refits each candidate (damping,
a spring, Stribeck friction) with the body, keeps one only when it predicts the held-out recording
significantly better, and reports the held-out error before and after.

    python examples/diagnose_drawer.py          # prints what was found
    python examples/diagnose_drawer.py --test   # and asserts it (tests/test_examples.py)
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from assets.materials import material_range
from pipelines.diagnose import DiagnoseConfig, diagnose
from pipelines.identify import JointedConfig, JointedPart, detect_kind
from pipelines.logs import read_recording
from pipelines.priors import uniform_density_prior
from pipelines.synth.effects import concealed_joint_effect
from pipelines.synth.held import SensorNoise
from pipelines.synth.jointed import JointedMotionConfig, jointed_paper_objects, simulate_jointed, write_jointed_recording

RATIO = 6.0
"""The hidden damping's force at the drawer's mean speed, in units of the effort noise."""


def record(directory: Path, seed: int = 11):
    """The trial and held-out recordings of the drawer with the damping hidden, and the damping."""
    drawer = jointed_paper_objects()["drawer"]
    rng = np.random.default_rng(seed)
    effect = concealed_joint_effect("viscous_damping", RATIO, rng, drawer, SensorNoise())
    recordings = []
    for name in ("trial", "heldout"):
        motion = simulate_jointed(drawer, JointedMotionConfig(), rng, effect=effect)
        path = write_jointed_recording(directory / f"{name}.mcap", drawer, motion, SensorNoise(), rng)
        recordings.append(read_recording(path))
    return drawer, effect, recordings


def main(test: bool = False) -> None:
    with tempfile.TemporaryDirectory(prefix="twin-example-") as tmp:
        drawer, effect, (trial, heldout) = record(Path(tmp))
    joint = detect_kind(trial).joint  # the slide's axis and type, from the motion alone
    prior = uniform_density_prior(drawer.mesh(), material_range(None)).inertial
    part = JointedPart(joint, drawer.placement(), prior, JointedConfig())
    diagnosis, refit = diagnose(part, [trial], heldout, DiagnoseConfig())
    truth = effect.params["b"]
    print(f"hidden: viscous_damping b = {truth:.3f} N s/m")
    for found in diagnosis.effects:
        print(f"found:  {found.name} {found.params}")
    if not diagnosis.effects:
        print("found:  nothing")
    before, after = diagnosis.fits["before"].rmse_position_m, diagnosis.fits["after"].rmse_position_m
    print(f"held-out replay RMS: {before * 1e3:.3f} mm before, {after * 1e3:.3f} mm after")
    if test:
        assert [e.name for e in diagnosis.effects] == ["viscous_damping"], diagnosis.effects
        b = diagnosis.effects[0].params["b"]
        assert abs(b / truth - 1) < 0.15, f"b {b:.3f} against {truth:.3f}"
        assert refit is not None and after < before


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--test", action="store_true", help="assert what the diagnosis finds")
    main(parser.parse_args().test)
