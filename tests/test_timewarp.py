"""Feed hold, resume and override by time warp: on the path, within limits, exact at the end."""

from __future__ import annotations

import numpy as np
import pytest

from jaxcnc.hw.timewarp import TimeWarp, hold_distance
from tests.conftest import make_machine
from tests.helpers import table_of

A_MAX = np.array([1000.0, 1000.0, 500.0])


@pytest.fixture(scope="module")
def planned(tmp_path_factory):
    return table_of("G1 X150 F6000\nG3 X150 Y0 I-20 J0\n", make_machine(v=200, a=1000), tmp_path_factory.mktemp("w"))


def _play(table, script: dict[int, float], chunk: int = 1000) -> np.ndarray:
    tw = TimeWarp(table, A_MAX)
    out, k = [], 0
    while not tw.done:
        for at, rate in script.items():
            if k <= at < k + chunk:
                out.append(tw.positions(at - k))
                k = at
                tw.command(rate)
        p = tw.positions(chunk)
        out.append(p)
        k += len(p)
    return np.concatenate(out)


def test_hold_at_full_speed_and_resume(planned):
    job, table, _ = planned
    f = table.header.tick_hz
    p = _play(table, {8000: 0.0, 12000: 1.0})  # hold while cruising at 100 mm/s along X, resume later
    v = np.diff(p, axis=0) * f
    a = np.diff(p, 2, axis=0) * f**2
    assert np.all(np.abs(a).max(axis=0) <= A_MAX * (1 + 1e-9))  # accelerations within the limits
    assert np.all(np.abs(v).max(axis=0) <= 100.0 + 1e-6)
    # the hold stops on the original path (the straight line y = 0) within a discrete, and stands still
    held = slice(8000, 12000)
    np.testing.assert_allclose(p[held, 1:], 0.0, atol=1e-3)
    speed = np.linalg.norm(v, axis=1)
    stop = 8000 + int(np.argmax(speed[8000:] < 1e-9))
    assert stop < 12000 and np.all(speed[stop:11999] < 1e-9)  # still until the resume (at row 12000)
    travelled = np.linalg.norm(p[stop] - p[8000])
    predicted = hold_distance(v[7999], A_MAX)
    assert travelled == pytest.approx(predicted, rel=0.01)
    # the job finishes at the same final position, later than planned
    np.testing.assert_allclose(p[-1], table.exact_mm(table.n_rows - 1)[0], atol=1e-12)
    assert len(p) > table.n_rows


def test_override_halves_the_feed(planned):
    job, table, _ = planned
    p = _play(table, {0: 0.5})
    speed = np.linalg.norm(np.diff(p, axis=0), axis=1) * table.header.tick_hz
    assert speed.max() == pytest.approx(50.0, rel=1e-6)
    assert len(p) == pytest.approx(2 * table.n_rows, rel=0.01)


def test_rate_is_checked(planned):
    with pytest.raises(ValueError):
        TimeWarp(planned[1], A_MAX).command(1.5)
