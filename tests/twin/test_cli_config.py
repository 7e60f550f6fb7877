"""Each stage's settings reach the build from the command line, whole, under the stage's prefix."""

from __future__ import annotations

from pathlib import Path

import twin.build
from twin.cli import main


def test_stage_settings_reach_the_build_config(tmp_path, monkeypatch):
    seen = []
    monkeypatch.setattr(twin.build, "build", lambda config, log=None: seen.append(config))
    mesh, log = tmp_path / "part.obj", tmp_path / "trial.mcap"
    code = main(["build", str(mesh), "--logs", str(log), "--reconstruct.voxel-size-m", "0.002",
                 "--decompose.max-convex-hull", "16", "--diagnosis.bootstraps", "7", "--mass", "1.5"])
    assert code == 0
    (config,) = seen
    assert config.reconstruct.voxel_size_m == 0.002
    assert config.decompose.max_convex_hull == 16
    assert config.diagnosis.bootstraps == 7
    assert config.mass_kg == (1.5, 0.0075)
    assert config.source == Path(mesh) and config.logs == (Path(log),)


def test_defaults_are_the_stages_own():
    from pipelines.decompose import DecomposeConfig
    from pipelines.diagnose import DiagnoseConfig
    from pipelines.reconstruct import ReconstructConfig
    from twin.stages import BuildConfig

    config = BuildConfig(source=Path("x.obj"), logs=())
    assert (config.reconstruct, config.decompose, config.diagnosis) == (
        ReconstructConfig(), DecomposeConfig(), DiagnoseConfig())
