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


TRIAL = "motion_surface=abs_shape=rect1_a=0_v=10_i=0.000_s=0.000_t=0.698"


def _trial(n: int = 20) -> dict[str, np.ndarray]:
    """A push along x at 10 mm/s for 1 s, each stream on its own clock, as the dataset holds them."""
    s = np.linspace(0.0, 1.0, n)
    t, zero = 1.46e9 + s, np.zeros(n)
    return {"object_pose": np.c_[t, 0.3 + 0.01 * s, zero, zero],
            "tip_pose": np.c_[t + 0.002, 0.25 + 0.01 * s, zero, zero],
            "ft_wrench": np.c_[t + 0.001, np.full(n, -1.0), zero, zero]}


def _write_json(path: Path, doc) -> Path:
    import json

    path.write_text(json.dumps(doc))
    return path


@pytest.mark.parametrize("doc, fault", [
    (5, "expected an object holding .* got a number"),
    (None, "expected an object holding .* got null"),
    ([], "expected an object holding .* got a list"),
    ({"object_pose": [[0, 0, 0, 0]] * 2, "ft_wrench": [[0, 0, 0, 0]] * 2, "tip_pose": {}},
     "tip_pose: expected an N x 4 array of numbers, got an object"),
    ({"object_pose": [[0, 0, 0, 0], [1, 0, 0, 0]], "ft_wrench": [[0, 0, 0, 0], [1, 0, 0, 0]],
      "tip_pose": [[0, 0, "x", 0], [1, 0, 0, 0]]}, "tip_pose: expected"),
    ({"object_pose": [[0, 0, 0, 0], [1, 0, 0, 0]], "ft_wrench": [[0, 0, 0, 0], [1, 0, 0]],
      "tip_pose": [[0, 0, 0, 0], [1, 0, 0, 0]]}, "ft_wrench: expected"),
    ({"object_pose": [[0, 0, 0, 0], [0, 1, 0, 0]], "ft_wrench": [[0, 0, 0, 0], [1, 0, 0, 0]],
      "tip_pose": [[0, 0, 0, 0], [1, 0, 0, 0]]}, "object_pose: 1 distinct stamp"),
])
def test_json_trials_of_the_wrong_shape_are_log_errors(tmp_path, doc, fault):
    """A document that is no object, or a key that is no N x 4 numeric array with two distinct stamps, is a
    LogError naming the file and the key (not a TypeError from deep inside numpy)."""
    path = _write_json(tmp_path / f"{TRIAL}.json", doc)
    with pytest.raises(LogError, match=rf"{TRIAL}\.json: {fault}") as err:
        read_push_trial(path)
    assert "\n" not in str(err.value)


def test_h5_trial_whose_key_is_a_group_or_text_is_a_log_error(tmp_path):
    """`tip_pose` as an HDF5 group, as strings, or as an empty dataset: LogErrors naming file and key."""
    import h5py

    def write(name, tip):
        path = tmp_path / name
        with h5py.File(path, "w") as h5:
            for k, v in _trial().items():
                if k != "tip_pose":
                    h5[k] = v
            tip(h5)
        return path

    with pytest.raises(LogError, match=r"group\.h5: tip_pose: expected an N x 4 array of numbers, got an HDF5 group"):
        read_push_trial(write("group.h5", lambda h5: h5.create_group("tip_pose")))
    with pytest.raises(LogError, match=r"text\.h5: tip_pose: expected .* numbers, got text"):
        read_push_trial(write("text.h5", lambda h5: h5.create_dataset("tip_pose", data=np.array([b"a"] * 8))))
    with pytest.raises(LogError, match=r"empty\.h5: tip_pose: expected .* numbers, got an empty dataset"):
        read_push_trial(write("empty.h5", lambda h5: h5.create_dataset("tip_pose", data=h5py.Empty("f8"))))


def test_push_trial_values_out_of_reason_are_log_errors_and_far_stamps_warnings(tmp_path):
    """A force of 1e300 N is a LogError naming the key; object and force streams on clocks that never
    overlap are a LogError naming both ranges; a stray stamp is dropped with a warning."""
    doc = {k: v.tolist() for k, v in _trial().items()}
    doc["ft_wrench"][4][1] = 1e300
    with pytest.raises(LogError, match=rf"{TRIAL}\.json: ft_wrench: force of 1e\+300 N"):
        read_push_trial(_write_json(tmp_path / f"{TRIAL}.json", doc))

    apart = {k: v.tolist() for k, v in _trial().items()}
    apart["ft_wrench"] = (np.array(apart["ft_wrench"]) + [100.0, 0, 0, 0]).tolist()
    with pytest.raises(LogError, match=r"object_pose stamps .* and ft_wrench stamps .* do not overlap"):
        read_push_trial(_write_json(tmp_path / f"{TRIAL}.json", apart))

    stray = {k: v.tolist() for k, v in _trial().items()}
    stray["object_pose"][7][0] = 2.0**31 * 1e3
    with pytest.warns(UserWarning, match=rf"{TRIAL}\.json: object_pose: dropped 1 sample stamped far"):
        rec = read_push_trial(_write_json(tmp_path / f"{TRIAL}.json", stray))
    assert len(rec.pose.t_s) == 19 and rec.duration_s < 2.0
