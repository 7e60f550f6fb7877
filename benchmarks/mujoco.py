"""`twin bench mujoco`: the paper's recordings identified by MuJoCo's sysid and by ours, side by side.

The held object becomes an MjSpec: one free body whose frame is the tracked
frame, its mass, COM and inertia as sysid's 10-parameter log-Cholesky
pseudo-inertia (`InertiaType.Pseudo`, bounds from our prior's C); six motors
on a site at the body origin (site transmission, gears in the axes of a world
site) apply the measured force and torque about the tracked origin in world
axes; framepos and framequat sensors of that site are compared with the
tracker's poses. The recording is cut into chunks, each started from the
measured state (sysid's multiple shooting: start states are fixed, not fitted),
and `mujoco.sysid.optimize` (mujoco.minimize's Levenberg-Marquardt on
finite-difference Jacobians from batched, threaded `mujoco.rollout`) fits the
trial recording from the same prior as our build; `calculate_intervals` gives
its covariance, carried to (mass, COM, inertia) in the object frame.

What it took on mujoco 4.0.0 (the first four as in notes/anchors.md):
- the pseudo-inertia update leaves the inertia orientation NaN, which fails to
  compile: the modifier resets it to identity;
- rollout sensors are stamped one step late: each chunk's clock starts one step early;
- the default residual divides each column by the chunk's measured magnitude, an
  arbitrary weighting for absolute world positions and quaternion components,
  and per-sensor weight dicts fail for multi-dimensional sensors: a
  `modify_residual` divides position and rotation errors by the tracker's noise
  levels, estimated from the recording as ours does;
- MuJoCo treats an inertial frame within about 1e-6 m of its body frame as the
  body frame, which swallows the finite-difference steps of a COM at the body
  origin (a zero Jacobian column, then a wild step): the body frame is the
  tracked frame, away from the COM;
- mujoco.minimize's damping range is absolute, so with large residuals (a
  noise-free recording) the default unscaled step never shrinks enough:
  x_scale='jac';
- `build_residual_fn` rolls each chunk out by itself and compiles the model
  once per chunk and parameter vector: `model_residual` over all chunks at once
  gives the same residuals in half the time.
"""

from __future__ import annotations

import io
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .paper import paper_cases, spread

SENSOR_POS, SENSOR_QUAT = "tracked_pos", "tracked_quat"
WRENCH_AXES = ("fx", "fy", "fz", "tx", "ty", "tz")


@dataclass(frozen=True)
class SysidConfig:
    """How mujoco.sysid is run (defaults: the best of a sweep on seed 0 of the cube and apple, see BENCHMARKS.md)."""

    chunk_s: float = 0.1
    """Shooting-chunk length [s]; each chunk starts from the measured state."""
    timestep_s: float = 0.001
    """MuJoCo time step [s] (5 steps per 200 Hz pose sample, as our rollout)."""
    integrator: str = "Euler"
    """MuJoCo integrator (its default, semi-implicit Euler, the order of our rollout; RK4 moves inertia errors
    by under a point at twice the time)."""
    max_iters: int = 100
    """Iterations of mujoco.minimize.least_squares (sysid's default backend); it stops on its own far earlier."""
    x_scale: str | None = "jac"
    """Parameter scaling of the Levenberg-Marquardt step. 'jac' (what sysid's conditioning warning recommends)
    reaches the same point as its default None on the noisy recordings, and unlike None it still converges when
    the residuals are large in absolute terms (a noise-free recording: its damping range is absolute)."""
    twist_half_width: int = 2
    """Pose samples each side of a local quadratic fit for a chunk's start twist (our windows use 5)."""
    start_smoothing_hz: float | None = None
    """Zero-phase low-pass of the poses [Hz] that the start states are taken from (None: raw poses)."""
    wrench_smoothing_hz: float | None = 10.0
    """Zero-phase low-pass of the measured wrench [Hz] before it drives the model (None: raw). An output-error
    fit with a noisy input is biased towards large inertia; filtering the input shrinks that bias."""
    batch_chunks: bool = True
    """Roll all chunks out in one `sysid.model_residual` call (one model compile per parameter vector) instead
    of `build_residual_fn`'s call per chunk, which compiles the model once per chunk: same result, half the time."""


