"""A simulated axis: each mode of the machine file a damped second-order system driven by the table.

The model (one mode of one axis; the modes of an axis add their errors). The table commands the
position ``u(t)``; the drive moves linearly between ticks, so the commanded velocity ``w = u̇`` is held
constant over each tick (a zero-order hold of the velocity, ``w_k = (u_{k+1} - u_k)·f``). The tool sits on
a spring and damper of natural frequency ``f_n`` and damping ratio ``ζ`` behind the drive (base
excitation, ``ω = 2π f_n``):

    ÿ = -2ζω (ẏ - u̇) - ω² (y - u)

In the error ``e = y - u`` and the tool's velocity ``q = ẏ`` (both continuous across ticks) this is

    ė = q - w,   q̇ = -ω² e - 2ζω (q - w)          x = [e, q],  ẋ = A x + B w

discretised **exactly** at the tick rate for the held ``w`` (zero-order hold,
``scipy.signal.cont2discrete``, i.e. the matrix exponential): ``x_{k+1} = Φ x_k + Γ w_k``. The recursion
runs as two IIR filters (``scipy.signal.lfilter``, state carried across chunks), so a table of any length
is simulated in bounded memory, with no Python loop over ticks.

A ramp ``u = v t`` from rest gives the classic response ``e(t) = -(v/ω_d) e^{-ζωt} sin(ω_d t)``;
``tests/test_dynamics.py`` compares the simulation with it (and with a step over one tick) in closed form.

**Residual vibration** at a tick where the command stands still: the amplitude of the free vibration the
state carries, ``√(e² + ((ė + ζω e)/ω_d)²)`` (``ė = q`` when ``w = 0``), summed over the axis' modes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal


@dataclass(frozen=True)
class Mode:
    """One vibration mode of an axis: natural frequency ``f_hz`` and damping ratio ``zeta`` (0 <= ζ < 1)."""

    f_hz: float
    zeta: float

    @property
    def omega(self) -> float:
        return 2 * math.pi * self.f_hz

    @property
    def omega_d(self) -> float:
        """The damped angular frequency ``ω √(1 - ζ²)`` (rad/s)."""
        return self.omega * math.sqrt(1.0 - self.zeta**2)


def discretise(mode: Mode, tick_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """The exact zero-order-hold discretisation ``(Φ (2, 2), Γ (2,))`` of ``mode`` at ``tick_hz``: state
    ``[e, q]`` (mm, mm/s), input the held commanded velocity (mm/s)."""
    w, z = mode.omega, mode.zeta
    a = np.array([[0.0, 1.0], [-(w**2), -2 * z * w]])
    b = np.array([[-1.0], [2 * z * w]])
    ad, bd, *_ = signal.cont2discrete((a, b, np.eye(2), np.zeros((2, 1))), 1.0 / tick_hz, method="zoh")
    return ad, bd[:, 0]


class ModeFilter:
    """The recursion ``x_{k+1} = Φ x_k + Γ w_k`` of one mode as IIR filters, fed chunk by chunk.

    ``step(w)`` takes the held velocities ``w`` ``(m,)`` of ticks ``k..k+m-1`` and returns the states
    ``x`` ``(m, 2)`` at ticks ``k+1..k+m`` (the state at tick 0 is rest: ``x = 0``)."""

    def __init__(self, mode: Mode, tick_hz: float):
        self.mode = mode
        phi, gamma = discretise(mode, tick_hz)
        # transfer functions from w_k to e_{k+1} and q_{k+1}: x_{k+1} = (I - Φ z^-1)^-1 Γ w_k, and for a 2x2 Φ
        # (I - Φ z^-1)^-1 = (I - z^-1 (tr(Φ) I - Φ)) / (1 - tr(Φ) z^-1 + det(Φ) z^-2)   (Cayley-Hamilton)
        den = np.array([1.0, -np.trace(phi), np.linalg.det(phi)])
        num = np.stack([gamma, -((np.trace(phi) * np.eye(2) - phi) @ gamma)], axis=1)  # (2 outputs, 2 taps)
        self.num, self.den = num, den
        self.zi = [np.zeros(2), np.zeros(2)]
        #: the state ``[e, q]`` at the tick after the last one fed (rest before the first)
        self.x = np.zeros(2)

    def step(self, w: np.ndarray) -> np.ndarray:
        out = np.empty((w.shape[0], 2))
        for i in range(2):  # two outputs (e, q), not a loop over ticks
            out[:, i], self.zi[i] = signal.lfilter(self.num[i], self.den, w, zi=self.zi[i])
        if w.shape[0]:
            self.x = out[-1]
        return out


def amplitude(mode: Mode, e: np.ndarray, q: np.ndarray) -> np.ndarray:
    """The free-vibration amplitude (mm) of states ``e``, ``q`` where the command stands still."""
    return np.hypot(e, (q + mode.zeta * mode.omega * e) / mode.omega_d)
