"""asset.json (schema "twin.asset/1") reading and writing."""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

from .model import Asset, Effect, Estimate, Fit, FitMetrics, Geometry, Joint, Material, Pose, Theta

SCHEMA = "twin.asset/1"
_THETA_FIELDS = ("mass", "com", "inertia", "friction")


def asset_to_json(asset: Asset) -> dict:
    """The asset.json document; keys follow DESIGN.md's contract."""
    theta = asset.theta
    doc = {
        "schema": SCHEMA,
        "name": asset.name,
        "kind": asset.kind,
        "placement": {
            "position": list(asset.placement.position),
            "quaternion_xyzw": list(asset.placement.quaternion_xyzw),
        },
        "theta": {
            "mass": theta.mass.to_json(),
            "com": theta.com.to_json(),
            "inertia": theta.inertia.to_json(),
            "friction": theta.friction.to_json(),
            **{name: e.to_json() for name, e in theta.determined},
        },
        "material": asdict(asset.material),
        "geometry": {"visual": asset.geometry.visual, "collision": list(asset.geometry.collision),
                     **({"base": asset.geometry.base} if asset.geometry.base else {})},
        "effects": [asdict(e) for e in asset.effects],
        "unexplained": list(asset.unexplained),
        "files": dict(asset.files),
        "provenance": asset.provenance,
    }
    if asset.joint is not None:
        doc["joint"] = asdict(asset.joint)
    if asset.fit is not None:
        doc["fit"] = asdict(asset.fit)
    return doc


def asset_from_json(doc: dict) -> Asset:
    if doc.get("schema") != SCHEMA:
        raise ValueError(f"asset.json: expected schema {SCHEMA!r}, got {doc.get('schema')!r}")
    t = doc["theta"]
    fit = doc.get("fit")
    return Asset(
        name=doc["name"],
        kind=doc["kind"],
        placement=Pose(doc["placement"]["position"], doc["placement"]["quaternion_xyzw"]),
        theta=Theta(*(Estimate.from_json(t[k]) for k in _THETA_FIELDS),
                    determined=tuple((k, Estimate.from_json(v)) for k, v in t.items() if k not in _THETA_FIELDS)),
        geometry=Geometry(doc["geometry"]["visual"], tuple(doc["geometry"]["collision"]), doc["geometry"].get("base")),
        material=Material(**doc["material"]),
        joint=Joint(**doc["joint"]) if doc.get("joint") else None,
        effects=tuple(Effect(**e) for e in doc.get("effects", [])),
        fit=Fit(FitMetrics(**fit["baseline"]), FitMetrics(**fit["final"]), fit["window_s"]) if fit else None,
        unexplained=tuple(doc.get("unexplained", [])),
        files=doc.get("files", {}),
        provenance=doc.get("provenance", {}),
    )


def write_asset(asset: Asset, path: Path) -> None:
    Path(path).write_text(json.dumps(asset_to_json(asset), indent=2) + "\n")


def read_asset(path: Path) -> Asset:
    try:
        doc = json.loads(Path(path).read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise ValueError(f"{path}: cannot read asset.json ({exc})") from exc
    return asset_from_json(doc)
