"""`twin diagnose`: the diagnose stage alone, on the asset a build wrote and recordings of the object."""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

from assets import asset_to_json, read_asset, write_asset
from pipelines.diagnose import DiagnoseConfig
from twin.checks import check_recording_path
from twin.report import write_report
from twin.stages import BuildConfig, BuildError, StageTimer, log_diagnosis


@dataclass(frozen=True)
class DiagnoseRunConfig:
    """`twin diagnose`: the diagnose stage alone on a built OUT and recordings."""

    output: Path
    logs: tuple[Path, ...]
    holdout: Path | None = None
    diagnosis: DiagnoseConfig = DiagnoseConfig()


def diagnose_output(config: DiagnoseRunConfig, log: Callable[[str], None] = print) -> Path:
    """Diagnose the asset in config.output against recordings; rewrite its asset.json and report.html.

    The identified parameters and exported files stay as built (`twin build` carries chosen effects into
    them); effects, unexplained and provenance.diagnose are replaced.
    """
    from pipelines.diagnose import diagnose
    from pipelines.identify import subject_from_json

    out = Path(config.output)
    if not (out / "asset.json").is_file():
        raise BuildError(f"{out}/asset.json: not found; run `twin build` into {out} first")
    if not config.logs:
        raise BuildError("--logs: no recording given; pass --logs TRIAL.mcap")
    for path in config.logs:
        check_recording_path(path)
    if config.holdout:
        check_recording_path(config.holdout, "--holdout")
    asset = read_asset(out / "asset.json")
    try:
        subject = subject_from_json(asset.provenance["subject"])
    except (KeyError, TypeError, ValueError) as exc:
        raise BuildError(f"{out}/asset.json: provenance holds no readable subject ({exc}); rebuild it with this "
                         "version of twin") from exc
    timer = StageTimer(log)
    # the recordings are read with the options the asset was built with (topics, frames, sensor rotation)
    built = asset.provenance.get("config", {})
    reader = BuildConfig(source=out, logs=(), topics=tuple(map(tuple, built.get("topics", ()))),
                         frames=tuple(map(tuple, built.get("frames", ()))),
                         wrench_rotation_xyzw=built.get("wrench_rotation_xyzw"),
                         wrench_reaction=bool(built.get("wrench_reaction", False)))
    trials = [reader.read(p) for p in config.logs]
    holdout = reader.read(config.holdout) if config.holdout else None
    diagnosis, _ = timer.run("diagnose", diagnose, subject, trials, holdout, config.diagnosis)
    log_diagnosis(diagnosis, log)
    run = {"logs": [str(p) for p in config.logs], "holdout": str(config.holdout) if config.holdout else None}
    asset = replace(asset, effects=diagnosis.effects, unexplained=diagnosis.unexplained,
                    provenance={**asset.provenance, "diagnose": diagnosis.provenance() | {"run": run}})
    # written beside and moved over: a reader, or an interrupt, sees the old files or the new ones
    with tempfile.TemporaryDirectory(prefix=".twin-", dir=out) as tmp:
        write_asset(asset, Path(tmp) / "asset.json")
        write_report(Path(tmp) / "report.html", asset_to_json(asset), (), None, diagnosis.traces)
        for name in ("asset.json", "report.html"):
            os.replace(Path(tmp) / name, out / name)
    log(f"updated {out}/asset.json and report.html")
    return out
