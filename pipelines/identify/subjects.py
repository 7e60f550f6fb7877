"""The body as each kind's model sees it, one type per kind: what the diagnosis needs besides the recordings.

A build records its subject in asset.json (provenance "subject"), and `twin diagnose` reads it back, so a
later diagnosis models the body exactly as the build did (the joint as found then, the support chosen then)
instead of finding them again from other recordings.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

from assets import Inertial, Pose

from .jointed import JointedConfig
from .kind import JointFit
from .sliding import PlanarBody, SlidingConfig


def _tuples(d: dict) -> dict:
    return {k: tuple(v) if isinstance(v, list) else v for k, v in d.items()}


@dataclass(frozen=True)
class HeldBody:
    """Kind "free": a body held and moved. X_tracked_body: the object frame in the tracked frame; uniform: the
    uniform-density body (object frame), the reference of a density shift; window_s: the replay windows [s]."""

    X_tracked_body: Pose
    uniform: Inertial
    window_s: float

    def to_json(self) -> dict:
        return {"kind": "free", "tracked_frame_in_object": self.X_tracked_body.inverse().to_json(),
                "uniform": self.uniform.to_json(), "window_s": self.window_s}

    @staticmethod
    def from_json(d: dict) -> HeldBody:
        return HeldBody(Pose.from_json(d["tracked_frame_in_object"]).inverse(), Inertial.from_json(d["uniform"]),
                        float(d["window_s"]))


@dataclass(frozen=True)
class PushedBody:
    """Kind "sliding": an object pushed over a table. body and mu_prior: the sliding model's prior; config: the
    sliding model as identified, its support the one the pushes chose."""

    body: PlanarBody
    mu_prior: float
    config: SlidingConfig

    def to_json(self) -> dict:
        return {"kind": "sliding", "body": asdict(self.body), "mu_prior": self.mu_prior, "config": asdict(self.config)}

    @staticmethod
    def from_json(d: dict) -> PushedBody:
        return PushedBody(PlanarBody(**_tuples(d["body"])), float(d["mu_prior"]), SlidingConfig(**_tuples(d["config"])))


@dataclass(frozen=True)
class JointedPart:
    """Kinds "prismatic" and "revolute": a part on one joint. joint: as found from the motion; placement: the
    object frame in world at q = 0; prior: the part's prior body (object frame); config: the jointed fit's."""

    joint: JointFit
    placement: Pose
    prior: Inertial
    config: JointedConfig

    def to_json(self) -> dict:
        return {"kind": self.joint.type, "joint": self.joint.to_json(), "placement": self.placement.to_json(),
                "prior": self.prior.to_json(), "config": asdict(self.config)}

    @staticmethod
    def from_json(d: dict) -> JointedPart:
        return JointedPart(JointFit.from_json(d["joint"]), Pose.from_json(d["placement"]),
                           Inertial.from_json(d["prior"]), JointedConfig(**d["config"]))


Subject = HeldBody | PushedBody | JointedPart

_BY_KIND = {"free": HeldBody, "sliding": PushedBody, "prismatic": JointedPart, "revolute": JointedPart}


def subject_from_json(d: dict) -> Subject:
    """The subject a build recorded (`to_json`); KeyError or ValueError where the record is not one."""
    if d.get("kind") not in _BY_KIND:
        raise ValueError(f"subject kind: expected one of {sorted(_BY_KIND)}, got {d.get('kind')!r}")
    return _BY_KIND[d["kind"]].from_json(d)
