"""Candidate effects for a held (free) body, in the DESIGN.md vocabulary.

Each candidate says how it enters the Newton-Euler regression (its columns, so
screening and least-squares refits can weigh it), how its fitted coefficients
become named SI parameters, how those parameters drive the Newton model (the
effect vector read by `apply_effect_wrench`, or a shift of the wrench stamps),
and whether it belongs to the object (exported) or to the recording
(`asset.json` only). A jointed kind adds its own candidates of the same type.

Regression conventions (tracked-frame axes, wrench about the tracked origin,
measured = applied + what the effect adds to the robot's measured wrench):
  sensor_bias:     + (force, torque), constant in the wrench message's frame (DESIGN.md): six constant
                   columns for a sensor turning with the tracked frame, the world's axes turned into the
                   tracked frame's sample by sample for a message in world axes (`FramedRows`)
  time_delay:      measured(t) = applied(t - d) ~ applied(t) - d dw/dt
  viscous_damping: the robot also pushes against -b v_com and -b_angular omega
  quadratic_drag:  ... and against -c |v_com| v_com
nonuniform_density has no columns: it is the identified COM against the
uniform-density prior's, tested in `select`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable, Literal

import numpy as np

from pipelines.identify import EFFECT_SIZE, NewtonEulerRows

Belongs = Literal["object", "recording"]


@dataclass(frozen=True)
class Candidate:
    """One effect: regression columns, parameter names with prior scales, and where it goes.

    columns(rows, com_tracked) -> [N, 6, k]; params(coefficients [k]) -> dict of SI values;
    prior_scale: a typical magnitude per coefficient (ranks screening, bounds refits);
    effect_slots: indices in the rollout's effect vector that the coefficients fill
    (None: the effect is applied by shifting the wrench stamps, see `time_delay`).
    main: the parameter that measures its size.
    """

    name: str
    columns: Callable[[NewtonEulerRows, np.ndarray], np.ndarray]
    params: Callable[[np.ndarray], dict]
    prior_scale: tuple[float, ...]
    effect_slots: tuple[int, ...] | None
    belongs: Belongs
    main: str

    @property
    def size(self) -> int:
        return len(self.prior_scale)


def _com_velocity(rows: NewtonEulerRows, com_tracked: np.ndarray) -> np.ndarray:
    return rows.velocity + np.cross(rows.omega, com_tracked)


@dataclass(frozen=True)
class FramedRows(NewtonEulerRows):
    """Rows whose wrench message was in axes fixed in the world: tracked_from_message [N, 3, 3] turns them
    into the tracked frame's at each row (None: the message's axes turn with the tracked frame)."""

    tracked_from_message: np.ndarray | None = None


def framed_rows(rows: NewtonEulerRows, recording) -> NewtonEulerRows:
    """`rows` of `recording`, told the wrench message's axes when they do not turn with the tracked frame (a
    world-frame message): the tracked frame's orientation interpolated at each row."""
    if recording.wrench_turns_with_pose:
        return rows
    from scipy.spatial.transform import Rotation, Slerp

    p = recording.pose
    R = Slerp(p.t_s, Rotation.from_quat(p.quat_xyzw))(np.clip(rows.t_s, p.t_s[0], p.t_s[-1]))
    return FramedRows(**{f: getattr(rows, f) for f in rows.__dataclass_fields__},
                      tracked_from_message=R.inv().as_matrix())


def bias_in_tracked_axes(recording) -> bool:
    """Whether a sensor_bias of `recording` is constant in the tracked frame's axes (its wrench message turns
    with it) rather than in the world's."""
    return bool(recording.wrench_turns_with_pose)


def remove_bias(recording, force_n, torque_nm):
    """`recording` with a bias constant in world axes taken off its wrench (world axes, torque about the tracked
    origin): measured = applied + bias."""
    w = recording.wrench
    wrench = replace(w, force=w.force - np.asarray(force_n), torque=w.torque - np.asarray(torque_nm))
    return replace(recording, wrench=wrench)


