"""Shooting windows simulated as parallel Newton worlds, with loss and gradient from a Warp tape."""

from __future__ import annotations

import numpy as np

from assets import Pose
from assets.conventions import GRAVITY_M_S2

from .inertia import THETA_SIZE
from .kernels import (
    EFFECT_SIZE,
    apply_effect_wrench,
    apply_measured_wrench,
    assign_inertial_params_to_model,
    eval_tracked_pose_error,
    eval_weighted_squares,
    eval_window_normal_equations,
    mat_columns,
    set_window_start_state,
    vec_columns,
)
from .windows import ShootingWindows


class FreeBodyRollout:
    """One free body per (parameter set, window), SemiImplicit, no damping; parameters written on the tape.

    X_tracked_body: the object (body) frame in the tracked frame. `sets` parameter sets run
    side by side, each over all windows (set-major worlds): multi-start and finite-difference
    Jacobians cost one rollout. Arguments take theta [sets, 10] and corrections [sets, W, 6].
    Without `requires_grad` it only runs forward (no tape), at half the memory.
    """

    def __init__(
        self, windows: ShootingWindows, X_tracked_body: Pose, sets: int = 1, device: str = "cpu",
        requires_grad: bool = True,
    ):
        import newton
        import warp as wp

        self.windows = windows
        self.sets = sets
        self.device = device
        W = windows.window_count
        sub = newton.ModelBuilder(gravity=tuple(GRAVITY_M_S2))
        # a link without add_body's free joint: SemiImplicit moves it alike, bit for bit, while a joint costs two
        # more launches a step (its forces and a copy of body_f), which set a CPU rollout's pace
        sub.add_link(mass=1.0, inertia=wp.mat33(np.eye(3) * 1e-3), lock_inertia=True)
        builder = newton.ModelBuilder(gravity=tuple(GRAVITY_M_S2))
        builder.replicate(sub, sets * W)
        self.model = builder.finalize(device=device, requires_grad=requires_grad)
        self.solver = newton.solvers.SolverSemiImplicit(self.model, angular_damping=0.0)
        self.control = self.model.control()
        # the tape needs every step's state; a forward-only rollout alternates two
        count = windows.step_count + 1 if requires_grad else 2
        self.states = [self.model.state(requires_grad=requires_grad) for _ in range(count)]

        X_tb = wp.transform(wp.vec3(*X_tracked_body.position), wp.quat(*X_tracked_body.quaternion_xyzw))
        self.X_tracked_body = X_tb
        self.X_body_tracked = wp.transform_inverse(X_tb)

        m = windows.measured_position
        q = windows.measured_quat_xyzw
        measured = np.concatenate([m, q], axis=-1).astype(np.float32)
        self.measured = wp.array(measured, dtype=wp.transform, device=device)
        self.start_pose = wp.array(measured[0], dtype=wp.transform, device=device)
        self.start_twist = wp.array(windows.start_twist.astype(np.float32), dtype=wp.spatial_vector, device=device)
        self.wrench = wp.array(windows.wrench.astype(np.float32), dtype=wp.spatial_vector, device=device)

        self.theta = wp.zeros((sets, THETA_SIZE), dtype=float, device=device, requires_grad=requires_grad)
        self.effect = wp.zeros((sets, EFFECT_SIZE), dtype=float, device=device, requires_grad=requires_grad)
        self.with_effects = False
        self.correction = wp.zeros(sets * W, dtype=wp.spatial_vector, device=device, requires_grad=requires_grad)
        self.correction_rate = wp.zeros(sets * W, dtype=wp.spatial_vector, device=device,
                                        requires_grad=requires_grad)
        self.residual = wp.zeros((windows.sample_count + 1, sets * W, 6), dtype=float, device=device,
                                 requires_grad=requires_grad)
        self.weight = wp.zeros((windows.sample_count + 1, 6), dtype=float, device=device)
        self.loss = wp.zeros(1, dtype=float, device=device, requires_grad=True)
        self._graphs: dict = {}
        self._tapes: dict = {}
        self._loaded: set = set()

    def _load(self, theta: np.ndarray, correction: np.ndarray | None, correction_rate: np.ndarray | None):
        shape = (self.sets * self.windows.window_count, 6)
        self.with_effects = False
        self.theta.assign(np.asarray(theta, dtype=np.float32).reshape(self.sets, THETA_SIZE))
        for array, value in ((self.correction, correction), (self.correction_rate, correction_rate)):
            array.assign(np.zeros(shape, np.float32) if value is None else np.asarray(value, np.float32).reshape(shape))

    def _forward(self, momentum_scaled: bool) -> None:
        import warp as wp

        w = self.windows
        W = w.window_count
        model = self.model
        assign_inertial_params_to_model(self.theta, W, model)
        s0 = self.states[0]
        wp.launch(
            set_window_start_state,
            dim=model.body_count,
            inputs=[self.start_pose, self.start_twist, self.correction, self.correction_rate, self.X_tracked_body, W,
                    model.body_com],
            outputs=[s0.body_q, s0.body_qd],
            device=self.device,
        )
        self.residual.zero_()
        for step in range(w.step_count):
            s, s_next = self.states[step % len(self.states)], self.states[(step + 1) % len(self.states)]
            wp.launch(
                apply_measured_wrench,
                dim=model.body_count,
                inputs=[s.body_q, model.body_com, self.X_body_tracked, self.wrench, step, W],
                outputs=[s.body_f],
                device=self.device,
            )
            if self.with_effects:
                wp.launch(
                    apply_effect_wrench,
                    dim=model.body_count,
                    inputs=[s.body_q, s.body_qd, model.body_com, self.X_body_tracked, self.effect, W],
                    outputs=[s.body_f],
                    device=self.device,
                )
            self.solver.step(s, s_next, self.control, None, w.dt_s)
            if (step + 1) % w.substeps == 0:
                sample = (step + 1) // w.substeps
                wp.launch(
                    eval_tracked_pose_error,
                    dim=model.body_count,
                    inputs=[s_next.body_q, model.body_mass, model.body_inertia, self.X_body_tracked, self.measured,
                            sample, int(momentum_scaled), W],
                    outputs=[self.residual],
                    device=self.device,
                )

    def _run(self, key, record) -> None:
        """Issue `record`'s launches; on a GPU, as a CUDA graph captured on first use.

        Hundreds of small launches per rollout make a GPU wait on the host;
        replaying one graph removes that. The first call runs uncaptured, since
        modules must be loaded before a capture; the second captures.
        """
        import warp as wp

        if not wp.get_device(self.device).is_cuda or key not in self._loaded:
            self._loaded.add(key)
            record()
            return
        if key not in self._graphs:
            with wp.ScopedCapture(device=self.device) as capture:
                record()
            self._graphs[key] = capture.graph
        wp.capture_launch(self._graphs[key])

    def residuals(self, theta, correction=None, correction_rate=None, momentum_scaled=True,
                  effect: np.ndarray | None = None) -> np.ndarray:
        """Tracked-frame errors [S, sets, W, 6] for samples 1..S: see `eval_tracked_pose_error`.

        effect [sets, EFFECT_SIZE]: candidate effects added by `apply_effect_wrench` (None: none).
        """
        self._load(theta, correction, correction_rate)
        if effect is not None:
            self.effect.assign(np.asarray(effect, np.float32).reshape(self.sets, EFFECT_SIZE))
            self.with_effects = True
        key = ("forward", momentum_scaled, self.with_effects)
        self._run(key, lambda: self._forward(momentum_scaled))
        S, W = self.windows.sample_count, self.windows.window_count
        return self.residual.numpy()[1:].astype(float).reshape(S, self.sets, W, 6)

    def normal_equations(self, theta, correction, correction_rate, steps: np.ndarray,
                         weight: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Run the sets (K points, each laid out as `eval_window_normal_equations` reads them) and
        return per point and window J^T J [K, W, n, n] and J^T r [K, W, n] of the weighted residuals.

        steps [K, n]: each column's difference step; weight [S, 6].
        """
        import warp as wp

        self._load(theta, correction, correction_rate)
        self._run(("forward", True), lambda: self._forward(True))
        K = len(steps)
        W = self.windows.window_count
        gram = wp.zeros((K, W), dtype=mat_columns, device=self.device)
        jtr = wp.zeros((K, W), dtype=vec_columns, device=self.device)
        wp.launch(
            eval_window_normal_equations,
            dim=(K, W),
            inputs=[self.residual, wp.array(np.sqrt(weight).astype(np.float32), dtype=float, device=self.device),
                    wp.array(steps.astype(np.float32), dtype=float, device=self.device), W, self.sets // K],
            outputs=[gram, jtr],
            device=self.device,
        )
        return gram.numpy().astype(float), jtr.numpy().astype(float)

    def loss_and_grad(
        self, theta, correction, correction_rate, weight: np.ndarray, momentum_scaled: bool
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Weighted sum of squared pose errors per set [sets] and its gradients w.r.t. theta [sets, 10]
        and the corrections [sets, W, 6]. A set's loss depends on its own parameters only, so one
        backward pass of the total gives every set's gradient.

        weight [S, 6]: per sample index within the window and channel.
        """
        import warp as wp

        self._load(theta, correction, correction_rate)
        self.weight.assign(np.vstack([np.zeros((1, 6)), weight]).astype(np.float32))
        def record():
            tape = self._tapes[momentum_scaled] = wp.Tape()
            with tape:
                self._forward(momentum_scaled)
                self.loss.zero_()
                wp.launch(
                    eval_weighted_squares,
                    dim=self.residual.shape,
                    inputs=[self.residual, self.weight],
                    outputs=[self.loss],
                    device=self.device,
                )
            tape.backward(self.loss)

        self._run(("gradient", momentum_scaled), record)
        K, S, W = self.sets, self.windows.sample_count, self.windows.window_count
        r = self.residual.numpy()[1:].astype(float).reshape(S, K, W, 6)
        out = (
            np.einsum("skwc,sc->k", r * r, weight),
            self.theta.grad.numpy().astype(float).copy(),
            self.correction.grad.numpy().astype(float).reshape(K, W, 6).copy(),
            self.correction_rate.grad.numpy().astype(float).reshape(K, W, 6).copy(),
        )
        self._tapes[momentum_scaled].zero()
        return out
