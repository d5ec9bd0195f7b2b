"""Batched evaluation of the path: position and derivatives in the path parameter ``s``.

One kernel serves every span kind, on NumPy or JAX arrays alike (``xp``), so the tick stage, the
planner's grid and the build-time checks evaluate the same formulas:

* line: ``q = o + s T`` (``s`` is arc length);
* arc or helix (centre ``c``, in-plane unit vectors ``e1, e2``, axis ``n``, radius ``r``, rise
  ``h`` mm per radian): at angle ``ψ = ω s``, ``ω = 1/sqrt(r² + h²)``,
  ``q = c + r cos ψ e1 + r sin ψ e2 + h ψ n`` — exact, unit speed, ``q' = ω(-r sin ψ e1 + r cos ψ e2 + h n)``,
  ``q'' = -ω² r (cos ψ e1 + sin ψ e2)``, ``q''' = ω³ r (sin ψ e1 - cos ψ e2)``;
* polynomial span (NURBS piece, blend): ``q = P(V(s/L))`` with the rational Bézier ``P`` and the
  timing polynomial ``V`` (:mod:`jaxcnc.geometry.poly`): Horner's scheme on both, the quotient rule
  for ``P``'s derivatives, then the chain rule
  ``q' = P' V₁``, ``q'' = P'' V₁² + P' V₂``, ``q''' = P''' V₁³ + 3 P'' V₁ V₂ + P' V₃`` (``V_k = d^k u/ds^k``);
* point (dwell, event): ``q = o``.

Arrays are in *column layout* (:func:`span_arrays`): one row per field component, spans along the
last axis, so a gather by span index reads contiguous vectors (an order of magnitude faster on CPU
than gathering ``(m, p+1, 4)`` blocks, and it fuses with Horner's loop).
"""

from __future__ import annotations

from types import ModuleType

import numpy as np

from jaxcnc.buckets import bucket_size
from jaxcnc.geometry.kinds import POLY_KINDS, SpanKind, kind_in


def span_arrays(spans, xp: ModuleType = np) -> dict:
    """The fields the evaluation reads, in column layout, as ``xp`` arrays (``numpy`` or ``jax.numpy``)."""

    if xp is np:
        put = np.asarray
    else:  # device_put: xp.asarray of a host array would compile a program per shape
        import jax

        put = jax.device_put

    def col(a: np.ndarray) -> np.ndarray:
        return put(np.ascontiguousarray(np.moveaxis(np.asarray(a), 0, -1)))

    arcs, polys = spans.arcs, spans.polys
    return {
        "kind": put(spans.kind),
        "item": put(spans.item),
        "length": put(spans.length),
        "origin": col(spans.origin),
        "tangent": col(spans.tangent_in),
        "arc_center": col(arcs.center),
        "arc_e1": col(arcs.e1),
        "arc_e2": col(arcs.e2),
        "arc_axis": col(arcs.axis),
        "arc_radius": put(arcs.radius),
        "arc_rise": put(arcs.rise),
        "poly_coeffs": put(_poly_columns(np.moveaxis(polys.coeffs, 0, -1))),  # (p+1, 4, q)
        "poly_timing": col(polys.timing),  # (6, q)
    }