def without_recording_effects(recording, effects):
    """`recording` as the object saw it: the wrench without a `sensor_bias` (constant in world axes, or in the
    tracked frame's where its message turns with it, as `diagnose_held` reports it) and as it acted under a
    `time_delay` (`Recording.wrench_acted`). effects: (name, params) pairs; others are ignored.
    """
    from scipy.spatial.transform import Rotation

    for name, params in effects:
        w = recording.wrench
        if name == "time_delay":
            raw = recording.wrench_raw
            recording = replace(recording, wrench=recording.wrench_acted(params["seconds"]),
                                wrench_raw=replace(raw, t_s=raw.t_s - params["seconds"]))
        elif name == "sensor_bias" and not bias_in_tracked_axes(recording):
            recording = remove_bias(recording, params["force"], params["torque"])
        elif name == "sensor_bias":
            R = Rotation.from_quat(recording.pose.interpolate(w.t_s)[1])
            recording = replace(recording, wrench=replace(w, force=w.force - R.apply(params["force"]),
                                                          torque=w.torque - R.apply(params["torque"])))
    return recording


def _bias_columns(rows, com_tracked):
    R = getattr(rows, "tracked_from_message", None)
    if R is None:
        return np.broadcast_to(np.eye(6), (len(rows.t_s), 6, 6))
    out = np.zeros((len(rows.t_s), 6, 6))
    out[:, :3, :3] = R
    out[:, 3:, 3:] = R
    return out


def _delay_columns(rows, com_tracked):
    return -np.gradient(rows.b, 1.0 / rows.rate_hz, axis=0)[:, :, None]


def _force_at_com_columns(force: np.ndarray, com_tracked: np.ndarray) -> np.ndarray:
    """A force through the COM as a wrench about the tracked origin, [N, 6, 1]."""
    return np.concatenate([force, np.cross(com_tracked, force)], axis=1)[:, :, None]


def _damping_columns(rows, com_tracked):
    angular = np.concatenate([np.zeros_like(rows.omega), rows.omega], axis=1)[:, :, None]
    return np.concatenate([_force_at_com_columns(_com_velocity(rows, com_tracked), com_tracked), angular], axis=2)


def _drag_columns(rows, com_tracked):
    v = _com_velocity(rows, com_tracked)
    return _force_at_com_columns(np.linalg.norm(v, axis=1, keepdims=True) * v, com_tracked)


CANDIDATES: dict[str, Candidate] = {
    c.name: c
    for c in (
        Candidate("sensor_bias", _bias_columns,
                  lambda x: {"force": [float(v) for v in x[:3]], "torque": [float(v) for v in x[3:6]]},
                  (0.05,) * 3 + (0.005,) * 3, (0, 1, 2, 3, 4, 5), "recording", "force"),
        Candidate("time_delay", _delay_columns, lambda x: {"seconds": float(x[0])}, (0.01,), None, "recording",
                  "seconds"),
        Candidate("viscous_damping", _damping_columns, lambda x: {"b": float(x[0]), "b_angular": float(x[1])},
                  (0.05, 1e-4), (6, 7), "object", "b"),
        Candidate("quadratic_drag", _drag_columns, lambda x: {"c": float(x[0])}, (0.05,), (8,), "object", "c"),
    )
}
"""Candidates with regression columns, in screening order."""

NONUNIFORM_DENSITY = "nonuniform_density"
EFFECT_NAMES = (*CANDIDATES, NONUNIFORM_DENSITY)


def main_magnitude(name: str, params: dict) -> float:
    """The size of an effect by its main parameter (vector parameters by their norm)."""
    key = CANDIDATES[name].main if name in CANDIDATES else "com_shift"
    return float(np.linalg.norm(np.atleast_1d(params[key])))


def effect_vector(names_and_coefficients: dict[str, np.ndarray]) -> np.ndarray:
    """The rollout's effect vector [EFFECT_SIZE] for fitted coefficients by candidate name."""
    out = np.zeros(EFFECT_SIZE)
    for name, x in names_and_coefficients.items():
        slots = CANDIDATES[name].effect_slots
        if slots is not None:
            out[list(slots)] = x
    return out
