"""The writing stage of `twin build`: the meshes, the provenance, asset.json and report.html, all into the
staging folder that `twin.output.staged_output` swaps in once everything is written and validated."""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING

from assets import Asset, Geometry, asset_to_json, write_asset
from twin.report import write_report
from twin.summary import summary_lines

if TYPE_CHECKING:
    from exporters import ExportPaths
    from twin.stages import Identified, Prepared

VISUAL = "meshes/visual.obj"
BASE = "meshes/base.obj"


def collision_paths(parts) -> tuple[str, ...]:
    """meshes/collision_NNN.obj, one per convex part, relative to the output."""
    return tuple(f"meshes/collision_{k:03d}.obj" for k in range(len(parts.parts)))


def mesh_geometry(parts, extent: dict | None, base_mesh: Path | None = None) -> Geometry:
    """The asset's mesh files as `write_meshes` writes them."""
    return Geometry(VISUAL, collision_paths(parts), BASE if base_mesh else None, extent)


def write_meshes(tmp: Path, mesh_object, parts, base_mesh: Path | None = None, mesh_units: str | None = None) -> None:
    """meshes/visual.obj, meshes/collision_NNN.obj and, given a base mesh file, meshes/base.obj under `tmp`."""
    (tmp / "meshes").mkdir()
    mesh_object.export(tmp / VISUAL)
    for rel, part in zip(collision_paths(parts), parts.parts):
        part.export(tmp / rel)
    if base_mesh:
        from pipelines.meshes import read_mesh

        read_mesh(base_mesh, mesh_units or "m", solid=False).export(tmp / BASE)


def output_files(paths: ExportPaths, tmp: Path, identified: Identified) -> dict[str, str]:
    """asset.json → files: the exported formats and the report, relative to the output."""
    return {**paths.to_json(relative_to=tmp), **({"report": "report.html"} if identified.report else {})}


def build_provenance(p: Prepared, identified: Identified, validation: dict, replay: dict | None) -> dict:
    """asset.json → provenance: the configuration, each stage's record, and the time each took."""
    return {
        "config": json.loads(json.dumps(asdict(p.config), default=str)),
        "scan": p.scan_stats,
        "decompose": identified.decompose,
        "prior": p.prior.provenance(),
        "kind": p.detection.to_json(),
        **identified.provenance,
        "validation": validation,
        **({"heldout_replay": replay} if replay is not None else {}),
        "timings_s": p.timer.seconds | {"total": p.timer.elapsed()},
    }


def write_results(tmp: Path, p: Prepared, identified: Identified, files: dict, validation: dict,
                  replay: dict | None) -> Asset:
    """asset.json (with its files and provenance) and report.html under `tmp`; returns the written asset."""
    asset = Asset(**{**identified.asset.__dict__, "files": files,
                     "provenance": build_provenance(p, identified, validation, replay)})
    write_asset(asset, tmp / "asset.json")
    if identified.report is not None:
        write_report(tmp / "report.html", asset_to_json(asset), *identified.report)
    return asset


def log_summary(doc: dict, log) -> None:
    log("summary:")
    for line in summary_lines(doc):
        log(f"  {line}")
