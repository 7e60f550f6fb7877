"""The sliding rollout: one pushed body per shooting window on a shared ground plane (Newton SemiImplicit),
its kernels beside their launches, and what its replay tells (sliding windows, replay errors)."""

from __future__ import annotations

import numpy as np
import warp as wp

from assets.conventions import GRAVITY_MAGNITUDE_M_S2 as GRAVITY_M_S2

from .body import PlanarBody, SlidingConfig, support_points
from .windows import PushWindows, planar_travel


@wp.kernel
def assign_sliding_params(
    theta: wp.array[float],
    inertia_xy: wp.vec2,
    shape_body: wp.array[int],
    body_mass: wp.array[float],
    body_inv_mass: wp.array[float],
    body_inertia: wp.array[wp.mat33],
    body_inv_inertia: wp.array[wp.mat33],
    shape_material_mu: wp.array[float],
):
    """Write mu (every shape, so the pair average is mu), mass [kg] and I_zz [kg m^2] on the tape.

    One thread per shape; the thread of a body's first contact sphere also writes
    the body. SemiImplicit integrates with the inverses (newton.md trap 1).
    """
    s = wp.tid()
    shape_material_mu[s] = theta[0]
    b = shape_body[s]
    if b >= 0 and (s == 0 or shape_body[s - 1] != b):
        m = theta[1]
        inertia = wp.mat33(inertia_xy[0], 0.0, 0.0, 0.0, inertia_xy[1], 0.0, 0.0, 0.0, theta[2])
        body_mass[b] = m
        body_inv_mass[b] = 1.0 / m
        body_inertia[b] = inertia
        body_inv_inertia[b] = wp.inverse(inertia)


@wp.kernel
def set_planar_start_state(
    start: wp.array[wp.spatial_vector],
    velocity_correction: wp.array[wp.vec3],
    rest_height_m: float,
    body_q: wp.array[wp.transform],
    body_qd: wp.array[wp.spatial_vector],
):
    """Body w at (x, y, rest height), heading yaw, velocity (vx, vy, 0) [m/s] and yaw rate [rad/s],
    each rate plus the window's correction (vx, vy, yaw rate)."""
    w = wp.tid()
    s = start[w]
    c = velocity_correction[w]
    body_q[w] = wp.transform(wp.vec3(s[0], s[1], rest_height_m), wp.quat_from_axis_angle(wp.vec3(0.0, 0.0, 1.0), s[2]))
    body_qd[w] = wp.spatial_vector(wp.vec3(s[3] + c[0], s[4] + c[1], 0.0), wp.vec3(0.0, 0.0, s[5] + c[2]))


@wp.kernel
def apply_pusher_force(
    body_q: wp.array[wp.transform],
    body_com: wp.array[wp.vec3],
    force: wp.array2d[wp.vec2],
    contact: wp.array2d[wp.vec2],
    effect: wp.array[float],
    step: int,
    margin: int,
    dt: float,
    body_f: wp.array[wp.spatial_vector],
):
    """Horizontal pusher force [N] at the contact point (x, y) [m], taken at the COM's height.

    The height at which a pusher meets the object only tilts it (SemiImplicit
    would rock the box on its contacts); the planar motion needs the in-plane moment.
    effect[4] is the wrench's delay d [s] (DESIGN.md time_delay: stamped t, it acted at t - d), so
    the force acting now was read d later: interpolated between steps, so d has a gradient.
    effect[5:7] is the contact point's offset [m], world x, y: the force acts at the measured point plus it
    (a probe or tracker calibration off by millimetres moves the pushing moment of a near-central push).
    """
    w = wp.tid()
    X = body_q[w]
    c = wp.transform_point(X, body_com[w])
    at = float(step + margin) + effect[4] / dt
    i = wp.clamp(int(wp.floor(at)), 0, force.shape[0] - 2)
    a = wp.clamp(at - float(i), 0.0, 1.0)
    f2 = force[i, w] * (1.0 - a) + force[i + 1, w] * a
    p2 = contact[step, w] + wp.vec2(effect[5], effect[6])
    f = wp.vec3(f2[0], f2[1], 0.0)
    arm = wp.vec3(p2[0] - c[0], p2[1] - c[1], 0.0)
    body_f[w] = wp.spatial_vector(f, wp.cross(arm, f))