def window_span_arrays(spans, first: int, last: int, rows: int, table_rows: int | None) -> dict:
    """:func:`span_arrays` (JAX) of spans ``first..last-1`` alone, row ``k`` being span ``first + k``: the spans padded
    to ``rows`` with points, their arc and poly rows (``item`` renumbered) padded to ``table_rows`` each (0: the path
    has none of that kind), or with ``None`` each to the bucket of its own rows (0: the window has none) — the
    values of ``span_arrays(pad_spans(pad_tables(slice_spans(...))))``, built in place in column layout, without
    the copies of every span field those make (the tick stage uploads one such window of a long job at a time, the
    planner's grid one per window: :func:`~jaxcnc.planners.grid.device_spans`)."""
    import jax

    from jaxcnc.geometry.spans import pad_table_rows

    n = last - first
    kind, item = spans.kind[first:last], spans.item[first:last]
    is_arc = (kind == SpanKind.ARC) & (item >= 0)
    is_poly = kind_in(kind, POLY_KINDS) & (item >= 0)  # (as spans._own_tables renumbers them)
    arc_rows, poly_rows = item[is_arc], item[is_poly]
    out_item = np.full(rows, -1, item.dtype)
    out_item[:n] = item
    out_item[:n][is_arc] = np.arange(arc_rows.size)
    out_item[:n][is_poly] = np.arange(poly_rows.size)
    out_kind = np.full(rows, SpanKind.POINT, kind.dtype)
    out_kind[:n] = kind
    length = np.zeros(rows)
    length[:n] = spans.length[first:last]

    def col(a: np.ndarray, take, size: int, pad) -> np.ndarray:
        """Rows ``take`` of ``a`` ``(m, ...)`` in column layout ``(..., size)``, the rest ``pad``."""
        src = np.moveaxis(a[take], 0, -1)
        out = np.empty(src.shape[:-1] + (size,), a.dtype)
        out[..., : src.shape[-1]] = src
        out[..., src.shape[-1] :] = np.asarray(pad, a.dtype).reshape(src.shape[:-1] + (1,))
        return out

    window = slice(first, last)
    arrays = {
        "kind": out_kind,
        "item": out_item,
        "length": length,
        "origin": col(spans.origin, window, rows, np.zeros(3)),
        "tangent": col(spans.tangent_in, window, rows, np.zeros(3)),
    }
    arcs, polys = spans.arcs, spans.polys
    arc_pad, poly_pad = pad_table_rows(polys.coeffs.shape[1:])
    if table_rows is None:
        n_arc_rows, n_poly_rows = (bucket_size(r.size) if r.size else 0 for r in (arc_rows, poly_rows))
    else:
        n_arc_rows, n_poly_rows = (table_rows if len(arcs) else 0), (table_rows if len(polys) else 0)
    for name in ("center", "e1", "e2", "axis", "radius", "rise"):
        arrays[f"arc_{name}"] = col(getattr(arcs, name), arc_rows, n_arc_rows, arc_pad[name])
    arrays["poly_coeffs"] = _poly_columns(col(polys.coeffs, poly_rows, n_poly_rows, poly_pad["coeffs"]))
    arrays["poly_timing"] = col(polys.timing, poly_rows, n_poly_rows, poly_pad["timing"])
    return {k: jax.device_put(v) for k, v in arrays.items()}


