"""asset.json (schema "twin.asset/1") reading and writing.

Reading checks every key before building the model (`asset_from_json`): anything an Asset cannot hold
is an `AssetError` naming the file and the key path, e.g. `out/asset.json: theta.mass.value: expected a
mass > 0, got -1.0`. Unknown top-level keys are allowed (the contract lets tools add them); unknown keys
inside the model's records are not, as they would be lost on writing.
"""

from __future__ import annotations

import json
import math
import numbers
from dataclasses import asdict
from pathlib import Path
from typing import get_args

import numpy as np

from .model import (
    KINDS, Asset, Effect, Estimate, Fit, FitMetrics, Geometry, Inertial, Joint, Material, Pose, Source, Theta,
)

SCHEMA = "twin.asset/1"
_THETA_FIELDS = ("mass", "com", "inertia", "friction")


def asset_to_json(asset: Asset) -> dict:
    """The asset.json document; keys follow DESIGN.md's contract."""
    theta = asset.theta
    doc = {
        "schema": SCHEMA,
        "name": asset.name,
        "kind": asset.kind,
        "placement": asset.placement.to_json(),
        "theta": {
            "mass": theta.mass.to_json(),
            "com": theta.com.to_json(),
            "inertia": theta.inertia.to_json(),
            "friction": theta.friction.to_json(),
            **{name: e.to_json() for name, e in theta.determined},
        },
        "material": asdict(asset.material),
        "geometry": {"visual": asset.geometry.visual, "collision": list(asset.geometry.collision),
                     **({"base": asset.geometry.base} if asset.geometry.base else {}),
                     **({"extent": asset.geometry.extent} if asset.geometry.extent else {})},
        "effects": [asdict(e) for e in asset.effects],
        "unexplained": list(asset.unexplained),
        "flags": list(asset.flags),
        "files": dict(asset.files),
        "provenance": asset.provenance,
    }
    if asset.joint is not None:
        doc["joint"] = asdict(asset.joint)
    if asset.fit is not None:
        doc["fit"] = asdict(asset.fit)
    return doc


class AssetError(ValueError):
    """An asset.json that cannot be read: `<file>: <key path>: <what is wrong>`, on one line."""


_UNIT_TOL = 1e-3
"""How far from 1 the norm of a quaternion or joint axis may be: four written digits, as people type them."""
_SYMMETRY_TOL = 1e-9
"""Relative asymmetry an inertia tensor may have; the writer's are symmetric to the last bit."""
_LISTS = (list, tuple)
"""JSON arrays: lists once parsed, tuples in a document fresh from `asset_to_json`."""


def _json_kind(value) -> str:
    if value is None:
        return "null"
    if isinstance(value, (bool, np.bool_)):
        return "a boolean"
    if isinstance(value, numbers.Real):
        return "a number"
    return {str: "a string", list: "a list", tuple: "a list", dict: "an object"}.get(type(value),
                                                                                   type(value).__name__)