EFFECT_SLOTS = {"sensor_bias": (0, 1), "viscous_damping": (2, 3), "time_delay": (4,), "contact_offset": (5, 6)}
"""Where each effect's parameters sit in the rollout's effect vector (apply_sliding_effects, apply_pusher_force)."""
EFFECT_SIZE = 7


@wp.kernel
def apply_sliding_effects(
    body_qd: wp.array[wp.spatial_vector],
    effect: wp.array[float],
    body_f: wp.array[wp.spatial_vector],
):
    """Add to the pusher's wrench what the base model leaves out: a force offset still in the reading
    (measured = applied + (effect[0], effect[1]) [N], world x, y; the same at every point of the push
    contact, so applied at the COM it only shifts the force) and viscous drag on the sliding body,
    -effect[2] v [N s/m] and -effect[3] omega_z [N m s] (velocity-strengthening friction)."""
    w = wp.tid()
    qd = body_qd[w]
    v = wp.spatial_top(qd)
    omega = wp.spatial_bottom(qd)
    f = wp.vec3(-effect[0] - effect[2] * v[0], -effect[1] - effect[2] * v[1], 0.0)
    tau = wp.vec3(0.0, 0.0, -effect[3] * omega[2])
    body_f[w] = body_f[w] + wp.spatial_vector(f, tau)


@wp.kernel
def eval_planar_error(
    body_q: wp.array[wp.transform],
    measured: wp.array2d[wp.vec3],
    sample: int,
    yaw_length_m: float,
    residual: wp.array3d[float],
):
    """Per window: x, y error [m] and heading error [rad] times yaw_length_m [m]."""
    w = wp.tid()
    X = body_q[w]
    p = wp.transform_get_translation(X)
    ax = wp.quat_rotate(wp.transform_get_rotation(X), wp.vec3(1.0, 0.0, 0.0))
    m = measured[sample, w]
    dyaw = wp.atan2(ax[1], ax[0]) - m[2]
    dyaw = dyaw - 2.0 * wp.pi * wp.round(dyaw / (2.0 * wp.pi))  # the short way round
    residual[sample, w, 0] = p[0] - m[0]
    residual[sample, w, 1] = p[1] - m[1]
    residual[sample, w, 2] = dyaw * yaw_length_m


@wp.kernel
def eval_sum_squares(residual: wp.array3d[float], loss: wp.array[float]):
    """loss += sum of squared residuals [m^2]."""
    j, w, k = wp.tid()
    r = residual[j, w, k]
    wp.atomic_add(loss, 0, r * r)


