"""What every writer checks before it writes: collision parts, a physical body, a joint with a sane range."""

from __future__ import annotations

from pathlib import Path

from assets import Asset, Inertial

FREE_KINDS: tuple[str, ...] = ("free", "sliding")
"""Kinds written as one body on a free joint; the others as a fixed base plus the part on `asset.joint`."""


def exportable_inertial(asset: Asset, path: Path, writer: str) -> Inertial:
    """The asset's inertial parameters, or ValueError naming `path` if it cannot be written.

    An unphysical tensor is refused: MuJoCo rejects it and Newton silently "balances" it.
    """
    if asset.joint is not None and not asset.joint.lower < asset.joint.upper:
        raise ValueError(f"{path}: {writer}: joint range [{asset.joint.lower}, {asset.joint.upper}] is empty")
    if not asset.geometry.collision:
        raise ValueError(f"{path}: asset {asset.name!r} has no collision parts")
    inertial = asset.theta.inertial()
    if violation := inertial.physical_violation():
        raise ValueError(f"{path}: cannot write asset {asset.name!r}: {violation}")
    return inertial
