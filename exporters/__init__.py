"""One writer per format: URDF, MJCF, USD.

Each writer takes an `assets.Asset` whose mesh files already lie under
`out_dir` (paths in `asset.geometry` relative to it) and writes one file next
to them, named after the asset: the file names and the names inside the files
(bodies, links, joints, prims) are derived from `asset.name` by
`exporters.names`, which writers and pipelines/validate.py share. The body frame
of every file is the object frame. A pushed object (kind "sliding") also gets
`scene.xml`: its MJCF on a support plane (`exporters.mjcf.export_scene`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from assets import Asset

from .mjcf import export_mjcf, export_scene
from .names import FormatNames
from .urdf import export_urdf
from .usd import export_usd

__all__ = ["ExportPaths", "FormatNames", "export_all", "export_mjcf", "export_scene", "export_urdf", "export_usd"]


@dataclass(frozen=True)
class ExportPaths:
    """The written files; keys match asset.json → files. `scene` only for pushed objects."""

    urdf: Path
    mjcf: Path
    usd: Path
    scene: Path | None = None

    def to_json(self, relative_to: Path | None = None) -> dict[str, str]:
        """{"urdf", "mjcf", "usd"} and "scene" where written, as strings, relative to `relative_to` when given."""
        out = {}
        for key in ("urdf", "mjcf", "usd", "scene"):
            if getattr(self, key) is None:
                continue
            p = Path(getattr(self, key))
            out[key] = str(p.relative_to(relative_to) if relative_to is not None else p)
        return out


def export_all(asset: Asset, out_dir: Path) -> ExportPaths:
    """Write NAME.urdf, NAME.xml and NAME.usda into `out_dir`, NAME `FormatNames.of(asset.name).file`, and
    scene.xml for a pushed object."""
    mjcf = export_mjcf(asset, out_dir)
    return ExportPaths(
        urdf=export_urdf(asset, out_dir),
        mjcf=mjcf,
        usd=export_usd(asset, out_dir),
        scene=export_scene(asset, out_dir, mjcf) if asset.kind == "sliding" else None,
    )