class _Checker:
    """Typed access to a parsed asset.json; each failure is an AssetError naming the source and the key path."""

    def __init__(self, source: str):
        self.source = source

    def fail(self, key: str, problem: str):
        raise AssetError(f"{self.source}: {key}: {problem}" if key else f"{self.source}: {problem}")

    def object(self, key: str, value, required=(), optional=None) -> dict:
        """`value` as a JSON object holding `required`; with `optional` given, no other keys."""
        if not isinstance(value, dict):
            self.fail(key, f"expected an object, got {_json_kind(value)}")
        missing = [k for k in required if k not in value]
        if missing:
            self.fail(f"{key}.{missing[0]}" if key else missing[0], "missing")
        if optional is not None:
            unknown = sorted(set(value) - set(required) - set(optional), key=str)
            if unknown:
                self.fail(key, f"unknown key {unknown[0]!r} (expected {', '.join((*required, *optional))})")
        return value

    def string(self, key: str, value, choices=None, optional=False, empty=False) -> str | None:
        """A string: one of `choices` when given, else non-empty unless `empty`; None too when `optional`."""
        if value is None and optional:
            return None
        if not isinstance(value, str):
            what = "a string" if choices or empty else "a non-empty string"
            self.fail(key, f"expected {what}, got {_json_kind(value)}")
        if choices is not None and value not in choices:
            self.fail(key, f"expected one of {choices}, got {value!r}")
        if not value and not empty:
            self.fail(key, "expected a non-empty string")
        return value

    def list(self, key: str, value, item=None) -> list:
        if not isinstance(value, _LISTS):
            self.fail(key, f"expected a list, got {_json_kind(value)}")
        if item is not None:
            for i, v in enumerate(value):
                item(f"{key}.{i}", v)
        return value

    def number(self, key: str, value, low=None, strict=False, finite=True) -> float:
        """A JSON number (no boolean), never NaN, finite unless not `finite`; >= low (> low when strict)."""
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
            self.fail(key, f"expected a number, got {_json_kind(value)}")
        try:
            x = float(value)
        except OverflowError:
            self.fail(key, "expected a finite number, got an integer too large for a float")
        if math.isnan(x) or (finite and math.isinf(x)):
            self.fail(key, f"expected a {'finite ' if finite else ''}number, got {x}")
        if low is not None and not (x > low if strict else x >= low):
            self.fail(key, f"expected a number {'>' if strict else '>='} {low:g}, got {x:g}")
        return x

    def array(self, key: str, value, shape: tuple[int, ...], low=None, finite=True) -> np.ndarray:
        """Nested lists of numbers of exactly `shape` (a number for ())."""
        if not shape:
            return np.array(self.number(key, value, low=low, finite=finite))
        n = shape[0]
        what = f"{n} numbers" if len(shape) == 1 else f"{n} rows"
        if not isinstance(value, _LISTS):
            self.fail(key, f"expected {what}, got {_json_kind(value)}")
        if len(value) != n:
            self.fail(key, f"expected {what}, got {len(value)}")
        return np.array([self.array(f"{key}.{i}", v, shape[1:], low, finite) for i, v in enumerate(value)])

    def unit(self, key: str, value, n: int, what: str) -> np.ndarray:
        a = self.array(key, value, (n,))
        norm = float(np.linalg.norm(a))
        if abs(norm - 1.0) > _UNIT_TOL:
            self.fail(key, f"norm {norm:.6g}, expected a unit {what}")
        return a

    def shape_of(self, key: str, value) -> tuple[int, ...]:
        """The shape a number, vector or matrix claims by its first elements (checked by `array`)."""
        shape = []
        while isinstance(value, _LISTS):
            if not value or len(shape) == 2:
                self.fail(key, "expected a number, a vector or a matrix")
            shape.append(len(value))
            value = value[0]
        return tuple(shape)

    def estimate(self, key: str, value, shape: tuple[int, ...] | None) -> Estimate:
        """An Estimate whose value has `shape` (None: a number, vector or matrix, whichever it is)."""
        d = self.object(key, value, ("value",), ("std", "source", "interval95", "prior"))
        if shape is None:
            shape = self.shape_of(f"{key}.value", d["value"])
        self.array(f"{key}.value", d["value"], shape)
        if d.get("std") is not None:  # an undetermined quantity's spread may be infinite
            self.array(f"{key}.std", d["std"], shape, low=0.0, finite=False)
        self.string(f"{key}.source", d.get("source", "measured"), get_args(Source))
        if d.get("interval95") is not None:
            pair = self.list(f"{key}.interval95", d["interval95"])
            if len(pair) != 2:
                self.fail(f"{key}.interval95", f"expected [lower, upper], got {len(pair)} entries")
            lo, hi = (self.array(f"{key}.interval95.{i}", b, shape, finite=False) for i, b in enumerate(pair))
            if np.any(lo > hi):
                self.fail(f"{key}.interval95", "a lower bound above its upper one")
        if d.get("prior") is not None:
            self.object(f"{key}.prior", d["prior"])
        return Estimate.from_json(d)