class SlidingRollout:
    """One pushed body on a shared ground plane per window; SemiImplicit, no damping."""

    def __init__(self, windows: PushWindows, body: PlanarBody, config: SlidingConfig, device: str = "cpu"):
        import newton

        self.windows, self.body, self.config, self.device = windows, body, config, device
        hx, hy, hz = body.half_extents_m
        W = windows.window_count
        radius = 1e-3
        support = support_points(body, config)
        n_contacts = len(support)
        ke = body.mass_kg * GRAVITY_M_S2 / config.contact_sink_m
        kd = 2.0 * config.contact_damping_ratio * np.sqrt(ke * body.mass_kg)
        cfg = newton.ModelBuilder.ShapeConfig(
            ke=ke / n_contacts, kd=kd / n_contacts,
            # slip speed mu g dt: Coulomb (mu-sensitive) at the speeds a push is fitted at,
            # while kf dt / (m / n) = 1 keeps the explicit viscous branch stable (deadbeat)
            kf=body.mass_kg / n_contacts / windows.dt_s, mu=0.5, density=0.0,
        )
        sub = newton.ModelBuilder(gravity=(0.0, 0.0, -GRAVITY_M_S2), up_axis=newton.Axis.Z)
        # a link without add_body's free joint: SemiImplicit moves it alike, bit for bit, 40 % faster on a CPU
        # (a joint costs two more launches a step: its forces and a copy of body_f)
        b = sub.add_link(mass=body.mass_kg, inertia=wp.mat33(np.eye(3) * body.izz_kgm2), lock_inertia=True)
        for px, py in support:
            sub.add_shape_sphere(b, xform=wp.transform(wp.vec3(px, py, -hz + radius), wp.quat_identity()),
                                 radius=radius, cfg=cfg)
        builder = newton.ModelBuilder(gravity=(0.0, 0.0, -GRAVITY_M_S2), up_axis=newton.Axis.Z)
        builder.replicate(sub, W)
        builder.add_ground_plane(cfg=cfg)
        self.model = builder.finalize(device=device, requires_grad=True)
        self.solver = newton.solvers.SolverSemiImplicit(self.model, angular_damping=0.0)
        self.control = self.model.control()
        self.states = [self.model.state(requires_grad=True) for _ in range(windows.step_count + 1)]
        self.rest_height_m = hz - config.contact_sink_m
        m_box = body.mass_kg
        self.inertia_xy = wp.vec2(m_box * (hy * hy + hz * hz) / 3.0, m_box * (hx * hx + hz * hz) / 3.0)
        self.yaw_length_m = config.yaw_length_m or float(np.hypot(hx, hy))

        self.start = wp.array(windows.start.astype(np.float32), dtype=wp.spatial_vector, device=device)
        self.force = wp.array(windows.force.astype(np.float32), dtype=wp.vec2, device=device)
        self.contact = wp.array(windows.contact.astype(np.float32), dtype=wp.vec2, device=device)
        self.measured = wp.array(windows.measured.astype(np.float32), dtype=wp.vec3, device=device)
        self.theta = wp.zeros(3, dtype=float, device=device, requires_grad=True)
        self.effect = wp.zeros(EFFECT_SIZE, dtype=float, device=device, requires_grad=True)
        self.correction = wp.zeros(W, dtype=wp.vec3, device=device, requires_grad=True)
        self.residual = wp.zeros((windows.sample_count + 1, W, 3), dtype=float, device=device, requires_grad=True)
        self.loss = wp.zeros(1, dtype=float, device=device, requires_grad=True)

        # Contacts against a plane depend only on the body-local sphere centres: found once.
        self.pipeline = newton.CollisionPipeline(self.model, broad_phase="explicit", requires_grad=True)
        self.contacts = self.pipeline.contacts()
        wp.launch(set_planar_start_state, dim=W, inputs=[self.start, self.correction, self.rest_height_m],
                  outputs=[self.states[0].body_q, self.states[0].body_qd], device=device)
        self.pipeline.collide(self.states[0], self.contacts)
        found = int(self.contacts.rigid_contact_count.numpy()[0])
        if found != W * n_contacts:
            raise RuntimeError(f"sliding model: expected {W * n_contacts} support contacts, the pipeline found {found}")

    def _forward(self) -> None:
        w, model = self.windows, self.model
        wp.launch(assign_sliding_params, dim=model.shape_count, inputs=[self.theta, self.inertia_xy, model.shape_body],
                  outputs=[model.body_mass, model.body_inv_mass, model.body_inertia, model.body_inv_inertia,
                           model.shape_material_mu], device=self.device)
        s0 = self.states[0]
        wp.launch(set_planar_start_state, dim=w.window_count, inputs=[self.start, self.correction, self.rest_height_m],
                  outputs=[s0.body_q, s0.body_qd], device=self.device)
        self.residual.zero_()
        for step in range(w.step_count):
            s, s_next = self.states[step], self.states[step + 1]
            wp.launch(apply_pusher_force, dim=w.window_count,
                      inputs=[s.body_q, model.body_com, self.force, self.contact, self.effect, step,
                              w.force_margin, w.dt_s],
                      outputs=[s.body_f], device=self.device)
            wp.launch(apply_sliding_effects, dim=w.window_count, inputs=[s.body_qd, self.effect], outputs=[s.body_f],
                      device=self.device)
            self.solver.step(s, s_next, self.control, self.contacts, w.dt_s)
            if (step + 1) % w.substeps == 0:
                wp.launch(eval_planar_error, dim=w.window_count,
                          inputs=[s_next.body_q, self.measured, (step + 1) // w.substeps, self.yaw_length_m],
                          outputs=[self.residual], device=self.device)

    def _load(self, theta, correction, effect) -> None:
        self.theta.assign(np.asarray(theta, dtype=np.float32))
        W = self.windows.window_count
        c = np.zeros((W, 3)) if correction is None else np.asarray(correction).reshape(W, 3)
        self.correction.assign(c.astype(np.float32))
        self.effect.assign(np.zeros(EFFECT_SIZE, np.float32) if effect is None else np.asarray(effect, np.float32))

    def residuals(self, theta, correction=None, effect=None) -> np.ndarray:
        """Errors [S, W, 3] at samples 1..S: x, y [m], heading x yaw_length_m [m].

        correction [W, 3]: start-velocity corrections (vx, vy [m/s], yaw rate [rad/s]);
        effect [EFFECT_SIZE]: see apply_sliding_effects (None: none).
        """
        self._load(theta, correction, effect)
        self._forward()
        return self.residual.numpy()[1:].astype(float)

    def trajectories(self, theta, correction=None, effect=None) -> np.ndarray:
        """Simulated x, y [m] and yaw [rad] at samples 0..S, shape [S+1, W, 3]."""
        r = self.residuals(theta, correction, effect)
        pred = self.windows.measured.copy()
        pred[1:, :, :2] += r[:, :, :2]
        pred[1:, :, 2] += r[:, :, 2] / self.yaw_length_m
        return pred

    def loss_and_grad(self, theta, correction=None, effect=None) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
        """Sum of squared residuals [m^2] and its gradients w.r.t. theta, the corrections [W, 3] and the effect."""
        self._load(theta, correction, effect)
        tape = wp.Tape()
        with tape:
            self._forward()
            self.loss.zero_()
            wp.launch(eval_sum_squares, dim=self.residual.shape, inputs=[self.residual], outputs=[self.loss],
                      device=self.device)
        tape.backward(self.loss)
        out = (float(self.loss.numpy()[0]), self.theta.grad.numpy().astype(float).copy(),
               self.correction.grad.numpy().astype(float).copy(), self.effect.grad.numpy().astype(float).copy())
        tape.zero()
        return out


def sliding_windows(rollout: SlidingRollout, theta, correction=None, effect=None) -> tuple[np.ndarray, np.ndarray]:
    """Per window: whether the measured object still moves over the window's second half (at least
    config.moving_speed_m_s on average), and whether the simulation at theta then slides too: at least half
    the measured travel (x, y and the heading as an arc at the face's half diagonal), at a measured speed
    of at least twice the slip speed mu g dt of Newton's penalty friction, below which it moves any body.

    A force-driven Coulomb model of a slow push balances on a knife edge: below the force over m g the
    object accelerates, above it it sticks, after coasting off its start velocity. Where the real object kept
    moving, a fit that sticks in every window has found the smallest mu that holds it, a lower bound, and
    its curvature is that of sliding below the bound, not a measurement of mu.
    """
    simulated = rollout.trajectories(theta, correction, effect)
    measured = rollout.windows.measured
    half = measured.shape[0] // 2
    span_s = (measured.shape[0] - 1 - half) * rollout.windows.sample_period_s

    def travel(track):
        return planar_travel(track[-1] - track[half], rollout.yaw_length_m)

    moving = travel(measured) >= rollout.config.moving_speed_m_s * span_s
    # below twice the penalty friction's slip speed (mu g dt) a simulated body moves in its viscous branch,
    # whatever mu: that is creep of the step, not Coulomb sliding
    coulomb = travel(measured) >= 2.0 * float(theta[0]) * GRAVITY_M_S2 * rollout.windows.dt_s * span_s
    return moving, moving & coulomb & (travel(simulated) >= 0.5 * travel(measured))


def replay_errors(rollout: SlidingRollout, theta, correction=None, effect=None) -> tuple[float, float]:
    """Position RMSE [m] and heading RMSE [rad] of the windowed replay at theta."""
    r = rollout.residuals(theta, correction, effect)
    return float(np.sqrt(np.mean(np.sum(r[..., :2] ** 2, axis=-1)))), float(
        np.sqrt(np.mean(r[..., 2] ** 2)) / rollout.yaw_length_m
    )
