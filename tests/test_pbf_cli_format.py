"""Common Layer Interface files: ASCII and binary written as the format says, read back, hostile bytes refused."""

from __future__ import annotations

import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxcnc.pbf import CLIFileError
from jaxcnc.pbf.cli_format import CLIData, CLILayer, HatchBlock, Polyline, decode, encode, zone_labels

SQUARE = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0], [0.0, 0.0]])


def _data(binary: bool, units: float = 1.0) -> CLIData:
    hatches = np.array([[[0.0, 0.5], [2.0, 0.5]], [[2.0, 1.5], [0.0, 1.5]]])
    layers = [CLILayer(0.03, [HatchBlock(1, hatches), Polyline(2, 1, SQUARE)]), CLILayer(0.06, [])]
    return CLIData(units, binary, zone_labels(), (0.0, 0.0, 0.0, 2.0, 2.0, 0.06), layers)


def test_binary_layout_byte_by_byte():
    raw = encode(_data(True, units=0.001))
    head, _, body = raw.partition(b"$$HEADEREND")
    assert head.decode().splitlines()[:4] == ["$$HEADERSTART", "$$BINARY", "$$UNITS/0.001000", "$$VERSION/200"]
    assert b"$$LABEL/1,core\n" in head and b"$$LAYERS/000002\n" in head
    cmd, z = struct.unpack_from("<Hf", body, 0)
    assert (cmd, z) == (127, pytest.approx(30.0))
    cmd, ident, n = struct.unpack_from("<Hii", body, 6)
    assert (cmd, ident, n) == (132, 1, 2)
    xy = np.frombuffer(body, "<f4", 8, 16)
    assert xy.tolist() == [0.0, 500.0, 2000.0, 500.0, 2000.0, 1500.0, 0.0, 1500.0]
    cmd, ident, d, n = struct.unpack_from("<Hiii", body, 48)
    assert (cmd, ident, d, n) == (130, 2, 1, 5)
    assert len(body) == 48 + 14 + 5 * 8 + 6


def test_ascii_layout():
    text = encode(_data(False)).decode()
    lines = text.splitlines()
    assert lines[0] == "$$HEADERSTART" and lines[1] == "$$ASCII" and "$$HEADEREND" in lines
    assert "$$LAYER/0.030000" in lines
    assert "$$HATCHES/1,2,0.000000,0.500000,2.000000,0.500000,2.000000,1.500000,0.000000,1.500000" in lines
    assert lines[-1] == "$$GEOMETRYEND"


@pytest.mark.parametrize("binary", [False, True])
def test_round_trip(binary):
    back = decode(encode(_data(binary)))
    assert back.binary == binary and back.labels == zone_labels() and len(back.layers) == 2
    h, p = back.layers[0].blocks
    np.testing.assert_allclose(h.segments_mm, _data(binary).layers[0].blocks[0].segments_mm, atol=1e-6)
    np.testing.assert_allclose(p.points_mm, SQUARE, atol=1e-6)
    assert p.dir == 1 and back.layers[1].z_mm == pytest.approx(0.06)


coords = st.floats(-500, 500, allow_nan=False, width=32)


@settings(max_examples=60, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.floats(0, 300, allow_nan=False, width=32),
            st.lists(st.lists(coords, min_size=4, max_size=4), max_size=5),
            st.lists(st.lists(coords, min_size=2, max_size=2), min_size=2, max_size=6),
        ),
        max_size=4,
    ),
    st.booleans(),
)
def test_round_trip_any_geometry(layers, binary):
    data = CLIData(1.0, binary, zone_labels())
    for z, hatches, poly in layers:
        blocks = []
        if hatches:
            blocks.append(HatchBlock(1, np.array(hatches, dtype=np.float64).reshape(-1, 2, 2)))
        blocks.append(Polyline(2, 2, np.array(poly, dtype=np.float64)))
        data.layers.append(CLILayer(z, blocks))
    back = decode(encode(data))
    assert len(back.layers) == len(data.layers)
    for a, b in zip(data.layers, back.layers, strict=True):
        assert b.z_mm == pytest.approx(a.z_mm, abs=1e-5)
        for x, y in zip(a.blocks, b.blocks, strict=True):
            got = y.segments_mm if isinstance(y, HatchBlock) else y.points_mm
            want = x.segments_mm if isinstance(x, HatchBlock) else x.points_mm
            np.testing.assert_allclose(got, want, atol=1e-4)


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=300), st.booleans())
def test_hostile_geometry_is_refused_in_one_line(tail, binary):
    head = encode(CLIData(1.0, binary)).split(b"$$HEADEREND")[0] + b"$$HEADEREND"
    try:
        decode(head + tail, "fuzz.cli")
    except CLIFileError as exc:
        assert str(exc).startswith("fuzz.cli") and "\n" not in str(exc)


@pytest.mark.parametrize(
    "raw, what",
    [
        (b"hello", "no $$HEADERSTART"),
        (b"$$HEADERSTART\n$$ASCII\n", "does not end"),
        (b"$$HEADERSTART\n$$UNITS/1\n$$HEADEREND", "neither $$ASCII nor $$BINARY"),
        (b"$$HEADERSTART\n$$BINARY\n$$HEADEREND\x7f\x00\x00", "x.cli: byte 36: truncated (needs 4 more bytes)"),
        (
            b"$$HEADERSTART\n$$ASCII\n$$HEADEREND\n$$GEOMETRYSTART\n$$HATCHES/1,1,0,0\n",
            ":5: $$HATCHES before any $$LAYER",
        ),
        (b"$$HEADERSTART\n$$ASCII\n$$HEADEREND\n$$LAYER/1\n$$HATCHES/1,2,0,0,1,1\n", ":5: 2 hatches have 4 numbers"),
    ],
)
def test_damaged_files_named(raw, what):
    with pytest.raises(CLIFileError) as err:
        decode(raw, "x.cli")
    assert str(err.value).startswith("x.cli") and what in str(err.value)
