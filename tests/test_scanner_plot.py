"""The beam plot (issue 18): commanded vs actual path coloured by the laser's state."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from jaxcnc.format.vectors import Op, VectorHeader, make, records
from jaxcnc.plot.scanner import plot_beam
from jaxcnc.scanner.compile import NO_DELAYS
from jaxcnc.scanner.emulator import emulate
from jaxcnc.scanner.head import HeadModel


def _colour_pixels(img: np.ndarray, hex_colour: str) -> int:
    rgb = np.array([int(hex_colour[i : i + 2], 16) for i in (1, 3, 5)])
    return int((np.abs(img[..., :3].astype(int) - rgb).sum(axis=-1) < 40).sum())


def test_plot_beam_colours_lit_and_dark(tmp_path):
    h = VectorHeader(100000.0, 0.001)
    rec = records(
        [make(Op.LIST_START), make(Op.SET_JUMP_SPEED, value=3000.0), make(Op.SET_MARK_SPEED, value=1000.0),
         make(Op.SET_LASER, value=1.0), *NO_DELAYS.commands(), make(Op.JUMP_ABS, pos=(2000, 0)),
         make(Op.MARK_ABS, pos=(4000, 0)), make(Op.MARK_ABS, pos=(4000, 2000)), make(Op.WAIT, ticks=50),
         make(Op.JUMP_ABS, pos=(0, 0)), make(Op.LIST_END)]
    )  # fmt: skip
    em = emulate(rec, h, HeadModel(150e-6, 1.0, 5e6), load_s=None)
    assert em.power.max() > 0 and (em.power == 0).any()
    path = [np.array([[2.0, 0.0], [4.0, 0.0], [4.0, 2.0]])]
    out = plot_beam(em.commanded, em.actual, em.power, tmp_path / "beam.png", paths=path)
    img = np.asarray(Image.open(out).convert("RGB"))
    assert img.shape[0] > 500 and img.shape[1] > 1000
    assert _colour_pixels(img, "#d62728") > 100 and _colour_pixels(img, "#1f77b4") > 100
    dark = plot_beam(em.commanded, em.actual, np.zeros_like(em.power), tmp_path / "dark.png")
    assert _colour_pixels(np.asarray(Image.open(dark).convert("RGB")), "#d62728") == 0  # nothing lit: no red
    with pytest.raises(ValueError, match="plot_beam"):
        plot_beam(em.commanded, em.actual[:-1], em.power, tmp_path / "bad.png")
