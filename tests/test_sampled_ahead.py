"""The tick stage's chunks made on a worker thread ahead of the writer (:func:`jaxcnc.ticks.sample.sampled_ahead`)."""

from __future__ import annotations

import threading
import time

import pytest

from jaxcnc.ticks.sample import sampled_ahead


def test_items_in_order() -> None:
    assert list(sampled_ahead(iter(range(1000)), depth=2)) == list(range(1000))
    assert list(sampled_ahead(iter([]))) == []


def test_runs_at_most_depth_ahead() -> None:
    made: list[int] = []

    def chunks():
        for i in range(50):
            made.append(i)
            yield i

    it = sampled_ahead(chunks(), depth=2)
    assert next(it) == 0
    time.sleep(0.2)  # the worker fills the queue and waits
    assert len(made) <= 1 + 2 + 1  # the one taken, the queue's two, the one it waits to put
    assert list(it) == list(range(1, 50))


def test_error_raised_in_its_place() -> None:
    def chunks():
        yield 1
        yield 2
        raise ValueError("chunk 3 failed")

    got = []
    with pytest.raises(ValueError, match="chunk 3 failed"):
        for item in sampled_ahead(chunks()):
            got.append(item)
    assert got == [1, 2]


def test_caller_stopping_early_stops_the_worker() -> None:
    before = threading.active_count()

    def chunks():
        i = 0
        while True:  # endless: only the stop ends it
            yield i
            i += 1

    it = sampled_ahead(chunks(), depth=2)
    assert [next(it) for _ in range(5)] == [0, 1, 2, 3, 4]
    it.close()  # the caller's loop broke off (an error in the writer, Ctrl-C)
    assert threading.active_count() == before
