"""What every writer checks before it writes: a supported kind, collision parts, a physical body."""

from __future__ import annotations

from pathlib import Path

from assets import Asset, Inertial

FREE_KINDS: tuple[str, ...] = ("free", "sliding")


def exportable_inertial(asset: Asset, path: Path, writer: str) -> Inertial:
    """The asset's inertial parameters, or ValueError naming `path` if it cannot be written.

    An unphysical tensor is refused: MuJoCo rejects it and Newton silently "balances" it.
    """
    if asset.kind not in FREE_KINDS:
        raise ValueError(f"{writer}: kind {asset.kind!r} is not supported yet (only {FREE_KINDS})")
    if not asset.geometry.collision:
        raise ValueError(f"{path}: asset {asset.name!r} has no collision parts")
    inertial = asset.theta.inertial()
    if violation := inertial.physical_violation():
        raise ValueError(f"{path}: cannot write asset {asset.name!r}: {violation}")
    return inertial
