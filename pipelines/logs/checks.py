"""What a recording holds is checked before anything downstream sees it: `LogError` for what cannot be
read, and the clean-up of one stream (non-finite samples, repeated stamps, stamps far outside the rest)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

__all__ = ["LogError", "MAX_FORCE_N", "MAX_POSITION_M", "MAX_TORQUE_NM", "bounded", "clean_stream",
           "drop_far_stamps", "require_overlap"]

_FAR_STAMP_SPREADS = 1000.0
"""A stamp farther from its stream's median stamp than this many spreads (the stamps' median absolute
deviation, at least the median gap) is a glitch, not a pause: one message stamped at 2^31 s among stamps
near 0 would stretch the recording over 68 years, and a pose grid over it would need terabytes."""
MAX_FORCE_N = 1e5
MAX_TORQUE_NM = 1e4
MAX_POSITION_M = 1e6
"""Beyond these a value is no measurement of a robot pushing an object (a unit or encoding error): it
would only surface later as a singular fit."""


class LogError(ValueError):
    """A recording that cannot be read; the message starts with the file path."""


def _at(t: float) -> str:
    """A stamp for a message: to the millisecond (UNIX stamps need all ten digits before the point)."""
    return f"{t:.3f}" if abs(t) < 1e12 else f"{t:.3g}"


def _samples_word(n: int) -> str:
    return f"{n} sample" if n == 1 else f"{n} samples"


def _far_stamps(t: np.ndarray) -> np.ndarray:
    """Mask of the stamps of a sorted, repeat-free stream that lie far outside its bulk.

    Far is more than `_FAR_STAMP_SPREADS` spreads from the median stamp, the spread being the stamps'
    median absolute deviation or the median gap if larger (so that three samples, two close together,
    do not make the third an outlier). The median sample is never far, so something always remains.
    """
    t = np.asarray(t, dtype=float)
    if len(t) < 3:
        return np.zeros(len(t), dtype=bool)
    middle = np.median(t)
    spread = max(float(np.median(np.abs(t - middle))), float(np.median(np.diff(t))))
    return np.abs(t - middle) > _FAR_STAMP_SPREADS * spread


def clean_stream(path: Path, topic: str, t: np.ndarray, arrays: list[np.ndarray], ok: np.ndarray | None = None,
           required: bool = False):
    """Drop non-finite / invalid rows and stamps far from the rest, sort by stamp, keep the first of equal stamps.

    A few non-finite samples are glitches and go with a warning; a `required` stream (pose, wrench) mostly
    non-finite is broken (LogError), and so is any stream with nothing left.
    """
    n = len(t)
    finite = np.isfinite(t)
    for a in arrays:
        finite &= np.all(np.isfinite(a.reshape(n, -1)), axis=1)
    non_finite = int(np.sum(~finite))
    if required and 2 * non_finite > n:
        raise LogError(f"{path}: {topic}: {non_finite} of {n} samples hold non-finite stamps or values")
    keep = finite if ok is None else finite & ok
    dropped = int(np.sum(~keep))
    if dropped:
        warnings.warn(f"{path}: {topic}: dropped {_samples_word(dropped)} with non-finite or invalid values",
                      stacklevel=3)
    t = t[keep]
    arrays = [a[keep] for a in arrays]
    order = np.argsort(t, kind="stable")
    t = t[order]
    arrays = [a[order] for a in arrays]
    first = np.ones(len(t), dtype=bool)
    first[1:] = np.diff(t) > 0
    dup = int(np.sum(~first))
    if dup:
        warnings.warn(f"{path}: {topic}: dropped {_samples_word(dup)} with repeated stamps", stacklevel=3)
    if not np.any(first):
        raise LogError(f"{path}: topic {topic} has no usable samples")
    return drop_far_stamps(path, topic, t[first], [a[first] for a in arrays])


def drop_far_stamps(path: Path, topic: str, t: np.ndarray, arrays: list[np.ndarray]):
    """The rows of a sorted, repeat-free stream less those stamped far outside the rest, with a warning."""
    far = _far_stamps(t)
    if not far.any():
        return t, arrays
    near = t[~far]
    warnings.warn(
        f"{path}: {topic}: dropped {_samples_word(int(far.sum()))} stamped far outside the rest "
        f"({_at(near[0])}..{_at(near[-1])} s), e.g. at {_at(t[far][0])} s",
        stacklevel=4,
    )
    return near, [a[~far] for a in arrays]


def require_overlap(path: Path, first: str, t_first: np.ndarray, second: str, t_second: np.ndarray) -> None:
    """LogError unless two streams share some time: on clocks that never meet, nothing can be paired."""
    if t_first[-1] < t_second[0] or t_second[-1] < t_first[0]:
        raise LogError(
            f"{path}: {first} stamps {_at(t_first[0])}..{_at(t_first[-1])} s and {second} stamps "
            f"{_at(t_second[0])}..{_at(t_second[-1])} s do not overlap"
        )


def bounded(path: Path, topic: str, what: str, t: np.ndarray, values: np.ndarray, limit: float, unit: str) -> None:
    """LogError if a component of a row exceeds `limit` in magnitude (see `MAX_FORCE_N`)."""
    size = np.max(np.abs(values), axis=1)
    beyond = np.flatnonzero(size > limit)
    if beyond.size:
        i = int(beyond[0])
        raise LogError(
            f"{path}: {topic}: {what} of {size[i]:.3g} {unit} at {_at(t[i])} s is beyond {limit:g} {unit} "
            f"({beyond.size} of {len(t)} samples)"
        )
