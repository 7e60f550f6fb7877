"""A real block's exported scene.xml in MuJoCo: the MIT block pushes of `twin bench push-real` (benchmarks/push.py)
fitted per support model, exported as a build exports them and replayed on a held-out bag, beside Newton's replay
of the same fit (BENCHMARKS.md, the MIT Al_block scene.xml row; docs/pushes.md). Run as
`python3 -c "from benchmarks.push_scene import bench_push_real_scene; bench_push_real_scene()"`.
"""

from __future__ import annotations

import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

from benchmarks.push import BLOCKS, DATA, block_prior, read_block_trial


def bench_push_real_scene(root: Path = DATA, block: str = "Al_block", fitted: str = "Test_metal_1",
                          held_out: str = "Test_metal_2", window_s: float = 0.5) -> list[dict]:
    """A real block's exported scene.xml replaying a held-out bag in MuJoCo, per support model: fitted on
    `fitted` (mu and I_zz, the mass the prior's), exported as a build exports it (the block's box as its
    collision mesh, resting on a plane) and replayed on `held_out` in `window_s` windows from measured states
    (`replay_pushed_mujoco`), beside Newton's replay of the same fit on the same windows (final sample and
    all samples). A row per support model, marked where `choose_support` keeps it (BENCHMARKS.md, "Pushed
    objects in MuJoCo: scene.xml")."""
    import trimesh

    from assets import Asset, Estimate, Geometry, Material, Pose, Theta
    from exporters import export_all
    from pipelines.identify.sliding import (
        SUPPORTS, SlidingConfig, SlidingRollout, choose_support, estimate_force_bias, push_windows, replay_errors,
    )
    from pipelines.validate import replay_pushed_mujoco

    spec = next(b for b in BLOCKS if b.folder == block)
    bags = root / "ros2_mcap" / block
    trial, heldout = read_block_trial(bags / fitted, spec), read_block_trial(bags / held_out, spec)
    body, mu_prior = block_prior(spec)
    half = np.asarray(spec.half_extents_m)
    rows = []
    config = SlidingConfig()
    check = push_windows(heldout, body, config, estimate_force_bias(heldout, config))
    windows = push_windows(trial, body, config, estimate_force_bias(trial, config))
    choice, fits = choose_support(windows, check, body, mu_prior, config, SUPPORTS)
    for support in SUPPORTS:
        fit = fits[support]
        support_config = replace(config, support=support)
        mu, mass, izz = (float(v) for v in fit.theta)
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp)
            (out / "meshes").mkdir()
            box = trimesh.creation.box(extents=2 * half)
            box.export(out / "meshes" / "visual.obj")
            box.export(out / "meshes" / "collision_000.obj")
            a, b, c = 2 * half
            # the prior's box tensor scaled to the fitted I_zz, as a build scales it (physically consistent)
            inertia = np.diag([b * b + c * c, a * a + c * c, a * a + b * b]) * izz / (a * a + b * b)
            asset = Asset(
                name="block", kind="sliding", placement=Pose((0.0, 0.0, half[2]), (0.0, 0.0, 0.0, 1.0)),
                theta=Theta(mass=Estimate(mass, 0.0), com=Estimate((0.0, 0.0, 0.0), (0.0, 0.0, 0.0)),
                            inertia=Estimate(tuple(map(tuple, inertia)), None), friction=Estimate(mu, 0.0)),
                geometry=Geometry("meshes/visual.obj", ("meshes/collision_000.obj",)),
                material=Material(spec.material, mass / (8 * float(np.prod(half))), mu),
                provenance={"identify": {"support": {"model": support}}})
            paths = export_all(asset, out)
            mujoco = replay_pushed_mujoco(paths.scene, asset, heldout, window_s, support_config)
        check_config = replace(support_config, window_s=window_s)
        replayed = push_windows(heldout, body, check_config, estimate_force_bias(heldout, check_config))
        rollout = SlidingRollout(replayed, body, check_config)
        residual = rollout.residuals(fit.theta)
        newton_final = float(np.sqrt(np.mean(np.sum(residual[-1, :, :2] ** 2, axis=-1))))
        rows.append({"support": support, "kept": support == choice.support, "mu": mu,
                     "izz_over_prior": izz / body.izz_kgm2,
                     "mujoco_final_mm": 1e3 * mujoco["rmse_final_position_m"],
                     "mujoco_all_mm": 1e3 * mujoco["rmse_position_m"],
                     "mujoco_heading_deg": float(np.degrees(mujoco["rmse_heading_rad"])),
                     "newton_final_mm": 1e3 * newton_final,
                     "newton_all_mm": 1e3 * replay_errors(rollout, fit.theta)[0], "why": choice.words})
    print(f"{block}: fitted on {fitted}, {held_out} replayed in {window_s} s windows")
    print(f"{'support':8} {'kept':4} {'mu':>6} {'Izz/prior':>9} {'MuJoCo final mm':>15} {'all mm':>6} "
          f"{'head deg':>8} {'Newton final mm':>15} {'all mm':>6}")
    for r in rows:
        print(f"{r['support']:8} {'yes' if r['kept'] else '':4} {r['mu']:6.3f} {r['izz_over_prior']:9.2f} "
              f"{r['mujoco_final_mm']:15.2f} {r['mujoco_all_mm']:6.2f} {r['mujoco_heading_deg']:8.2f} "
              f"{r['newton_final_mm']:15.2f} {r['newton_all_mm']:6.2f}")
    print(choice.words)
    return rows
