"""Front ends: each reads one kind of input file into what the planners take, chosen by the file's suffix.

A front end turns a file into a :class:`~jaxcnc.program.Program` (contours: G-code, drawings) or a
:class:`~jaxcnc.program.PointJob` (points burned one pulse each), starting where the machine is homed
(:func:`~jaxcnc.program.program_start`). The job layer (:mod:`jaxcnc.jobs`) picks one by suffix from
:data:`FRONT_ENDS` and never knows more about it than this protocol.

A third-party front end subclasses :class:`FrontEnd` and is declared under the ``jaxcnc.front_ends``
entry-point group, one entry per suffix (without the dot)::

    [project.entry-points."jaxcnc.front_ends"]
    svg = "my_svg:SvgFrontEnd"

Options a front end does not know are errors, never ignored: :meth:`FrontEnd.load` takes keyword
options and a front end refuses those it lacks (:meth:`FrontEnd.refuse_options`).
"""

from __future__ import annotations

import abc
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar, Literal

from jaxcnc.errors import JaxcncError
from jaxcnc.plugins import Registry

if TYPE_CHECKING:
    from jaxcnc.machine import MachineConfig
    from jaxcnc.program import PointJob, Program


class FrontEnd(abc.ABC):
    """Reads one kind of input file.

    Attributes:
        name: what the input is called in messages (``"G-code"``).
        produces: ``"program"`` (contours) or ``"points"`` (a point job, for pulsed engraving).
        options: the keyword options :meth:`load` accepts (others are refused).
    """

    name: ClassVar[str] = ""
    produces: ClassVar[Literal["program", "points"]] = "program"
    options: ClassVar[tuple[str, ...]] = ()

    @abc.abstractmethod
    def load(self, path: Path, machine: MachineConfig, **options: Any) -> Program | PointJob:
        """The job in ``path`` for ``machine``; raises a :class:`~jaxcnc.errors.JaxcncError` naming the
        file (and line or entity) on bad input."""

    def refuse_options(self, path: Path, options: dict[str, Any]) -> None:
        """Raise for options this front end does not take (set to anything but ``None``)."""
        unknown = sorted(k for k, v in options.items() if v is not None and k not in self.options)
        if unknown:
            takes = ", ".join(self.options) or "none"
            raise JaxcncError(f"{path}: {self.name} input takes no option {', '.join(unknown)} (it takes: {takes})")

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.name!r}>"


def _as_front_end(obj: Any) -> FrontEnd:
    if isinstance(obj, FrontEnd):
        return obj
    if isinstance(obj, type) and issubclass(obj, FrontEnd):
        return obj()
    raise TypeError(f"{obj!r} is not a FrontEnd (subclass jaxcnc.front_ends.FrontEnd and implement load())")


#: Front ends by file suffix, without the dot (entry-point group ``jaxcnc.front_ends``).
FRONT_ENDS: Registry[FrontEnd] = Registry("input type", "jaxcnc.front_ends", adapt=_as_front_end)


class GCodeFrontEnd(FrontEnd):
    """G-code in the LinuxCNC, Siemens or Fanuc dialect (:mod:`jaxcnc.gcode`)."""

    name = "G-code"
    produces = "program"
    options = ("dialect",)

    def load(self, path: Path, machine: MachineConfig, **options: Any) -> Program:
        from jaxcnc.gcode import load_gcode
        from jaxcnc.program import program_start

        self.refuse_options(path, options)
        start = program_start(machine)
        external = machine.galvo is not None and machine.galvo.stage  # M170/M171: stage + galvo (docs/scanner.md)
        return load_gcode(
            path,
            start=start,
            home=start,
            dialect=options.get("dialect"),
            external=external,
            tools=machine.tool_offsets(),
        )


class PointFileFrontEnd(FrontEnd):
    """Point files for pulsed engraving: one ``x y z [energy]`` per line (:mod:`jaxcnc.io.points`)."""

    name = "point file"
    produces = "points"

    def load(self, path: Path, machine: MachineConfig, **options: Any) -> PointJob:
        from jaxcnc.io.points import read_points

        self.refuse_options(path, options)
        if machine.laser.mode != "pulsed":
            raise JaxcncError(
                f'{path}: point files are burned point by point, which needs [laser] mode = "pulsed" '
                f"(machine {machine.name!r} has mode {machine.laser.mode!r})"
            )
        return read_points(path)


class DxfFrontEnd(FrontEnd):
    """DXF drawings (:mod:`jaxcnc.io.dxf`): contours chained, checked closed and non-crossing, cut inner first.

    Options (:class:`~jaxcnc.io.drawing.DrawingOptions`): ``allow_open``, ``tol_mm``, ``feed_mm_s`` (default:
    the machine's ``[path] feed``), ``power``, ``lead_in_mm``, ``layers``.
    """

    name = "DXF drawing"
    produces = "program"
    options = ("allow_open", "tol_mm", "feed_mm_s", "power", "lead_in_mm", "layers")

    def load(self, path: Path, machine: MachineConfig, **options: Any) -> Program:
        return self.drawing(path, machine, **options).program

    def drawing(self, path: Path, machine: MachineConfig, **options: Any):
        """The :class:`~jaxcnc.io.drawing.Drawing` (Program, contours, notes); a bad option value is a
        one-line error naming it."""
        from jaxcnc.io.drawing import DrawingOptions
        from jaxcnc.program import program_start

        self.refuse_options(path, options)
        try:
            opts = DrawingOptions(**{k: v for k, v in options.items() if v is not None})
        except ValueError as exc:
            raise JaxcncError(f"{path}: {exc}") from None
        return self.read(path, program_start(machine), opts)

    @staticmethod
    def read(path: Path, start_mm, options):
        """The drawing in ``path`` read with ``options`` (:func:`jaxcnc.io.dxf.read_dxf`)."""
        from jaxcnc.io.dxf import read_dxf

        return read_dxf(path, start_mm, options)


