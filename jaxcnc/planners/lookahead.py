"""Whole-program acceleration-limited look-ahead as two parallel scans.

With ``x = v²`` at the junction nodes ``0..n``, constant acceleration ``a_k`` over span ``k`` of
length ``L_k`` changes ``x`` by at most ``d = 2 a_k L_k`` (from ``v² = v0² + 2 a s``). The
fastest admissible profile under node caps ``b`` is the fixed point of

    forward:  x_k = min(b_k, x_{k-1} + d_{k-1})      backward: x_k = min(b_k, x_{k+1} + d_k)

Each step is the map ``f(x) = min(B, x + D)``; these maps compose in closed form,
``f2 ∘ f1 = (min(B2, B1 + D2), D1 + D2)``, an associative operation. ``lax.associative_scan``
therefore runs each pass in O(log n) parallel depth — the whole program at once, on CPU or
GPU, with no look-ahead window to run dry. Only sums of non-negative numbers occur, so unlike
the ``cumsum``/``cummin`` closed form there is no cancellation on long programs.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jaxcnc.jaxconfig import on_cpu  # (and float64)


def _compose(first: tuple[jnp.ndarray, jnp.ndarray], second: tuple[jnp.ndarray, jnp.ndarray]):
    b1, d1 = first
    b2, d2 = second
    return jnp.minimum(b2, b1 + d2), d1 + d2


def forward_pass(b: jnp.ndarray, d: jnp.ndarray) -> jnp.ndarray:
    """``x_k = min(b_k, x_{k-1} + d_k)`` with ``x_{-1} = inf``; ``b``, ``d`` of shape ``(m,)``.

    On a GPU the associative scan runs in O(log m) parallel depth; on a CPU a sequential scan does the
    same work in a fraction of the time (~2 ns a step, compiled in milliseconds where the associative
    scan takes a second to compile), so the backend decides.
    """
    if not on_cpu():
        big, _ = jax.lax.associative_scan(_compose, (b, d))
        return big

    def step(x_prev, row):
        bk, dk = row
        x = jnp.minimum(bk, x_prev + dk)
        return x, x

    _, x = jax.lax.scan(step, jnp.asarray(jnp.inf, b.dtype), (b, d))
    return x


def lookahead(node_cap: jnp.ndarray, delta: jnp.ndarray) -> jnp.ndarray:
    """Maximal ``x = v²`` at the nodes under the caps and the per-span reach.

    Args:
        node_cap: ``(n+1,)`` caps on v² at the nodes (0 where the motion must stop).
        delta: ``(n,)`` reach ``2 a_k L_k`` of span k, between node k and node k+1.
    Returns:
        ``(n+1,)`` v² at the nodes: the backward pass (deceleration) then the forward pass.
    """
    zero = jnp.zeros((1,), delta.dtype)
    # backward: node k is reached from node k+1 over span k
    back = forward_pass(node_cap[::-1], jnp.concatenate([zero, delta[::-1]]))[::-1]
    return forward_pass(back, jnp.concatenate([zero, delta]))