# the setting as a user would first try it: our windows' start twists, raw wrench
SYSID_RAW = SysidConfig(twist_half_width=5, wrench_smoothing_hz=None)


@dataclass(frozen=True)
class SysidResult:
    """mujoco.sysid's estimate in the object frame; covariance [10, 10] over (mass, com xyz, Ixx Iyy Izz Ixy
    Ixz Iyz), propagated from its covariance of the log-Cholesky parameters."""

    inertial: object
    covariance: np.ndarray
    theta: np.ndarray
    theta_half_widths: np.ndarray
    iterations: int
    chunk_count: int
    wall_s: float
    log: str = ""


def in_frame(inertial, X):
    """The inertial parameters re-expressed in the frame in which X (a Pose) places their own frame."""
    from assets import Inertial

    R = X.rotation_matrix()
    return Inertial(inertial.mass, R @ np.asarray(inertial.com) + np.asarray(X.position),
                    R @ inertial.inertia_matrix() @ R.T)


def held_spec(prior_tracked, config: "SysidConfig"):
    """MjSpec of the held body with its frame at the tracked frame (`prior_tracked`: the prior's inertial in the
    tracked frame), six motors applying the wrench at its origin in world axes, and its pose sensors.

    The body frame is the tracked frame, not the object frame: MuJoCo treats an inertial frame within ~1e-6 m
    of the body frame as the same frame, which swallows the finite-difference steps of a COM at the origin.
    """
    import mujoco

    I = prior_tracked.inertia_matrix()

    def f(*values):
        return " ".join(f"{float(v):.17g}" for v in values)

    motors = "\n".join(
        f'<motor name="{n}" site="tracked" refsite="world" gear="{" ".join("1" if j == i else "0" for j in range(6))}"/>'
        for i, n in enumerate(WRENCH_AXES)
    )
    xml = f"""<mujoco model="held">
  <option timestep="{config.timestep_s}" integrator="{config.integrator}"><flag contact="disable"/></option>
  <worldbody>
    <site name="world"/>
    <body name="object">
      <freejoint name="free"/>
      <inertial pos="{f(*prior_tracked.com)}" mass="{f(prior_tracked.mass)}"
                fullinertia="{f(I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2])}"/>
      <site name="tracked"/>
    </body>
  </worldbody>
  <actuator>{motors}</actuator>
  <sensor>
    <framepos name="{SENSOR_POS}" objtype="site" objname="tracked"/>
    <framequat name="{SENSOR_QUAT}" objtype="site" objname="tracked"/>
  </sensor>
</mujoco>"""
    return mujoco.MjSpec.from_string(xml)


def pseudo_inertia_parameter(spec, prior, bounds, body_name: str = "object"):
    """sysid's pseudo-inertia Parameter of the body, with box bounds from our prior's C: mass range,
    COM box, and the inertia spread per unit mass as the stretch range; its modifier resets iquat."""
    from mujoco import sysid
    from mujoco.sysid._src.model_modifier import apply_body_theta_inertia

    lo, hi = np.asarray(bounds.lower), np.asarray(bounds.upper)
    com = np.asarray(prior.com)
    # inertia per unit mass may move as far as C lets it at C's extreme masses (at least sysid's default range)
    I0 = np.diag(prior.inertia_matrix())
    stretch = (min(0.5, float(np.min(lo[4:7] / I0) / (lo[0] / prior.mass))),
               max(2.0, float(np.max(hi[4:7] / I0) / (hi[0] / prior.mass))))

    def modifier(s, p):
        apply_body_theta_inertia(s, body_name, p.value)
        s.body(body_name).iquat = [1.0, 0.0, 0.0, 0.0]  # mujoco 4.0.0: NaN iquat fails to compile

    return sysid.body_inertia_param(
        spec, spec.compile(), body_name, sysid.InertiaType.Pseudo,
        mass_bound_mult=np.array([lo[0], hi[0]]) / prior.mass,
        ipos_bound_off=np.array([float(np.max(lo[1:4] - com)), float(np.min(hi[1:4] - com))]),
        stretch_bound_mult=np.array(stretch),
        modifier=modifier,
    )