class HpglFrontEnd(DxfFrontEnd):
    """HP-GL plot files (:mod:`jaxcnc.io.hpgl`): IN, SP, PU, PD, PA, PR in plotter units (40 per mm); the
    contours checked and cut like a DXF drawing's (same options but ``layers``)."""

    name = "HP-GL plot file"
    options = ("allow_open", "tol_mm", "feed_mm_s", "power", "lead_in_mm")

    @staticmethod
    def read(path: Path, start_mm, options):
        """The plot in ``path`` read with ``options`` (:func:`jaxcnc.io.hpgl.read_hpgl`)."""
        from jaxcnc.io.hpgl import read_hpgl

        return read_hpgl(path, start_mm, options)


class ImageFrontEnd(FrontEnd):
    """Raster images, PNG/BMP/TIFF through Pillow (:mod:`jaxcnc.io.image`): engraved line by line at constant speed
    with overscan, each tick's power read from the image. Options: :class:`~jaxcnc.io.image.RasterOptions`."""

    name = "raster image"
    produces = "program"
    options = (
        "pixel_mm",
        "dpi",
        "width_mm",
        "feed_mm_s",
        "power",
        "power_min",
        "dither",
        "threshold",
        "unidirectional",
        "angle_deg",
        "overscan_mm",
        "bidir_offset_mm",
    )

    def load(self, path: Path, machine: MachineConfig, **options: Any) -> Program:
        return self.raster(path, machine, **options).program

    def raster(self, path: Path, machine: MachineConfig, **options: Any):
        """The :class:`~jaxcnc.io.image.Raster` (Program with its image map, scan lines)."""
        from jaxcnc.io.image import raster_job, raster_options

        self.refuse_options(path, options)
        return raster_job(path, machine, raster_options(path, options))


IMAGE_SUFFIXES = (".png", ".bmp", ".tif", ".tiff")
GCODE_SUFFIXES = (".ngc", ".nc", ".gcode", ".tap", ".g", ".cnc")
POINT_SUFFIXES = (".xyz", ".csv")
DRAWING_SUFFIXES = (".dxf", ".plt", ".hpgl")
FRONT_ENDS.register("dxf", DxfFrontEnd)
FRONT_ENDS.register("plt", HpglFrontEnd)
FRONT_ENDS.register("hpgl", HpglFrontEnd)
for _suffix in IMAGE_SUFFIXES:
    FRONT_ENDS.register(_suffix[1:], ImageFrontEnd)
for _suffix in GCODE_SUFFIXES:
    FRONT_ENDS.register(_suffix[1:], GCodeFrontEnd)
for _suffix in POINT_SUFFIXES:
    FRONT_ENDS.register(_suffix[1:], PointFileFrontEnd)


#: Inputs another command reads, by suffix: what to do instead.
ELSEWHERE = {
    s: "a mesh is built layer by layer for powder-bed fusion: jaxcnc build MESH --machine PBF.toml -o FOLDER"
    for s in ("stl", "3mf", "obj", "ply", "off")
}


def front_end_for(path: str | Path) -> FrontEnd:
    """The front end that reads ``path``, by its suffix; an error naming the file and the known suffixes."""
    path = Path(path)
    suffix = path.suffix.lower().lstrip(".")
    if suffix in ELSEWHERE:
        raise JaxcncError(f"{path}: {ELSEWHERE[suffix]}")
    if not suffix or suffix not in FRONT_ENDS:
        known = ", ".join("." + s for s in FRONT_ENDS.names())
        raise JaxcncError(f"{path}: unknown input type {path.suffix or '(no suffix)'!r}; jaxcnc reads {known}")
    return FRONT_ENDS.get(suffix)


def load_input(path: str | Path, machine: MachineConfig, **options: Any) -> Program | PointJob:
    """Read ``path`` with its front end (options such as ``dialect`` passed on; unknown ones refused)."""
    path = Path(path)
    return front_end_for(path).load(path, machine, **options)


__all__ = [
    "FRONT_ENDS",
    "DRAWING_SUFFIXES",
    "GCODE_SUFFIXES",
    "POINT_SUFFIXES",
    "DxfFrontEnd",
    "FrontEnd",
    "HpglFrontEnd",
    "IMAGE_SUFFIXES",
    "ImageFrontEnd",
    "GCodeFrontEnd",
    "PointFileFrontEnd",
    "front_end_for",
    "load_input",
]
