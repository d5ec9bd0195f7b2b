"""A layer's scan compiled into a galvo board list (issue 18's vector list format, :mod:`jaxcnc.format.vectors`).

The driver makes a :class:`ListTarget` once from a scanner-only machine file (``[machine] tick_hz``,
``discrete_mm``, ``[galvo]``): the board settings — every ``[galvo]`` delay and sky-writing key given there
(:func:`jaxcnc.scanner.compile.machine_settings`), the others from the build's ``[pbf.scanner]`` — as list
commands, and the jump speed. The target is plain data (NumPy records), so the workers that compute the layers
compile them without importing JAX or the scanner package.

A layer's list: ``list_start`` at the first vector, the jump speed, the settings, then per vector of the layer
(:data:`jaxcnc.pbf.order.VECTOR_DTYPE`) a ``set_mark_speed`` / ``set_laser`` where its zone's speed / power
differs from the previous mark's, a ``jump_abs`` (jumps) or ``mark_abs`` (marks; a contour's marks form one chain,
so its corners get the polygon delay and sky-writing), ``list_end``. Positions are rounded to the machine's
discrete. Built with array operations, no Python loop per vector.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from jaxcnc.format.vectors import VECTOR_DTYPE as RECORD_DTYPE
from jaxcnc.format.vectors import Op, VectorHeader, make, records, vector_bytes
from jaxcnc.pbf.params import BuildParams


def list_name(k: int) -> str:
    """File name of layer ``k``'s board list."""
    return f"L{k:06d}.jxv"


@dataclass(frozen=True)
class ListTarget:
    """What a layer's list is compiled for: the board clock and discrete, the settings' list commands (records),
    the jump speed and the machine file's name."""

    tick_hz: float
    discrete_mm: float
    settings: np.ndarray
    jump_speed_mm_s: float
    machine: str

    def header(self, meta: dict | None = None) -> VectorHeader:
        """The header of a list for this target."""
        return VectorHeader(self.tick_hz, self.discrete_mm, ("x", "y"), dict(meta or {}))

    def digest(self) -> str:
        """SHA-256 of everything a list depends on besides the layer (a manifest's lists are keyed by it)."""
        h = hashlib.sha256(np.ascontiguousarray(self.settings).tobytes())
        h.update(repr((self.tick_hz, self.discrete_mm, self.jump_speed_mm_s)).encode())
        return h.hexdigest()


def pbf_settings(params: BuildParams, tick_hz: float):
    """The build's ``[pbf.scanner]`` delays and sky-writing as board :class:`~jaxcnc.scanner.compile.Settings`
    (seconds rounded to ticks; sky-writing: mode 1, ``skywriting_s`` split into run-in and run-out)."""
    from jaxcnc.scanner.compile import Settings

    sc = params.scanner
    half = round(sc.skywriting_s * tick_hz / 2)
    return Settings(
        laser_on=round(sc.laser_on_delay_s * tick_hz),
        laser_off=round(sc.laser_off_delay_s * tick_hz),
        jump=round(sc.jump_delay_s * tick_hz),
        mark=round(sc.mark_delay_s * tick_hz),
        polygon=round(sc.polygon_delay_s * tick_hz),
        sky_mode=1 if sc.skywriting else 0,
        run_in=half if sc.skywriting else 0,
        run_out=half if sc.skywriting else 0,
    )


def list_target(machine, params: BuildParams) -> ListTarget:
    """The target of a scanner-only machine (a :class:`~jaxcnc.machine.MachineConfig` or its file) for a build.

    Raises :class:`~jaxcnc.errors.MachineFileError` (file, line, cause) for a bad machine file or one without
    ``[galvo]``.
    """
    from jaxcnc.machine import MachineConfig, load_machine
    from jaxcnc.scanner.compile import machine_settings

    m = machine if isinstance(machine, MachineConfig) else load_machine(Path(machine))
    s = machine_settings(m, pbf_settings(params, m.tick_hz))
    return ListTarget(
        float(m.tick_hz), float(m.discrete_mm), records(s.commands()), params.scanner.jump_speed_mm_s, str(m.source)
    )


def compile_layer(vectors: np.ndarray, target: ListTarget) -> np.ndarray:
    """A layer's vector list (``(K,)`` :data:`jaxcnc.pbf.order.VECTOR_DTYPE`) as board records
    (:data:`jaxcnc.format.vectors.VECTOR_DTYPE`)."""
    d = target.discrete_mm
    n = len(vectors)
    p0 = np.rint(np.stack([vectors["x0_mm"], vectors["y0_mm"]], axis=1) / d).astype(np.int64)
    p1 = np.rint(np.stack([vectors["x1_mm"], vectors["y1_mm"]], axis=1) / d).astype(np.int64)
    mark = vectors["mark"] == 1
    start = p0[0] if n else np.zeros(2, np.int64)
    prev_end = np.concatenate([start[None], p1[:-1]]) if n else p1
    # the previous mark's speed and power (a jump changes neither)
    m_idx = np.flatnonzero(mark)
    speed, power = vectors["speed_mm_s"], vectors["power_w"]
    new_speed = np.zeros(n, bool)
    new_power = np.zeros(n, bool)
    if m_idx.size:
        new_speed[m_idx] = np.concatenate([[True], speed[m_idx[1:]] != speed[m_idx[:-1]]])
        new_power[m_idx] = np.concatenate([[True], power[m_idx[1:]] != power[m_idx[:-1]]])
    gap = mark & np.any(p0 != prev_end, axis=1)
    # a mark's settings go before the jump that leads to it: a board looks from a jump to the mark after it
    # (sky-writing's run-in point)
    host = np.arange(n) - np.concatenate([[False], ~mark[:-1]]) if n else np.arange(0)
    set_speed, set_power = np.zeros(n, bool), np.zeros(n, bool)
    set_speed[host[new_speed]], set_power[host[new_power]] = True, True
    v_at, w_at = np.zeros(n), np.zeros(n)
    v_at[host[new_speed]], w_at[host[new_power]] = speed[new_speed], power[new_power]
    slots = np.zeros((n, 4), RECORD_DTYPE)
    keep = np.stack([set_speed, set_power, gap, np.ones(n, bool)], axis=1)
    slots["op"][:, 0], slots["value"][:, 0] = Op.SET_MARK_SPEED, v_at
    slots["op"][:, 1], slots["value"][:, 1] = Op.SET_LASER, w_at
    slots["op"][:, 2], slots["pos"][:, 2, :2] = Op.JUMP_ABS, p0
    slots["op"][:, 3] = np.where(mark, Op.MARK_ABS, Op.JUMP_ABS)
    slots["pos"][:, 3, :2] = p1
    head = records([make(Op.LIST_START, pos=tuple(start), value=0.0),
                    make(Op.SET_JUMP_SPEED, value=target.jump_speed_mm_s)])  # fmt: skip
    return np.concatenate([head, target.settings, slots[keep], records([make(Op.LIST_END)])])


