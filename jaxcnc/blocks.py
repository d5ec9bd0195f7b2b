"""Block kinds: motion blocks beyond the core ones, lowered to rows the geometry evaluates exactly.

A :class:`~jaxcnc.program.Program` holds five row kinds (line, arc/helix, (rational) B-spline, dwell, event),
and the geometry and the planners evaluate each in closed form inside compiled array kernels — so that list
is closed on purpose. What is open is the *block*: a G-code word (or a front end's element) whose motion is
something else — an involute, a clothoid, a control's special interpolation — is a :class:`BlockKind` that
turns one block into a chain of core pieces (:class:`Line`, :class:`Arc`, :class:`Curve`) from the block's
start to its end, within a tolerance it states. The G-code interpreter then emits those pieces as the
block's rows (same source line, feed, laser state), and everything downstream plans them like any other.

Block kinds are looked up by their G word (``"G2.2"``). A third-party kind subclasses :class:`BlockKind` and
is declared under the ``jaxcnc.block_kinds`` entry-point group, one entry per G word::

    [project.entry-points."jaxcnc.block_kinds"]
    "G2.2" = "involute_block:Involute"
    "G3.2" = "involute_block:Involute"

The word is then modal in the motion group (like G1) in every dialect the kind names. An example with its
geometry derived is ``examples/involute_block.py`` (Fanuc's involute interpolation).
"""

from __future__ import annotations

import abc
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from jaxcnc.plugins import Registry


@dataclass(frozen=True, eq=False)
class BlockCall:
    """One block of a registered kind, as the interpreter hands it over (program frame, mm).

    Attributes:
        word: the G word that selected the kind (``"G3.2"``), as registered.
        start_mm, end_mm: ``(3,)`` where the block starts and where its axis words put its end.
        params: the block's parameter words the kind declares (:attr:`BlockKind.letters`), by letter; those
            in :attr:`BlockKind.lengths` already in mm (G20 inch programs converted).
        plane: 17, 18 or 19 (G17 XY, G18 ZX, G19 YZ).
        dialect: the dialect's name.
    """

    word: str
    start_mm: np.ndarray
    end_mm: np.ndarray
    params: Mapping[str, float]
    plane: int
    dialect: str


@dataclass(frozen=True, eq=False)
class Line:
    """A straight piece to ``end_mm`` ``(3,)``."""

    end_mm: np.ndarray


@dataclass(frozen=True, eq=False)
class Arc:
    """A circular arc (or helix along the plane's normal) to ``end_mm`` about ``center_mm`` (both ``(3,)``) in
    ``plane`` (17/18/19); ``turn`` +1 counter-clockwise, -1 clockwise."""

    end_mm: np.ndarray
    center_mm: np.ndarray
    turn: int
    plane: int = 17


@dataclass(frozen=True, eq=False)
class Curve:
    """A clamped (rational) B-spline from the piece's start to its last control point: ``degree``, control
    points ``points_mm`` ``(m, 3)``, ``weights`` ``(m,)``, ``knots`` ``(m + degree + 1,)``."""

    degree: int
    points_mm: np.ndarray
    weights: np.ndarray
    knots: np.ndarray

    @property
    def end_mm(self) -> np.ndarray:
        return np.asarray(self.points_mm[-1], dtype=np.float64)


Piece = Line | Arc | Curve


class BlockKind(abc.ABC):
    """A kind of motion block, lowered to core pieces.

    Attributes:
        name: what the block is called in messages (``"involute interpolation"``).
        letters: the parameter letters a block of this kind reads besides the axis words (``"IJR"``); any other
            word left in the block is an error, as for every block.
        lengths: which of ``letters`` are lengths (converted to mm under G20).
        dialects: the dialects the kind's words belong to (``None``: every dialect).
    """

    name: ClassVar[str] = ""
    letters: ClassVar[str] = ""
    lengths: ClassVar[str] = ""
    dialects: ClassVar[tuple[str, ...] | None] = None

    @abc.abstractmethod
    def lower(self, block: BlockCall) -> list[Piece]:
        """The pieces from ``block.start_mm`` to ``block.end_mm``, chained end to start.

        Raise ``ValueError`` with the reason for a block that cannot be honoured (the interpreter reports it
        at the block's word, one line); any other exception is reported as a failure of the plug-in."""

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.name!r}>"


def _as_block_kind(obj: Any) -> BlockKind:
    if isinstance(obj, BlockKind):
        return obj
    if isinstance(obj, type) and issubclass(obj, BlockKind):
        return obj()
    raise TypeError(f"{obj!r} is not a BlockKind (subclass jaxcnc.blocks.BlockKind and implement lower())")


#: Block kinds by G word (``"G2.2"``; entry-point group ``jaxcnc.block_kinds``). None is built in.
BLOCK_KINDS: Registry[BlockKind] = Registry("block kind", "jaxcnc.block_kinds", adapt=_as_block_kind)


def g_word(code_tenths: int) -> str:
    """The canonical spelling of a G code given in tenths (``22`` → ``"G2.2"``, ``10`` → ``"G1"``)."""
    whole, tenth = divmod(code_tenths, 10)
    return f"G{whole}" if tenth == 0 else f"G{whole}.{tenth}"


def chain_error(pieces: list[Piece], start_mm: np.ndarray, end_mm: np.ndarray) -> float:
    """The largest gap (mm) in the chain ``start → pieces → end``: a kind's pieces must join up."""
    at, gap = np.asarray(start_mm, dtype=np.float64), 0.0
    for p in pieces:
        first = p.points_mm[0] if isinstance(p, Curve) else None
        if first is not None:
            gap = max(gap, float(np.linalg.norm(np.asarray(first) - at)))
        at = np.asarray(p.end_mm, dtype=np.float64)
    return max(gap, float(np.linalg.norm(at - np.asarray(end_mm, dtype=np.float64))))


__all__ = ["BLOCK_KINDS", "Arc", "BlockCall", "BlockKind", "Curve", "Line", "Piece", "chain_error", "g_word"]
