"""Powder-bed fusion from a mesh, layer by layer (docs/pbf.md; the source documents' preprocessor, SEEDS §3).

One concept per module:

- :mod:`jaxcnc.pbf.params` — the build-parameters file (``[pbf]`` TOML; unknown keys are errors);
- :mod:`jaxcnc.pbf.mesh` — intake with trimesh: vertex merge within a tolerance, defect report, repair, placement;
- :mod:`jaxcnc.pbf.slice` — slicing vectorised over triangles and layers, loops assembled without a Python loop
  per segment;
- :mod:`jaxcnc.pbf.contours` — Clipper (pyclipper) unions, offsets ("equidistants"), boolean zone algebra;
- :mod:`jaxcnc.pbf.zones` — special zones: thin walls (offset in, offset out), down-skin and up-skin;
- :mod:`jaxcnc.pbf.hatch` — scanline hatching (lines, meander, stripes, chessboard islands), angle per layer;
- :mod:`jaxcnc.pbf.order` — scan ordering and the per-layer vector list (marks and jumps);
- :mod:`jaxcnc.pbf.layer` — one layer from its loops to its vector list;
- :mod:`jaxcnc.pbf.cli_format` — Common Layer Interface export and reader (ASCII and binary);
- :mod:`jaxcnc.pbf.build` — the build driver: one file per layer, a manifest with checksums, resumable;
- :mod:`jaxcnc.pbf.distributed` — the same build on dask.distributed;
- :mod:`jaxcnc.pbf.picture` — layer pictures, contours and hatches coloured by zone;
- :mod:`jaxcnc.pbf.scanlist` — a layer as a galvo board list (issue 18's format) and as a planned tick table;
- :mod:`jaxcnc.pbf.selfint` — self-intersections: loops of one cut that cross themselves or each other.
"""

from __future__ import annotations

from jaxcnc.errors import JaxcncError


class MeshError(JaxcncError):
    """A mesh that cannot be built: unreadable, or with defects that were not repaired (names file and defect)."""


class CLIFileError(JaxcncError):
    """A Common Layer Interface file that is damaged or not a CLI file (names file, place and cause)."""


class BuildError(JaxcncError):
    """A build folder that cannot be used (another part's manifest, unwritable, ...)."""
