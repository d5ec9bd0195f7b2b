"""The chain bound: a certified lower bound on a chain of gaps from one axis' motion, by dynamic programming
over the axis' speed at the pulses (step 6 of :mod:`.bound`'s argument; ``docs/pulsed.md``).

One axis, speed ``v(t)`` with ``|a| <= A``, ``|v| <= Vc`` everywhere and ``|v| <= F`` (the feed's share) at
every pulse. Gap ``i`` moves it by ``d_i`` in ``h_i`` seconds, ``h_i`` a whole admissible tick count. Cut
``[-F, F]`` into ``B`` intervals; a motion's knot speeds lie in some sequence of them. For a gap and two
intervals ``I = [p0, p1]``, ``J = [q0, q1]``, every motion with end speeds ``v0 ∈ I``, ``v1 ∈ J`` needs

- ``|v1 - v0| <= A h`` (reach), and
- ``Dmin(v0, v1, h) <= d <= Dmax(v0, v1, h)`` where ``Dmax = ∫ min(v0 + A t, v1 + A (h - t), Vc) dt`` is the
  farthest it gets (:func:`dmax`) and ``Dmin(v0, v1, h) = -Dmax(-v0, -v1, h)`` the least.

``Dmax`` grows with both speeds, so its largest value over the pairs within reach is at one corner of the
box (and ``Dmin``'s least at the opposite one): closed form. The *cost* of ``(gap, I, J)`` is the least
admissible count at which some pair passes — necessary for any motion, so the cheapest path through the
intervals (min-plus over the gaps) is at most the time of every motion.

Counts come in blocks ``[lo, hi]`` (:func:`.bound._candidates`); a block is tested once, at ``hi``, and
covers every count inside it: ``dDmax/dh >= max(v0, v1)`` (Leibniz: the integrand's value at ``t = h`` is
``v1``, the rest grows with ``h``; and symmetrically ``v0``), so for ``h`` in the block
``Dmax(h) <= Dmax(hi) + (hi - h) max(0, -max(v0, v1)) <= Dmax(hi) + width max(0, -max(p0, q0))``, and
likewise ``Dmin(h) >= Dmin(hi) - width max(0, min(p1, q1))``; reach only loosens with ``h``. Moving
forward between speeds of the same sign the slack is zero: the block is as good as its least count.

Compiled with JAX: a chunk of gaps' costs ``(G, B, B)`` and the min-plus scan over them in one program
(fixed chunk and candidate counts, so one compile per ``B``); the costs never leave the program.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from jaxcnc.jaxconfig import planning_scope  # float64 on import

#: Gaps per call of the compiled chain program (padded: one compile per bin count).
CHAIN_CHUNK = 256
#: Counts tried one by one at the start of the block that passed (the rest of a wider block is charged
#: the count after the last one tried).
REFINE_COUNTS = 8


def dmax(v0, v1, h, v_cap, a_max, xp=np):
    """``∫_0^h min(v0 + A t, v1 + A (h - t), Vc) dt``: the farthest a 1-D motion from ``v0`` to ``v1`` gets.

    Signed speeds with ``|v0 - v1| <= A h`` and ``v0, v1 <= Vc``; arrays, broadcast. ``xp``: the array module
    (``numpy``, or ``jax.numpy`` inside the compiled chain).
    """
    u = 0.5 * (v0 + v1 + a_max * h)  # the tent's peak
    tent = (2.0 * u * u - v0 * v0 - v1 * v1) / (2.0 * a_max)
    cut = v_cap * h - ((v_cap - v0) ** 2 + (v_cap - v1) ** 2) / (2.0 * a_max)
    return xp.where(u <= v_cap, tent, cut)


def _gap_costs(d, lo, hi, edges, v_cap, a_max, tick_hz):
    """Costs ``(G, B, B)`` (ticks) of each gap between each pair of knot-speed intervals.

    ``d`` ``(G,)`` mm, ``lo``/``hi`` ``(G, C)`` the candidate blocks, ``edges`` ``(B + 1,)`` the intervals.
    First the least block whose test passes; then, inside it, the least count whose own test passes (a
    count is a block of width 0), else the count after the block. No block passes: ``hi[:, -1] + 1``.
    """
    p0, p1 = edges[:-1][None, :, None], edges[1:][None, :, None]  # entry interval (1, B, 1)
    q0, q1 = edges[:-1][None, None, :], edges[1:][None, None, :]  # exit interval (1, 1, B)
    dd = d[:, None, None]
    n_cand = lo.shape[1]
    # slack of a block per unit width: only when the speeds can run against the motion's growth
    up = jnp.maximum(0.0, -jnp.maximum(p0, q0))
    down = jnp.maximum(0.0, jnp.minimum(p1, q1))

    def passes(h, width):
        ah = a_max * h
        ok = (p0 - q1 <= ah) & (q0 - p1 <= ah)  # some pair within reach of each other
        # Dmax grows with both speeds: its largest value over the pairs in reach is at this corner
        top = dmax(jnp.minimum(p1, q1 + ah), jnp.minimum(q1, p1 + ah), h, v_cap, a_max, jnp) + width * up
        bot = -dmax(-jnp.maximum(p0, q0 - ah), -jnp.maximum(q0, p0 - ah), h, v_cap, a_max, jnp) - width * down
        return ok & (bot <= dd) & (dd <= top)

    bins = edges.shape[0] - 1

    def block_cond(state):
        j, first = state
        return (j < n_cand) & jnp.any(first < 0)

    def block_body(state):
        j, first = state
        h = (hi[:, j] / tick_hz)[:, None, None]
        width = ((hi[:, j] - lo[:, j]) / tick_hz)[:, None, None]
        return j + 1, jnp.where(passes(h, width) & (first < 0), j, first)

    first0 = jnp.full((d.shape[0], bins, bins), -1, jnp.int32)
    _, first = jax.lax.while_loop(block_cond, block_body, (0, first0))
    found = first >= 0
    rows = jnp.arange(d.shape[0])[:, None, None]
    b_lo, b_hi = lo[rows, jnp.maximum(first, 0)], hi[rows, jnp.maximum(first, 0)]  # (G, B, B) the block passed
    widest = jnp.minimum(jnp.max(jnp.where(found, b_hi - b_lo, 0)), REFINE_COUNTS - 1)

    def count_cond(state):
        t, cost = state
        return (t <= widest) & jnp.any(found & (cost < 0))

    def count_body(state):
        t, cost = state
        c = b_lo + t
        ok = passes(c / tick_hz, 0.0) & (c <= b_hi) & (cost < 0)
        return t + 1, jnp.where(ok, c, cost)

    _, cost = jax.lax.while_loop(count_cond, count_body, (jnp.zeros((), lo.dtype), jnp.full_like(b_lo, -1)))
    # no count tried passes alone: the first is beyond them (the block's end, or the last count tried)
    cost = jnp.where(cost < 0, jnp.minimum(b_hi + 1, b_lo + widest + 1), cost)
    return jnp.where(found, cost, (hi[:, -1] + 1)[:, None, None])


@functools.partial(jax.jit, static_argnames=("bins",))
def _chain_chunk(cost_to, d, lo, hi, first, valid, knot_cap, v_cap, a_max, tick_hz, bins: int):
    """One chunk of the chain: ``cost_to`` ``(B,)`` least ticks to each interval at the chunk's first knot →
    ``(the same at the knot after its last valid gap, (G,) the least of them after each gap)``. ``first``
    ``(G,)``: a chain starts here (free entry speed); ``valid`` ``(G,)``: padding is skipped."""
    edges = jnp.linspace(-knot_cap, knot_cap, bins + 1)
    costs = _gap_costs(d, lo, hi, edges, v_cap, a_max, tick_hz)

    def step(carry, x):
        cost, start, keep = x
        carry = jnp.where(start, jnp.full_like(carry, jnp.min(carry)), carry)
        nxt = jnp.where(keep, jnp.min(carry[:, None] + cost, axis=0), carry)
        return nxt, jnp.min(nxt)

    return jax.lax.scan(step, cost_to, (costs, first, valid))


def chain_ticks(d_mm, lo, hi, start, tick_hz: float, knot_cap, v_cap, a_max, bins: int) -> np.ndarray:
    """Bounds on chains of gaps from one axis' motion (ticks, one per chain): the cheapest paths through
    the intervals.

    ``d_mm`` ``(g,)`` the axis' signed displacement per gap; ``lo``, ``hi`` ``(g, C)`` int: each gap's
    candidate blocks of admissible counts, tiling every count from the gap's own bound on
    (:func:`.bound._candidates`); ``start`` ``(g,)`` bool, ``start[0]`` true: a chain starts at this gap
    (its entry speed free). ``knot_cap``: the axis' speed limit at a pulse; ``v_cap`` everywhere;
    ``a_max``; ``bins`` intervals of ``[-knot_cap, knot_cap]``. Returns ``(start.sum(),)`` int64. Runs on
    the planning device (:func:`~jaxcnc.jaxconfig.planning_scope`: a sequential scan).
    """
    g = d_mm.shape[0]
    args = (float(knot_cap), float(v_cap), float(a_max), float(tick_hz))
    n_pad = -(-g // CHAIN_CHUNK) * CHAIN_CHUNK  # whole chunks: one shape, one compile

    def padded(x, fill):
        x = np.asarray(x)
        return np.concatenate([x, np.full((n_pad - g, *x.shape[1:]), fill, x.dtype)])

    cols = (
        padded(np.asarray(d_mm, np.float64), 0.0),
        padded(lo, 1),
        padded(hi, 1),
        padded(np.asarray(start, bool), False),
        padded(np.ones(g, bool), False),  # padding gaps are skipped
    )
    least = []  # the least cost after each gap: a running total over the chains
    with planning_scope():
        cost_to = jnp.zeros(bins, jnp.int64)
        for s in range(0, g, CHAIN_CHUNK):  # a few calls of one compiled program
            chunk = [c[s : s + CHAIN_CHUNK] for c in cols]
            cost_to, after = _chain_chunk(cost_to, *chunk, *args, bins=bins)
            least.append(np.asarray(after))
    total = np.concatenate(least)[:g]
    ends = np.append(np.flatnonzero(start)[1:] - 1, g - 1)  # each chain's last gap
    return np.diff(total[ends], prepend=0)
