"""Tests for pipelines.push_dataset: the MIT pushing dataset's trial files, read as they are."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pipelines.logs import LogError
from pipelines.push_dataset import PushTrialName, read_push_trial

DATASET = (Path(__file__).parents[2] / ".." / "shared" / "data" / "mit-push" / "mit_push_dataset").resolve()
RAW = DATASET / "h5_raw" / "motion_surface=delrin_shape=rect1_a=0_v=10_i=0.000_s=0.000_t=-1.396.h5"
ACCEL = DATASET / "h5_raw" / "motion_surface=delrin_shape=rect1_a=2500_v=-1_i=3.000_s=1.000_t=-1.396.h5"
JSON = DATASET / "json" / "motion_surface=plywood_shape=hex_a=0_v=150_i=1.000_s=0.000_t=-0.349.json"
needs_data = pytest.mark.skipif(not RAW.exists(), reason="shared data (../shared/data/mit-push) not present")


def test_trial_name_gives_the_push():
    """Surface, object, acceleration, speed, side, point and angle come from the file name."""
    name = PushTrialName.parse(Path("motion_surface=delrin_shape=rect1_a=2500_v=-1_i=3.000_s=1.000_t=-1.396.h5"))
    assert name == PushTrialName("delrin", "rect1", 2500.0, -1.0, 3, 1.0, -1.396)
    with pytest.raises(LogError, match=r"trial\.h5: not a MIT pushing-dataset trial name"):
        PushTrialName.parse(Path("trial.h5"))


@needs_data
def test_real_raw_trial_reads_as_a_push():
    """The raw h5 trial: object pose, the force applied TO the object (the sensor's reading negated),
    the tip as the contact point, all in the robot frame; the object moves along the applied force."""
    rec = read_push_trial(RAW)
    assert len(rec.pose.t_s) == 1237 and len(rec.wrench.t_s) == 1377 and len(rec.contact.t_s) == 1368
    assert rec.duration_s == pytest.approx(5.52, abs=0.02)
    np.testing.assert_array_equal(rec.wrench.force[:, :2], -rec.wrench_raw.force[:, :2])
    # pushing (force above 1 N): the tip is at the face, 45 mm half side plus the 4.75 mm tip, of the rect1 block
    pushing = np.linalg.norm(rec.wrench.force[:, :2], axis=1) > 1.0
    t = rec.wrench.t_s[pushing]
    tip = np.stack([np.interp(t, rec.contact.t_s, rec.contact.position[:, k]) for k in range(2)], axis=1)
    obj, _ = rec.pose.interpolate(t)
    distance = np.linalg.norm(tip - obj[:, :2], axis=1)
    assert 0.045 < np.median(distance) < 0.075
    moved = rec.pose.position[-1, :2] - rec.pose.position[0, :2]
    assert np.linalg.norm(moved) > 0.005
    assert moved @ np.median(rec.wrench.force[pushing, :2], axis=0) > 0


@needs_data
def test_real_trials_with_unordered_stamps_and_json_read():
    """The accelerating trial's object stamps are out of order in the file (sorted on reading); the JSON
    trial holds the same keys."""
    rec = read_push_trial(ACCEL)
    assert np.all(np.diff(rec.pose.t_s) > 0)
    hexagon = read_push_trial(JSON)
    assert hexagon.contact is not None and len(hexagon.pose.t_s) > 100


def test_bad_trial_files_name_the_file_and_the_fault(tmp_path):
    """A missing key, a wrong shape and an unreadable file are LogErrors naming the file."""
    import h5py

    good = np.c_[np.linspace(0, 1, 5), np.zeros((5, 3))]
    missing = tmp_path / "missing.h5"
    with h5py.File(missing, "w") as h5:
        h5["object_pose"] = good
        h5["tip_pose"] = good
    with pytest.raises(LogError, match=r"missing\.h5: missing datasets \['ft_wrench'\]"):
        read_push_trial(missing)
    narrow = tmp_path / "narrow.h5"
    with h5py.File(narrow, "w") as h5:
        h5["object_pose"] = good
        h5["tip_pose"] = good
        h5["ft_wrench"] = good[:, :3]
    with pytest.raises(LogError, match=r"narrow\.h5: ft_wrench has shape \(5, 3\), expected N x 4"):
        read_push_trial(narrow)
    junk = tmp_path / "junk.h5"
    junk.write_bytes(b"not hdf5")
    with pytest.raises(LogError, match=r"junk\.h5: not a readable HDF5 file"):
        read_push_trial(junk)
