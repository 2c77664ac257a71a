"""Joint plants driven by simulated servos.

`JointPlant` is the small interface a simulated servo bus needs from the thing
it moves: goals and torque switches in, joint state arrays out, and a time step.
`ServoPlant` is the default: N independent position-controlled joints, all
numpy arrays. A richer plant (a whole humanoid with contacts) can stand in for
it by offering the same methods.

`ServoPlant` model, per joint, on each step of ``dt`` seconds:

* torque on: first-order tracking of the goal with time constant ``tau``
  (exact discretisation, so with no limit active the position follows
  ``goal + (p0 - goal) exp(-t / tau)`` whatever the step size), then the
  velocity is clipped to ``max_velocity`` and its change per step to
  ``max_acceleration * dt``;
* torque off: the joint is passive, its velocity decays exponentially with
  time constant ``coast_time_constant`` (viscous friction) and it comes to rest;
* position limits ``lower``/``upper`` are hard stops: the joint stops there;
* current estimate ``(inertia * acceleration + damping * velocity +
  external_torque) / torque_constant`` while the torque is on, else 0.

Units: rad, rad/s, rad/s^2, s, N m, A, kg m^2.
"""

from __future__ import annotations

import math
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]

# XM430-W350 at 12 V: 46 rpm no-load speed, 4.1 N m stall torque at 2.3 A.
XM430_NO_LOAD_SPEED = 46.0 * 2.0 * math.pi / 60.0
XM430_TORQUE_CONSTANT = 4.1 / 2.3


class JointPlant(Protocol):
    """What a simulated servo bus drives: joint ``idx`` is one servo."""

    position: Array  #: rad, shape (n,)
    velocity: Array  #: rad/s, shape (n,)
    current: Array  #: A, shape (n,)

    def set_goal(self, idx: int, position: float) -> None:
        """Set joint ``idx``'s goal position (rad)."""

    def set_torque(self, idx: int, on: bool) -> None:
        """Switch joint ``idx``'s motor torque on or off."""

    def step(self, dt: float) -> None:
        """Advance the plant by ``dt`` seconds."""


def _per_joint(value: ArrayLike, n: int, name: str) -> Array:
    array = np.asarray(value, dtype=float)
    try:
        return np.broadcast_to(array, (n,)).copy()
    except ValueError:
        raise ValueError(f"ServoPlant: '{name}' must be a scalar or have {n} entries, "
                         f"got shape {array.shape}") from None