def _chunks(recording, model, config: SysidConfig):
    """Per chunk: the initial state (clock one step early), the wrench on the MuJoCo time grid (zero-order hold),
    and the measured tracked poses after the start (as sysid TimeSeries); and the time step, a whole fraction
    of the pose period."""
    from mujoco import sysid
    from pipelines.identify.windows import local_twist, lowpass, smoothed_pose_grid, uniform_pose_grid

    pose, wrench = recording.pose, recording.wrench
    grid, pos, rot = uniform_pose_grid(pose.t_s, pose.position, pose.quat_xyzw)
    if config.start_smoothing_hz:
        _, pos_start, rot_start = smoothed_pose_grid(pose.t_s, pose.position, pose.quat_xyzw,
                                                     config.start_smoothing_hz)
    else:
        pos_start, rot_start = pos, rot
    period = grid[1] - grid[0]
    substeps = max(1, int(round(period / config.timestep_s)))
    dt = period / substeps
    samples = max(1, int(round(config.chunk_s / period)))
    t_begin, t_end = max(grid[0], wrench.t_s[0]), min(grid[-1], wrench.t_s[-1])
    first = int(np.searchsorted(grid, t_begin - 1e-9))
    starts = np.arange(first, len(grid) - samples, samples)
    starts = starts[grid[starts + samples] <= t_end + 1e-9]

    q_all = rot.as_quat()  # xyzw
    w_all = np.concatenate([wrench.force, wrench.torque], axis=1)
    if config.wrench_smoothing_hz:
        w_all = lowpass(w_all, config.wrench_smoothing_hz, 1.0 / float(np.median(np.diff(wrench.t_s))))
    initial, controls, sensors = [], [], []
    for i0 in starts:
        twist = local_twist(grid, pos_start, rot_start, i0, config.twist_half_width)
        qx, qy, qz, qw = rot_start[i0].as_quat()
        qpos = np.concatenate([pos_start[i0], [qw, qx, qy, qz]])
        qvel = np.concatenate([twist[:3], rot_start[i0].as_matrix().T @ twist[3:]])  # free joint: body axes
        state = sysid.create_initial_state(model, qpos, qvel)
        state[0] = grid[i0] - dt  # mjSTATE_FULLPHYSICS starts with time: sensors come out one step late
        initial.append(state)

        # steps + 1 steps so the sensor of the chunk's last pose sample is recorded; +1 control sysid drops
        t_ctrl = grid[i0] + dt * np.arange(samples * substeps + 2)
        idx = np.clip(np.searchsorted(wrench.t_s, t_ctrl + 1e-9, side="right") - 1, 0, len(wrench.t_s) - 1)
        controls.append(sysid.TimeSeries(t_ctrl, w_all[idx]))  # on the step grid already: not resampled

        k = i0 + np.arange(1, samples + 1)
        q = q_all[k][:, [3, 0, 1, 2]]
        sensors.append(sysid.TimeSeries.from_names(grid[k], np.concatenate([pos[k], q], axis=1), model))
    return initial, controls, sensors, dt


def _noise_residual(sigma_position_m: float, sigma_rotation_rad: float):
    """modify_residual: tracked-frame position error / sigma_p and rotation-vector error / sigma_r per sample."""
    from mujoco import sysid

    def modify_residual(params, pred, measured, model, return_pred_all, state=None, **_):
        pred_at = pred.resample(measured.times)
        qm, qp = measured.data[:, 3:7], pred_at.data[:, 3:7].copy()
        qp *= np.where(np.sum(qm * qp, axis=1) < 0, -1.0, 1.0)[:, None]
        # rotation error in world axes: 2 vec(q_pred * conj(q_meas)), small angles
        wm, vm, wp, vp = qm[:, :1], qm[:, 1:], qp[:, :1], qp[:, 1:]
        rot_err = 2 * (wm * vp - wp * vm - np.cross(vp, vm))
        res = np.concatenate([(measured.data[:, :3] - pred_at.data[:, :3]) / sigma_position_m,
                              -rot_err / sigma_rotation_rad], axis=1)
        pred_out = sysid.TimeSeries(measured.times, np.concatenate([pred_at.data[:, :3], qp], axis=1),
                                    measured.signal_mapping)
        return res, pred_out, measured

    return modify_residual