def junction_curvatures(spans, j: np.ndarray, arrays: dict | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Curvature vectors ``(k, 3)`` at the end of spans ``j`` ``(k,)`` and at the start of the spans after them
    (NumPy; ``arrays``: :func:`span_arrays` of ``spans`` where made already)."""
    arrays = span_arrays(spans) if arrays is None else arrays
    k_end = evaluate_path(arrays, j, spans.length[j], 2)[2]
    k_start = evaluate_path(arrays, j + 1, np.zeros(j.size), 2)[2]
    return k_end, k_start


def _poly_columns(c: np.ndarray) -> np.ndarray:
    """Poly coefficients in column layout ``(p+1, 4, q)`` from ``(p+1, 4, q)`` or polynomial ``(p+1, 3, q)`` ones
    (the weight 1 added: what the evaluation reads), contiguous."""
    from jaxcnc.geometry.spans import with_unit_weight

    return np.ascontiguousarray(c if c.shape[1] == 4 else with_unit_weight(c, axis=1))


def _horner(c, x, order: int, xp):
    """Value and derivatives ``[f, f', ...]`` of ``sum_k c[k] x^k`` (``c`` a sequence of arrays)."""
    deg = len(c) - 1
    d = [c[deg]] + [xp.zeros_like(x) for _ in range(order)]
    for k in range(deg - 1, -1, -1):
        for r in range(min(order, deg - k), 0, -1):
            d[r] = d[r] * x + d[r - 1]
        d[0] = d[0] * x + c[k]
    fact = 1.0
    for r in range(2, order + 1):
        fact *= r
        d[r] = fact * d[r]
    return d


def _rational(c, item, u, order: int, xp, polynomial: bool = False) -> list:
    """Per coordinate: ``[P_i - o_i, P_i', ...]`` of rational Bézier pieces ``item`` at ``u`` (quotient rule).

    ``c``: ``(p+1, 4, n)`` homogeneous power-basis coefficients in column layout. ``polynomial``: every
    weight is 1 (blends), so ``P = N`` and the quotient rule is skipped.
    """
    deg = c.shape[0] - 1
    if polynomial:
        return [_horner([c[k, comp][item] for k in range(deg + 1)], u, order, xp) for comp in range(3)]
    h = [_horner([c[k, comp][item] for k in range(deg + 1)], u, order, xp) for comp in range(4)]
    w = h[3]
    out = []
    for i in range(3):
        n = h[i]
        p = [n[0] / w[0]]
        if order >= 1:
            p.append((n[1] - p[0] * w[1]) / w[0])
        if order >= 2:
            p.append((n[2] - 2.0 * p[1] * w[1] - p[0] * w[2]) / w[0])
        if order >= 3:
            p.append((n[3] - 3.0 * p[2] * w[1] - 3.0 * p[1] * w[2] - p[0] * w[3]) / w[0])
        if order >= 4:
            p.append((n[4] - 4.0 * p[3] * w[1] - 6.0 * p[2] * w[2] - 4.0 * p[1] * w[3] - p[0] * w[4]) / w[0])
        out.append(p)
    return out


def _poly(a: dict, span, s, order: int, xp, polynomial: bool = False):
    """Per coordinate ``i``: ``[q_i - o_i, q_i', ...]`` on polynomial spans."""
    q = a["poly_timing"].shape[-1]
    item = xp.clip(a["item"][span], 0, q - 1)
    length = a["length"][span]
    safe = xp.where(length > 0, length, 1.0)
    sigma = s / safe
    t = a["poly_timing"]
    v = _horner([t[k][item] for k in range(6)], sigma, order, xp)
    vs = [None] + [v[r] / safe**r for r in range(1, order + 1)]  # d^r u / ds^r
    out = []
    for p in _rational(a["poly_coeffs"], item, v[0], order, xp, polynomial):
        d = [p[0]]
        if order >= 1:
            d.append(p[1] * vs[1])
        if order >= 2:
            d.append(p[2] * vs[1] ** 2 + p[1] * vs[2])
        if order >= 3:
            d.append(p[3] * vs[1] ** 3 + 3.0 * p[2] * vs[1] * vs[2] + p[1] * vs[3])
        if order >= 4:  # Faà di Bruno
            v1, v2, v3, v4 = vs[1:5]
            d.append(p[4] * v1**4 + 6.0 * p[3] * v1**2 * v2 + p[2] * (3.0 * v2**2 + 4.0 * v1 * v3) + p[1] * v4)
        out.append(d)
    return out


def _arc_angle(a: dict, span, s, xp) -> tuple:
    """``(item, r, h, ω, ψ)`` of arcs ``span`` at ``s`` (clipped to the span as :func:`evaluate_path` does)."""
    k = a["arc_radius"].shape[-1]
    item = xp.clip(a["item"][span], 0, k - 1)
    r, h = a["arc_radius"][item], a["arc_rise"][item]
    omega = 1.0 / xp.sqrt(r * r + h * h)
    return item, r, h, omega, s * omega


def arc_trig(a: dict, span, s, xp: ModuleType = np) -> tuple:
    """``(cos ψ, sin ψ)`` at ``s`` mm along arcs ``span`` (``s`` clipped to the span), the values
    :func:`evaluate_path` uses: computed apart and handed back as its ``trig``, a compiled caller evaluates them
    once per point (XLA's CPU backend would otherwise evaluate both again in the loop of each output column)."""
    s = xp.clip(s, 0.0, a["length"][span])
    psi = _arc_angle(a, span, s, xp)[4]
    return xp.cos(psi), xp.sin(psi)


def _arc(a: dict, span, s, order: int, xp, trig: tuple | None = None):
    """Per coordinate ``i``: ``[q_i, q_i', ...]`` on arcs and helices (absolute positions); ``trig``: ``(cos ψ,
    sin ψ)`` from :func:`arc_trig` (computed here when ``None``)."""
    item, r, h, omega, psi = _arc_angle(a, span, s, xp)
    cos, sin = (xp.cos(psi), xp.sin(psi)) if trig is None else trig
    out = []
    for i in range(3):
        e1, e2, n = a["arc_e1"][i][item], a["arc_e2"][i][item], a["arc_axis"][i][item]
        d = [a["arc_center"][i][item] + r * (cos * e1 + sin * e2) + h * psi * n]
        if order >= 1:
            d.append(omega * (r * (cos * e2 - sin * e1) + h * n))
        if order >= 2:
            d.append(-(omega**2) * r * (cos * e1 + sin * e2))
        if order >= 3:
            d.append(omega**3 * r * (sin * e1 - cos * e2))
        if order >= 4:
            d.append(omega**4 * r * (cos * e1 + sin * e2))
        out.append(d)
    return out


def evaluate_path(
    a: dict, span, s, order: int = 0, xp: ModuleType = np, only: str | None = None, trig: tuple | None = None
) -> tuple:
    """Position and derivatives in ``s`` of span ``span[i]`` at ``s[i]`` mm from its start.

    Args:
        a: :func:`span_arrays` of the spans (the same ``xp``); span ``(m,)`` int; s ``(m,)`` mm (or any
            shapes that broadcast: span ``(m, 1)`` with s ``(m, k)`` reads each span's fields once).
        order: highest derivative (0..4).
        only: every queried span is of one family, and the other families' formulas are skipped:
            ``"arc"`` (arcs and helices), ``"curve"`` (polynomial spans) or ``"blend"`` (polynomial
            spans whose weights are all 1: no quotient rule).
        trig: with ``only="arc"``, :func:`arc_trig` of the same ``span`` and ``s`` (else computed here).
    Returns:
        ``(q, q', ..., q^(order))``, each ``(m, 3)`` (the broadcast shape, then 3): mm, then per mm of
        path parameter.
    """
    if not 0 <= order <= 4:
        raise ValueError("order must be 0 to 4")
    if only not in (None, "arc", "curve", "blend"):
        raise ValueError(f"unknown span family {only!r}")
    if trig is not None and only != "arc":
        raise ValueError("trig is for arcs alone (only='arc')")
    if xp is np and only is None:
        return _evaluate_families(a, span, s, order)
    kind = a["kind"][span]
    s = xp.clip(s, 0.0, a["length"][span])
    line = kind == SpanKind.LINE
    arc = kind == SpanKind.ARC
    poly = (kind == SpanKind.CURVE) | (kind == SpanKind.BLEND)
    has_polys = a["poly_timing"].shape[-1] and only in (None, "curve", "blend")
    polys = _poly(a, span, s, order, xp, only == "blend") if has_polys else None
    arcs = _arc(a, span, s, order, xp, trig) if a["arc_radius"].shape[-1] and only in (None, "arc") else None
    zero = xp.zeros_like(s)
    cols = [[] for _ in range(order + 1)]
    for i in range(3):
        o, t = a["origin"][i][span], a["tangent"][i][span]
        if only == "arc":
            val = arcs[i]
        elif only is not None:
            val = [o + polys[i][0]] + polys[i][1:]
        else:
            val = [o + xp.where(line, s, 0.0) * t, xp.where(line, t, 0.0)] + [zero] * (order - 1)
            val = val[: order + 1]
            if polys is not None:
                pv = [o + polys[i][0]] + polys[i][1:]
                val = [xp.where(poly, pv[r], val[r]) for r in range(order + 1)]
            if arcs is not None:
                val = [xp.where(arc, arcs[i][r], val[r]) for r in range(order + 1)]
        for r in range(order + 1):
            cols[r].append(val[r])
    return tuple(xp.stack(c, axis=-1) for c in cols)


def _evaluate_families(a: dict, span: np.ndarray, s: np.ndarray, order: int) -> tuple:
    """:func:`evaluate_path` on NumPy arrays, each family's formulas on its own rows alone: a path of lines with a
    few arcs does not pay every arc's sines and cosines on every line. Each row gets the value of the same
    operations as in :func:`evaluate_path`'s selection (``s`` clipped; lines ``o + s t``; other rows ``o + 0 t``)."""
    shape = np.broadcast_shapes(np.shape(span), np.shape(s))
    span = np.broadcast_to(span, shape).reshape(-1)
    s = np.clip(np.broadcast_to(s, shape).reshape(-1), 0.0, a["length"][span])
    kind = a["kind"][span]
    # the lines' and points' derivatives from the second on are 0: zeroed pages, not values written
    out = [np.empty((span.size, 3)) for _ in range(min(order, 1) + 1)]
    out += [np.zeros((span.size, 3)) for _ in range(order - 1)]
    arc = kind == SpanKind.ARC
    poly = (kind == SpanKind.CURVE) | (kind == SpanKind.BLEND)
    rest = ~(arc | poly)  # lines, and points (``o``, derivatives 0)
    # where lines and points are most rows, their formulas run on every row and the other families' rows are written
    # over below: no scatter into the rest's rows (a contour's blends: ~1/3 of the time)
    rows = np.flatnonzero(rest) if 2 * np.count_nonzero(rest) < rest.size else slice(None)
    sp, line = span[rows], kind[rows] == SpanKind.LINE
    step = np.where(line, s[rows], 0.0)
    for i in range(3):
        o, t = a["origin"][i][sp], a["tangent"][i][sp]
        out[0][rows, i] = o + step * t
        if order >= 1:
            out[1][rows, i] = np.where(line, t, 0.0)
    for family, mask in (("arc", arc), ("curve", poly)):
        rows = np.flatnonzero(mask)
        if rows.size:
            for r, v in enumerate(evaluate_path(a, span[rows], s[rows], order, only=family)):
                out[r][rows] = v
    return tuple(v.reshape(shape + (3,)) for v in out)


def evaluate_bezier(coeffs_t, origin_t, seg, u, order: int = 0, xp: ModuleType = np) -> tuple:
    """Position and ``u``-derivatives of rational Bézier pieces ``seg[i]`` at ``u[i]`` (no timing).

    Args:
        coeffs_t: ``(p+1, 4, n)`` homogeneous power-basis coefficients in column layout;
            origin_t: ``(3, n)``; seg ``(m,)``; u ``(m,)``.
    Returns:
        ``(P, P', ..., P^(order))``, each ``(m, 3)``.
    """
    cols = [[] for _ in range(order + 1)]
    for i, p in enumerate(_rational(coeffs_t, seg, u, order, xp)):
        p[0] = origin_t[i][seg] + p[0]
        for r in range(order + 1):
            cols[r].append(p[r])
    return tuple(xp.stack(c, axis=1) for c in cols)


def evaluate(coeffs, origin, u, order: int = 0) -> tuple:
    """:func:`evaluate_bezier` for pieces in row layout: coeffs ``(m, p+1, 4)``, origin ``(m, 3)``, u ``(m,)``.

    JAX arrays in give JAX arrays out (jittable); NumPy in, NumPy out.
    """
    xp = np if all(isinstance(a, np.ndarray | float) for a in (coeffs, origin, u)) else _jnp()
    rows = xp.arange(u.shape[0])
    return evaluate_bezier(
        xp.transpose(xp.asarray(coeffs), (1, 2, 0)), xp.transpose(xp.asarray(origin)), rows, xp.asarray(u), order, xp
    )


def _jnp() -> ModuleType:
    import jax.numpy as jnp

    return jnp
