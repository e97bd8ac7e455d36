"""Fixtures shared by several test modules: the office's PostgreSQL cluster is made once per
test run (tests/office_rig.py). The modules that drive a browser, QEMU or real-time processes
run first, so the workers of `make test` start on the long tests and end on short ones."""

import pytest

from office_rig import office_cluster, office_db

__all__ = ["office_cluster", "office_db"]

SLOW_MARKS = ("browser", "qemu", "wallclock")


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Whole modules moved, each in its own order (its module fixtures stay set up once)."""
    slow = {
        item.module.__name__
        for item in items
        if isinstance(item, pytest.Function) and any(item.get_closest_marker(m) for m in SLOW_MARKS)
    }
    items.sort(key=lambda item: 0 if getattr(item.module, "__name__", "") in slow else 1)
