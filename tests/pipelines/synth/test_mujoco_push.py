"""The MuJoCo push engine: the force's sign and frames, Coulomb friction at mu, and its truth model's replay."""

from __future__ import annotations

import json
from dataclasses import replace

import mujoco
import numpy as np
import pytest

from pipelines.identify.sliding import PlanarBody
from pipelines.logs import read_recording
from pipelines.synth.mujoco_push import (
    PushContact,
    PushedSampleConfig,
    make_pushed_sample,
    push_settings,
    pushed_block_xml,
    simulate_pushed_mujoco,
    write_pushed_mujoco,
)
from pipelines.synth.push import PushConfig
from pipelines.validate import replay_pushed_model

QUIET = dict(force_noise_n=0.0, position_noise_m=0.0, yaw_noise_rad=0.0)


def test_steady_centred_push_needs_mu_m_g_along_the_push():
    """A centred push at constant speed: the sensor gives the force applied TO the block, along +y, at the
    Coulomb value mu m g of MuJoCo's elliptic cone (within 2 %), and the block does not turn."""
    config = PushConfig(mu=0.4, mass_kg=0.6, offset_m=0.0, yaw0_rad=0.0, speed_m_s=0.05, stroke_s=4.0, push_s=1.5,
                        idle_s=0.3)
    data, truth = simulate_pushed_mujoco(config)
    t = data["t_s"]
    steady = (t > config.idle_s + 0.9) & (t < config.idle_s + 1.4)  # the stroke's hold, the block sliding
    speed = np.gradient(data["position"][:, 1], t)
    assert np.all(speed[steady] > 0.03)
    np.testing.assert_allclose(np.median(data["force"][steady], axis=0), [0.0, truth.mu * truth.mass_kg * 9.81],
                               rtol=0.02, atol=0.02)
    assert np.abs(np.diff(np.unwrap(2 * np.arctan2(data["quat_xyzw"][:, 2], data["quat_xyzw"][:, 3])))).sum() < 1e-3


def test_world_and_sensor_frame_recordings_read_to_the_same_force(tmp_path):
    """The force written in the sensor's axes (through /tf_static) and in world's reads back as one world force."""
    config = PushConfig(push_s=1.0, **QUIET)
    reads = {}
    for frame in ("world", "sensor"):
        write_pushed_mujoco(tmp_path / f"{frame}.mcap", config, wrench_frame=frame)
        reads[frame] = read_recording(tmp_path / f"{frame}.mcap")
    assert reads["sensor"].wrench_raw.frame_id == "pusher_ft"
    assert np.abs(reads["sensor"].wrench_raw.force - reads["world"].wrench_raw.force).max() > 0.5  # turned
    np.testing.assert_allclose(reads["sensor"].wrench.force[:, :2], reads["world"].wrench.force[:, :2], atol=1e-3)
    with pytest.raises(ValueError, match="wrench_frame"):
        write_pushed_mujoco(tmp_path / "x.mcap", config, wrench_frame="gripper")


def test_truth_model_replays_its_own_recording(tmp_path):
    """Driven by the recorded force at the recorded tip, the pusher-less model that made a noise-free push
    follows it within 2 mm over 0.3 s windows (each starts at a velocity estimated from the poses, which a
    sharp stop spoils); 20 % more friction is 4x further off."""
    config = PushConfig(mu=0.3, mass_kg=0.8, offset_m=0.015, yaw0_rad=0.2, push_s=1.2, **QUIET)
    write_pushed_mujoco(tmp_path / "push.mcap", config)
    rec = read_recording(tmp_path / "push.mcap")
    planar = PlanarBody(config.half_extents_m, config.mass_kg, 1e-3)
    errors = {}
    for mu in (0.3, 0.36):
        model = mujoco.MjModel.from_xml_string(pushed_block_xml(replace(config, mu=mu), push_settings(),
                                                                PushContact(), pusher=False))
        errors[mu] = replay_pushed_model(model, "block", planar, rec, 0.3)["rmse_position_m"]
    assert errors[0.3] < 2e-3 and errors[0.36] > 4 * errors[0.3]


def test_truth_model_replays_a_push_with_its_effects(tmp_path):
    """A push with a concealed 30 ms delay and damping: the model that made it, given those effects as a
    pushed asset carries them (`pushed_effects`), replays it far closer than without them."""
    from assets import Effect
    from pipelines.validate import pushed_effects

    config = PushConfig(mu=0.3, mass_kg=0.8, offset_m=0.015, yaw0_rad=0.2, push_s=1.2, delay_s=0.03,
                        damping_n_s_m=3.0, **QUIET)
    write_pushed_mujoco(tmp_path / "push.mcap", config)
    rec = read_recording(tmp_path / "push.mcap")
    planar = PlanarBody(config.half_extents_m, config.mass_kg, 1e-3)
    effects = pushed_effects((Effect("time_delay", {"seconds": 0.03}, {}),
                              Effect("viscous_damping", {"b": 3.0, "b_angular": 0.0}, {})))
    errors = {}
    for label, given in (("without", None), ("with", effects)):
        model = mujoco.MjModel.from_xml_string(pushed_block_xml(config, push_settings(), PushContact(), pusher=False))
        errors[label] = replay_pushed_model(model, "block", planar, rec, 0.3, effects=given)["rmse_position_m"]
    assert errors["with"] < 2e-3 and errors["without"] > 2 * errors["with"]


def test_mesh_block_and_torsional_contact_simulate(tmp_path):
    """The block as a mesh geom with condim 4 under RK4, and on a grid of support spheres: finite pushes that
    move the block; a time constant under two steps is refused."""
    config = PushConfig(push_s=0.6, idle_s=0.2, **QUIET)
    for settings, contact in ((push_settings(integrator="RK4"), PushContact(shape="mesh", condim=4)),
                              (push_settings(), PushContact(shape="grid", grid=4))):
        data, _ = simulate_pushed_mujoco(config, settings, contact)
        assert np.all(np.isfinite(data["position"])) and data["position"][-1, 1] > 0.01
    with pytest.raises(ValueError, match="two steps"):
        simulate_pushed_mujoco(config, contact=PushContact(tip_solref=(0.001, 1.0)))


def test_pushed_sample_writes_what_a_build_reads(tmp_path):
    """make_pushed_sample: the block mesh resting on the table, two recordings and the truth."""
    import trimesh

    push = PushConfig(push_s=0.6, idle_s=0.2)
    make_pushed_sample(tmp_path, PushedSampleConfig(push=push), engine="mujoco", wrench_frame="sensor")
    truth = json.loads((tmp_path / "truth.json").read_text())
    assert truth["kind"] == "sliding" and truth["engine"] == "mujoco" and truth["mu"] == push.mu
    box = trimesh.load(tmp_path / "block.obj")
    np.testing.assert_allclose(box.bounds, [[-0.05, -0.05, 0.0], [0.05, 0.05, 0.01]], atol=1e-9)
    for name in ("trial", "heldout"):
        assert read_recording(tmp_path / f"{name}.mcap").contact is not None
    with pytest.raises(ValueError, match="world axes only"):
        make_pushed_sample(tmp_path, PushedSampleConfig(push=push), engine="newton", wrench_frame="sensor")