def layer_list_bytes(vectors: np.ndarray, target: ListTarget, k: int, z_mm: float) -> bytes:
    """Layer ``k``'s list as the bytes of a list file (checked records, CRC-32; header meta: layer, z, machine)."""
    header = target.header(dict(layer=int(k), z_mm=float(z_mm), machine=Path(target.machine).name))
    return vector_bytes(compile_layer(vectors, target), header, list_name(k))


def mark_length_mm(rec: np.ndarray, header: VectorHeader) -> float:
    """Total length (mm) of a list's straight marks (``mark_abs``), from the positions its moves reach."""
    moving = np.isin(rec["op"], (Op.LIST_START, Op.JUMP_ABS, Op.MARK_ABS))
    r = rec[moving]
    pos = r["pos"][:, :2].astype(np.float64)
    step = np.hypot(*np.diff(pos, axis=0).T)
    return float(step[r["op"][1:] == Op.MARK_ABS].sum() * header.discrete_mm)


def layer_gcode(vectors: np.ndarray) -> str:
    """A layer's vector list as G-code for a scanner-only machine: jumps ``G0``, marks ``G1`` at their zone's
    speed (``F`` mm/min) and power (``S`` W) under ``M3``."""
    lines = ["(jaxcnc powder-bed layer: jumps G0, marks G1)", "G21 G90 G17"]
    if len(vectors):
        lines.append(f"G0 X{vectors['x0_mm'][0]:.6f} Y{vectors['y0_mm'][0]:.6f}")
        lines.append("M3 S0")
    mark = vectors["mark"] == 1
    x, y = vectors["x1_mm"], vectors["y1_mm"]
    f, s = vectors["speed_mm_s"] * 60.0, vectors["power_w"]
    g1 = np.char.add(np.char.add("G1 X", np.char.mod("%.6f", x)), np.char.add(" Y", np.char.mod("%.6f", y)))
    g1 = np.char.add(
        np.char.add(g1, np.char.add(" F", np.char.mod("%.3f", f))), np.char.add(" S", np.char.mod("%.3f", s))
    )
    g0 = np.char.add(np.char.add("G0 X", np.char.mod("%.6f", x)), np.char.add(" Y", np.char.mod("%.6f", y)))
    lines.extend(np.where(mark, g1, g0).tolist())
    lines += ["M5", "M2", ""]
    return "\n".join(lines)


def layer_ticks(out_dir, k: int, machine, table_path=None, planner: str | None = None) -> dict:
    """Layer ``k`` of a build folder as a tick table planned on a scanner-only machine (its file or config).

    The layer's vector file is read (its checksum checked against the manifest), written as G-code
    (:func:`layer_gcode`) beside the table and planned by :func:`jaxcnc.jobs.plan_file`, which writes and verifies
    the table. ``table_path`` defaults to ``OUT/ticks/L000042.ticks``. Returns the planner's report with ``table``
    and ``program`` (the G-code's path) added. Raises :class:`~jaxcnc.pbf.BuildError` for a layer the folder does
    not hold whole.
    """
    import io
    import json

    from jaxcnc.jobs import plan_file
    from jaxcnc.pbf import BuildError
    from jaxcnc.pbf.build import MANIFEST, sha256_bytes

    out = Path(out_dir)
    try:
        man = json.loads((out / MANIFEST).read_text())
    except (OSError, ValueError) as exc:
        raise BuildError(f"{out / MANIFEST}: cannot read the build's manifest ({exc})") from None
    recs = {int(r["index"]): r for r in man.get("layers", [])}
    if k not in recs:
        raise BuildError(
            f"{out / MANIFEST}: layer {k} is not in this build (layers 0..{man.get('layer_count', 0) - 1})"
        )
    f = out / recs[k]["file"]
    raw = f.read_bytes() if f.is_file() else b""
    if sha256_bytes(raw) != recs[k]["sha256"]:
        raise BuildError(f"{f}: missing or its checksum differs from the manifest's; build again")
    vectors = np.load(io.BytesIO(raw), allow_pickle=False)
    table = Path(table_path) if table_path is not None else out / "ticks" / f"L{k:06d}.ticks"
    table.parent.mkdir(parents=True, exist_ok=True)
    prog = table.with_suffix(".ngc")
    prog.write_text(layer_gcode(vectors))
    report = plan_file(prog, machine, table, planner=planner, progress=False)
    return dict(report, table=str(table), program=str(prog))