def physical_from_pseudo(theta: np.ndarray, X_object_tracked=None) -> np.ndarray:
    """(mass, com xyz, Ixx Iyy Izz Ixy Ixz Iyz about the COM) from sysid's log-Cholesky theta of the body,
    re-expressed in the object frame when X_object_tracked (the tracked frame in the object frame) is given."""
    from mujoco.sysid._src.model_modifier import pi_from_theta, skew

    pi = pi_from_theta(theta)
    m, c = pi[0], pi[1:4] / pi[0]
    I = pi[4:].reshape(3, 3) + m * skew(c) @ skew(c)
    if X_object_tracked is not None:
        R = X_object_tracked.rotation_matrix()
        c, I = R @ c + np.asarray(X_object_tracked.position), R @ I @ R.T
    return np.array([m, *c, I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2]])


def _physical_covariance(theta: np.ndarray, cov_theta: np.ndarray, X_object_tracked) -> np.ndarray:
    """Delta method: G cov G^T with G = d physical / d theta by central differences."""
    G = np.zeros((10, len(theta)))
    for j in range(len(theta)):
        h = 1e-6 * max(1.0, abs(theta[j]))
        e = np.zeros_like(theta)
        e[j] = h
        G[:, j] = (physical_from_pseudo(theta + e, X_object_tracked)
                   - physical_from_pseudo(theta - e, X_object_tracked)) / (2 * h)
    return G @ cov_theta @ G.T


def sysid_held(recording, X_tracked_body, prior, bounds, config: SysidConfig = SysidConfig()) -> SysidResult:
    """Identify the held body from one Recording with mujoco.sysid (pseudo-inertia), started from `prior`
    (object frame, as `bounds`); the result is in the object frame."""
    from mujoco import sysid

    from assets import Inertial
    from pipelines.identify.noise import recording_noise_levels

    t0 = time.perf_counter()
    spec = held_spec(in_frame(prior, X_tracked_body), config)
    model = spec.compile()
    initial, controls, sensors, spec.option.timestep = _chunks(recording, model, config)
    params = sysid.ParameterDict()
    params.add(pseudo_inertia_parameter(spec, prior, bounds))
    noise = recording_noise_levels(recording)
    sequences = sysid.ModelSequences("held", spec, [f"chunk{i}" for i in range(len(initial))], initial, controls,
                                     sensors)
    # floors keep a noise-free recording finite (1 um and 10 urad: the tracker's ratio, 0.1 m per rad)
    modify_residual = _noise_residual(max(noise.position_m, 1e-6), max(noise.rotation_rad, 1e-5))
    if config.batch_chunks:
        def build(p, _spec=sequences.spec):
            return sysid.apply_param_modifiers(p, _spec)

        chunks = len(sequences.measured_rollout)

        def residual_fn(x, p, **_):
            res, _, _ = sysid.model_residual(x, p, build, sequences.measured_rollout, modify_residual,
                                             resample_true=False)
            if x.ndim == 1:
                return [res], None, None
            # model_residual lays out [per-chunk residual, fd column x chunk]: stack the chunks per column
            n_fd = x.shape[1]
            return [res.reshape(-1, n_fd, chunks).transpose(2, 0, 1).reshape(-1, n_fd)], None, None
    else:
        residual_fn = sysid.build_residual_fn(models_sequences=[sequences], modify_residual=modify_residual,
                                              resample_true=False)
    log = io.StringIO()
    opt_params, result = sysid.optimize(params, residual_fn, optimizer="mujoco", verbose=False,
                                        max_iters=config.max_iters, x_scale=config.x_scale, output=log)
    residuals, _, _ = residual_fn(result.x, opt_params)
    cov_theta, half_widths = sysid.calculate_intervals(residuals, result.jac)
    theta = np.asarray(result.x, dtype=float)
    X_object_tracked = X_tracked_body.inverse()
    flat = physical_from_pseudo(theta, X_object_tracked)
    I = np.array([[flat[4], flat[7], flat[8]], [flat[7], flat[5], flat[9]], [flat[8], flat[9], flat[6]]])
    iterations = sum(1 for line in log.getvalue().splitlines() if line.startswith("iter:"))
    return SysidResult(
        inertial=Inertial(flat[0], flat[1:4], I), covariance=_physical_covariance(theta, cov_theta, X_object_tracked),
        theta=theta, theta_half_widths=np.asarray(half_widths), iterations=iterations, chunk_count=len(initial),
        wall_s=time.perf_counter() - t0, log=log.getvalue(),
    )


