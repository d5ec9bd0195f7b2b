"""Layer pictures: a layer's marks drawn by zone (contours and hatches), jumps left out."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from jaxcnc.pbf.params import ZONES

#: Colour of each zone (core, contour, thin_wall, downskin, upskin).
ZONE_COLOURS = ("#1f77b4", "#000000", "#d62728", "#2ca02c", "#ff7f0e")


def draw_layer(vectors: np.ndarray, title: str):
    """A matplotlib figure of one layer's marks, coloured by zone, with a legend of the zones present."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection

    fig, ax = plt.subplots(figsize=(7, 7), dpi=110)
    marks = vectors[vectors["mark"] == 1]
    for zid, name in enumerate(ZONES):
        v = marks[marks["zone"] == zid]
        if len(v) == 0:
            continue
        seg = np.stack([np.column_stack([v["x0_mm"], v["y0_mm"]]), np.column_stack([v["x1_mm"], v["y1_mm"]])], 1)
        width = 0.9 if name == "contour" else 0.4
        ax.add_collection(LineCollection(seg, colors=ZONE_COLOURS[zid], linewidths=width, label=f"{name} ({len(v)})"))
    ax.autoscale()
    ax.set_aspect("equal")
    ax.set_xlabel("x, mm")
    ax.set_ylabel("y, mm")
    ax.set_title(title)
    if len(marks):
        ax.legend(loc="upper right", fontsize=8)
    return fig


def draw_layers(out: Path, records: list[dict]) -> list[Path]:
    """Draw the layers of ``records`` (manifest records) into ``out/pictures``; returns the files written."""
    import matplotlib.pyplot as plt

    from jaxcnc.pbf.build import atomic_write

    folder = Path(out) / "pictures"
    folder.mkdir(exist_ok=True)
    written = []
    for rec in records:
        vec = np.load(Path(out) / rec["file"], allow_pickle=False)
        title = (
            f"layer {rec['index']}  z = {rec['z_mm']:.3f} mm  hatch {rec['hatch_mm']:.0f} mm  "
            f"est. {rec['time_s']:.1f} s"
        )
        fig = draw_layer(vec, title)
        buf = io.BytesIO()
        fig.savefig(buf, format="png", metadata={"Software": None})
        plt.close(fig)
        path = folder / Path(rec["file"]).with_suffix(".png").name
        atomic_write(path, buf.getvalue())
        written.append(path)
    return written