def _theta(c: _Checker, doc) -> Theta:
    t = c.object("theta", doc, _THETA_FIELDS)
    mass = c.estimate("theta.mass", t["mass"], ())
    if not mass.value > 0:
        c.fail("theta.mass.value", f"expected a mass > 0, got {mass.value}")
    com = c.estimate("theta.com", t["com"], (3,))
    inertia = c.estimate("theta.inertia", t["inertia"], (3, 3))
    friction = c.estimate("theta.friction", t["friction"], ())
    I = np.array(inertia.value, dtype=float)
    if np.max(np.abs(I - I.T)) > _SYMMETRY_TOL * np.max(np.abs(I)):
        c.fail("theta.inertia.value", f"not symmetric ({I.tolist()})")
    try:
        violation = Inertial(mass.value, com.value, I).physical_violation()
    except ValueError as exc:  # entries near the largest float overflow as the tensor is symmetrised
        c.fail("theta.inertia.value", str(exc))
    if violation:
        c.fail("theta.inertia.value", violation)
    determined = tuple((k, c.estimate(f"theta.{k}", v, None)) for k, v in t.items() if k not in _THETA_FIELDS)
    return Theta(mass, com, inertia, friction, determined)


def _joint(c: _Checker, doc, kind: str) -> Joint | None:
    if kind in ("free", "sliding"):
        if doc is not None:
            c.fail("joint", f"kind {kind!r} takes no joint")
        return None
    if doc is None:
        c.fail("joint", f"kind {kind!r} needs a joint")
    j = c.object("joint", doc, ("type", "axis", "origin", "lower", "upper"),
                 ("damping", "stiffness", "spring_ref", "axis_std_rad", "origin_std_m", "friction_grip_s"))
    if j["type"] != kind:
        c.string("joint.type", j["type"], ("prismatic", "revolute"))
        c.fail("joint.type", f"{j['type']!r}, but kind is {kind!r}")
    c.unit("joint.axis", j["axis"], 3, "vector")
    c.array("joint.origin", j["origin"], (3,))
    lower, upper = c.number("joint.lower", j["lower"]), c.number("joint.upper", j["upper"])
    if not lower < upper:
        c.fail("joint.lower", f"{lower:g} is not below joint.upper {upper:g}")
    c.number("joint.damping", j.get("damping", 0.0), low=0.0)
    c.number("joint.stiffness", j.get("stiffness", 0.0))
    c.number("joint.spring_ref", j.get("spring_ref", 0.0))
    if j.get("axis_std_rad") is not None:
        c.number("joint.axis_std_rad", j["axis_std_rad"], low=0.0, finite=False)
    if j.get("origin_std_m") is not None:
        c.array("joint.origin_std_m", j["origin_std_m"], (3,), low=0.0, finite=False)
    if j.get("friction_grip_s") is not None:
        c.number("joint.friction_grip_s", j["friction_grip_s"], low=0.0, strict=True)
    return Joint(**{**j, "axis": tuple(j["axis"]), "origin": tuple(j["origin"]),
                    **({"origin_std_m": tuple(j["origin_std_m"])} if j.get("origin_std_m") is not None else {})})


def _fit(c: _Checker, doc) -> Fit | None:
    if doc is None:
        return None
    f = c.object("fit", doc, ("baseline", "final", "window_s"), ())

    def metrics(which: str) -> FitMetrics:
        m = c.object(f"fit.{which}", f[which], ("rmse_position_m", "rmse_rotation_rad", "loss"), ())
        for name, v in m.items():  # a replay that diverged is reported as an infinite error
            c.number(f"fit.{which}.{name}", v, low=0.0, finite=False)
        return FitMetrics(**m)

    return Fit(metrics("baseline"), metrics("final"), c.number("fit.window_s", f["window_s"], low=0.0, strict=True))