def bench_mujoco(seeds: int = 5, duration_s: float = 10.0, sysid_configs: dict | None = None) -> list[dict]:
    """`bench_paper`'s recordings identified by ours (`identify_held`) and by mujoco.sysid in the same process:
    parameter errors, 95 % interval half-widths and coverage, and wall time of each."""
    from pipelines.identify import IdentifyConfig, identify_held, identify_least_squares, tracked_to_object

    if sysid_configs is None:
        sysid_configs = {"mujoco.sysid": SysidConfig(), "mujoco.sysid raw": SYSID_RAW}
    estimates, truths, kept_newton = {}, {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, truth, placement, prior, bounds, seed, trial, heldout in paper_cases(seeds, duration_s, Path(tmp)):
            truths[name] = truth
            X = tracked_to_object(trial, placement)
            t0 = time.perf_counter()
            held = identify_held([trial], heldout, X, prior.inertial, bounds, IdentifyConfig())
            wall = time.perf_counter() - t0
            t0 = time.perf_counter()
            r = trial
            identify_least_squares(r.pose.t_s, r.pose.position, r.pose.quat_xyzw, r.wrench.t_s, r.wrench.force,
                                   r.wrench.torque, X)
            wall_ls = time.perf_counter() - t0
            rows = {
                "twin kept": (held.inertial, held.covariance, wall),
                "twin least squares": (held.least_squares.inertial, held.least_squares.covariance, wall_ls),
                "twin Newton": (held.newton.inertial, held.newton.covariance, held.newton.wall_s),
            }
            for label, config in sysid_configs.items():
                result = sysid_held(trial, X, prior.inertial, bounds, config)
                rows[label] = (result.inertial, result.covariance, result.wall_s)
            for label, value in rows.items():
                estimates.setdefault((name, label), []).append(value)
            kept_newton.setdefault(name, []).append(held.selected == "newton")
            print(f"  {name} seed {seed}: kept {held.selected}; wall " + ", ".join(
                f"{k} {v[2]:.1f} s" for k, v in rows.items()), flush=True)
    out = []
    for (name, label), values in estimates.items():
        truth = truths[name]
        if label == "twin kept":
            label = f"twin kept (Newton {sum(kept_newton[name])}/{len(kept_newton[name])})"
        out.append({"object": name, "estimator": label, **spread([(v[0], v[1]) for v in values], truth),
                    **_widths(values, truth)})
    _print_table(out)
    return out


def _widths(values, truth) -> dict:
    """95 % interval half-widths (1.96 sigma, mean over draws): mass and Ixx Iyy Izz in % of the truth, COM in mm
    (largest axis); median wall time."""
    std = np.array([np.sqrt(np.maximum(np.diag(cov), 0.0)) for _, cov, _ in values])
    true_diag = np.diag(truth.inertia_matrix())
    return {
        "mass_halfwidth_pct": float(np.mean(196 * std[:, 0] / truth.mass)),
        "inertia_halfwidth_pct": np.mean(196 * std[:, 4:7] / true_diag, axis=0).tolist(),
        "com_halfwidth_mm": float(np.mean(1960 * std[:, 1:4].max(axis=1))),
        "wall_s": float(np.median([w for _, _, w in values])),
    }


def _print_table(rows: list[dict]) -> None:
    print(f"{'object':7} {'estimator':26} {'mass %':>7} {'principal moments %':>21} {'COM mm':>7} "
          f"{'±mass %':>8} {'±Ixx Iyy Izz %':>18} {'±COM mm':>8} {'cover':>6} {'wall s':>7}")
    for r in rows:
        pm = " ".join(f"{x:6.2f}" for x in r["inertia_error_pct"])
        hw = " ".join(f"{x:5.2f}" for x in r["inertia_halfwidth_pct"])
        print(f"{r['object']:7} {r['estimator']:26} {r['mass_error_pct']:7.2f} {pm:>21} {r['com_error_max_mm']:7.3f} "
              f"{r['mass_halfwidth_pct']:8.2f} {hw:>18} {r['com_halfwidth_mm']:8.3f} {r['interval_coverage']:6.2f} "
              f"{r['wall_s']:7.2f}")