class ServoPlant:
    """N position-controlled joints (see module docstring); all state is numpy arrays.

    Every parameter is a scalar or a per-joint array. ``max_substep`` (s) bounds
    the integration step; one `step` call does at most ``max_substeps`` substeps
    (longer calls use longer substeps) so its cost stays bounded.
    """

    def __init__(self, n: int, *, position: ArrayLike = 0.0, tau: ArrayLike = 0.03,
                 max_velocity: ArrayLike = XM430_NO_LOAD_SPEED, max_acceleration: ArrayLike = 200.0,
                 coast_time_constant: ArrayLike = 0.05, lower: ArrayLike = -np.inf,
                 upper: ArrayLike = np.inf, inertia: ArrayLike = 2e-3, damping: ArrayLike = 0.1,
                 torque_constant: ArrayLike = XM430_TORQUE_CONSTANT, max_substep: float = 1e-3,
                 max_substeps: int = 100) -> None:
        self.n = n
        self.tau = _per_joint(tau, n, "tau")
        self.max_velocity = _per_joint(max_velocity, n, "max_velocity")
        self.max_acceleration = _per_joint(max_acceleration, n, "max_acceleration")
        self.coast_time_constant = _per_joint(coast_time_constant, n, "coast_time_constant")
        self.lower = _per_joint(lower, n, "lower")
        self.upper = _per_joint(upper, n, "upper")
        self.inertia = _per_joint(inertia, n, "inertia")
        self.damping = _per_joint(damping, n, "damping")
        self.torque_constant = _per_joint(torque_constant, n, "torque_constant")
        for name in ("tau", "coast_time_constant", "torque_constant", "max_velocity", "max_acceleration"):
            if not np.all(getattr(self, name) > 0):
                raise ValueError(f"ServoPlant: '{name}' must be > 0")
        self.max_substep = max_substep
        self.max_substeps = max_substeps
        self.position = np.clip(_per_joint(position, n, "position"), self.lower, self.upper)
        self.velocity = np.zeros(n)
        self.current = np.zeros(n)
        self.goal = self.position.copy()
        self.torque_on = np.zeros(n, dtype=bool)
        self.external_torque = np.zeros(n)  #: N m applied by the load, e.g. gravity
        self.steps = 0  #: `step` calls that advanced the plant (observers wait on it, not on the clock)
        self._factors: tuple[float, tuple[Array, ...]] | None = None  # (substep s, its factors), see _factors_for

    def set_goal(self, idx: int, position: float) -> None:
        """Set joint ``idx``'s goal position (rad)."""
        self.goal[idx] = position

    def set_torque(self, idx: int, on: bool) -> None:
        """Switch joint ``idx``'s torque; off makes it passive (coasting to rest)."""
        self.torque_on[idx] = on

    def step(self, dt: float) -> None:
        """Advance all joints by ``dt`` seconds (dt <= 0 does nothing)."""
        if dt <= 0.0:
            return
        self.steps += 1
        count = min(self.max_substeps, max(1, math.ceil(dt / self.max_substep)))
        h = dt / count
        for _ in range(count):
            self._substep(h)

    def _factors_for(self, h: float) -> tuple[Array, ...]:
        """The per-joint factors of a substep of ``h`` s (first-order gain per second, lowest velocity, velocity
        change limit, coast decay, 1 - decay, inertia / h), made once per substep length from the parameters as
        constructed: a plant stepped at a fixed rate (the humanoid's 1 kHz physics) pays their exponentials once,
        not every step."""
        if self._factors is None or self._factors[0] != h:
            decay = np.exp(-h / self.coast_time_constant)
            self._factors = (h, (-np.expm1(-h / self.tau) / h, -self.max_velocity, self.max_acceleration * h, decay,
                                 1.0 - decay, self.inertia / h))
        return self._factors[1]

    def _substep(self, h: float) -> None:
        # ufuncs with out= rather than np.clip/np.where: this runs per packet, on small arrays.
        on = self.torque_on
        velocity = self.velocity
        gain, lowest, dv, decay, coasted, inertia_rate = self._factors_for(h)
        # Torque on: the average velocity that makes this step exactly first-order, then limits.
        driven = self.goal - self.position
        driven *= gain
        np.minimum(driven, self.max_velocity, out=driven)
        np.maximum(driven, lowest, out=driven)
        np.minimum(driven, velocity + dv, out=driven)
        np.maximum(driven, velocity - dv, out=driven)
        all_on = b"\x00" not in on.tobytes()  # all() (a bool array's bytes are 0 or 1): cheaper than a reduction
        if all_on:  # every joint driven (a standing humanoid, every step): no coasting terms to compute or mask
            shift = driven * h
            new_velocity = driven
        else:
            # Torque off: exact integral of an exponentially decaying velocity.
            new_velocity = np.where(on, driven, velocity * decay)
            shift = np.where(on, driven * h, velocity * self.coast_time_constant * coasted)
        position = self.position + shift
        # In place, so arrays handed out earlier stay live views of the state; each written whole by its last
        # ufunc (out=) where one makes it, not computed and copied in
        np.minimum(np.maximum(position, self.lower), self.upper, out=self.position)
        new_velocity[self.position != position] = 0.0
        torque = (new_velocity - velocity) * inertia_rate
        torque += self.damping * new_velocity
        torque += self.external_torque
        if all_on:
            np.divide(torque, self.torque_constant, out=self.current)
        else:
            torque /= self.torque_constant
            torque[~on] = 0.0
            self.current[:] = torque
        self.velocity[:] = new_velocity