def _effect(c: _Checker, key: str, doc) -> Effect:
    e = c.object(key, doc, ("name", "params"), ("evidence",))
    c.string(f"{key}.name", e["name"])
    c.object(f"{key}.params", e["params"])
    c.object(f"{key}.evidence", e.get("evidence", {}))
    return Effect(**e)


def asset_from_json(doc, path: Path | str | None = None) -> Asset:
    """The Asset an asset.json document describes, every key checked.

    Raises AssetError `<path>: <key path>: <what is wrong>` (path "asset.json" when none is given) for a
    missing key, a wrong type, a non-finite number, a mass <= 0, an unphysical inertia (asymmetric, not
    positive definite or breaking the triangle inequality), a quaternion or joint axis of norm other
    than 1, a joint that does not fit the kind, or an empty joint range.
    """
    c = _Checker(str(path) if path is not None else "asset.json")
    c.object("", doc, ("schema", "name", "kind", "placement", "theta", "material", "geometry"))
    if doc["schema"] != SCHEMA:
        c.fail("schema", f"expected {SCHEMA!r}, got {doc['schema']!r}")
    kind = c.string("kind", doc["kind"], KINDS)
    p = c.object("placement", doc["placement"], ("position", "quaternion_xyzw"), ())
    placement = Pose(tuple(c.array("placement.position", p["position"], (3,))),
                     tuple(c.unit("placement.quaternion_xyzw", p["quaternion_xyzw"], 4, "quaternion")))
    g = c.object("geometry", doc["geometry"], ("visual", "collision"), ("base", "extent"))
    m = c.object("material", doc["material"], ("name", "density", "friction"),
                 ("restitution", "text", "source", "match_score"))
    c.string("material.name", m["name"])
    c.number("material.density", m["density"], low=0.0, strict=True)
    c.number("material.friction", m["friction"])
    restitution = c.number("material.restitution", m.get("restitution", 0.0), low=0.0)
    if restitution > 1.0:
        c.fail("material.restitution", f"expected a number <= 1, got {restitution:g}")
    c.string("material.text", m.get("text"), optional=True, empty=True)
    c.string("material.source", m.get("source", "library"))
    if m.get("match_score") is not None and not 0.0 <= c.number("material.match_score", m["match_score"]) <= 1.0:
        c.fail("material.match_score", f"expected a number in [0, 1], got {m['match_score']:g}")
    return Asset(
        name=c.string("name", doc["name"]),
        kind=kind,
        placement=placement,
        theta=_theta(c, doc["theta"]),
        geometry=Geometry(c.string("geometry.visual", g["visual"]),
                          tuple(c.list("geometry.collision", g["collision"], c.string)),
                          c.string("geometry.base", g.get("base"), optional=True),
                          c.object("geometry.extent", g["extent"]) if g.get("extent") is not None else None),
        material=Material(**m),
        joint=_joint(c, doc.get("joint"), kind),
        effects=tuple(_effect(c, f"effects.{i}", e) for i, e in enumerate(c.list("effects", doc.get("effects", [])))),
        fit=_fit(c, doc.get("fit")),
        unexplained=tuple(c.list("unexplained", doc.get("unexplained", []), c.object)),
        flags=tuple(c.list("flags", doc.get("flags", []), c.object)),
        files=c.object("files", doc.get("files", {})),
        provenance=c.object("provenance", doc.get("provenance", {})),
    )


def write_asset(asset: Asset, path: Path) -> None:
    Path(path).write_text(json.dumps(asset_to_json(asset), indent=2) + "\n")


def read_asset(path: Path) -> Asset:
    """The asset an asset.json file describes; AssetError naming the file for anything else (asset_from_json)."""
    try:
        doc = json.loads(Path(path).read_text())
    except OSError as exc:
        raise AssetError(f"{path}: cannot read ({exc.strerror or type(exc).__name__})") from None
    except (ValueError, RecursionError) as exc:  # bad UTF-8 or JSON, nesting past the recursion limit, a huge number
        raise AssetError(f"{path}: not valid JSON ({type(exc).__name__}: {exc})") from None
    return asset_from_json(doc, path)
