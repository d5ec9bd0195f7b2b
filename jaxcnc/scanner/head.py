"""The scan head: how the mirrors follow the command (a second-order tracking model with an acceleration limit).

Per axis, at the field (mm): ``x'' = clip(ω² (c − x) − 2 ζ ω x', ±a_max)`` with ``ω = 2 ζ / τ``, where ``c`` is the
commanded position (linear between board ticks), ``τ`` the **tracking error** (``tracking_error_s``: at constant
speed the mirror is ``τ`` behind the command, ``x(t) = c(t − τ)``, the figure galvo makers quote), ``ζ`` the
damping (1: critically damped, no overshoot on a step) and ``a_max`` the mirrors' acceleration limit (their
inertia against the drive's torque, expressed at the field). Integrated with four explicit midpoint (second-order
Runge-Kutta) steps per tick, the command linear between ticks; ``jax.lax.scan`` over ticks. (Semi-implicit Euler
with eight steps lagged 0.35 µm behind the exact response at 900 mm/s; the midpoint rule: 0.013 µm.)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

import jaxcnc.jaxconfig  # noqa: F401  (float64)
from jaxcnc.errors import MachineFileError
from jaxcnc.machine import MachineConfig


@dataclass(frozen=True)
class HeadModel:
    """A scan head's tracking model (``docs/scanner.md``; machine file ``[galvo]``: ``tracking_error_s``,
    ``damping``, ``mirror_a_max_mm_s2``)."""

    tracking_error_s: float = 150e-6
    damping: float = 1.0
    a_max_mm_s2: float = 5e6

    @property
    def omega(self) -> float:
        """Natural angular frequency (rad/s): ``2 ζ / τ``."""
        return 2.0 * self.damping / self.tracking_error_s

    @property
    def bandwidth_hz(self) -> float:
        """The -3 dB small-signal bandwidth of the tracking loop (Hz)."""
        z, w = self.damping, self.omega
        return w * math.sqrt(1 - 2 * z * z + math.sqrt((1 - 2 * z * z) ** 2 + 1)) / (2 * math.pi)

    @classmethod
    def from_machine(cls, machine: MachineConfig) -> HeadModel:
        """The head of a scanner-only machine, from its ``[galvo]`` table.

        Raises :class:`~jaxcnc.errors.MachineFileError` naming the file when the machine has no ``[galvo]``
        table (no default head stands in for a missing one).
        """
        g = machine.galvo
        if g is None:
            raise MachineFileError(
                machine.source, "galvo", f"machine {machine.name!r} has no [galvo] table (the scan-head model)"
            )
        return cls(g.tracking_error_s, g.damping, g.mirror_a_max_mm_s2)


@jax.jit
def _simulate(cmd: jnp.ndarray, omega: float, zeta: float, a_max: float, dt: float) -> jnp.ndarray:
    substeps = 4
    h = dt / substeps

    def accel(c, x, v):
        return jnp.clip(omega * omega * (c - x) - 2.0 * zeta * omega * v, -a_max, a_max)

    def tick(state, c_pair):
        c0, c1 = c_pair

        def sub(k, s):  # the explicit midpoint rule (second order), the command at the substep's middle
            x, v = s
            c = c0 + (c1 - c0) * (k + 0.5) / substeps
            xm, vm = x + 0.5 * h * v, v + 0.5 * h * accel(c, x, v)
            return x + h * vm, v + h * accel(c, xm, vm)

        x, v = jax.lax.fori_loop(0, substeps, sub, state, unroll=True)
        return (x, v), x

    x0 = cmd[0]
    _, xs = jax.lax.scan(tick, (x0, jnp.zeros_like(x0)), (cmd[:-1], cmd[1:]))
    return jnp.concatenate([x0[None], xs])


def simulate(cmd_mm: np.ndarray, head: HeadModel, dt_s: float) -> np.ndarray:
    """The mirrors' position per tick for a commanded path: ``cmd_mm`` ``(n, k)`` mm → ``(n, k)`` mm.

    The mirrors start at rest on ``cmd_mm[0]``. Lengths are padded to a power of two (the last command held) so
    that lists of similar size share one compiled program.
    """
    cmd = np.asarray(cmd_mm, np.float64)
    n = cmd.shape[0]
    size = 1 << max(4, (n - 1).bit_length())
    pad = np.concatenate([cmd, np.repeat(cmd[-1:], size - n, axis=0)])
    out = _simulate(jnp.asarray(pad), head.omega, head.damping, head.a_max_mm_s2, dt_s)
    return np.asarray(out)[:n]
