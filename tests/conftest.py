"""Fixtures shared by several test modules: the office's PostgreSQL cluster is made once per
test run (tests/office_rig.py)."""

from office_rig import office_cluster, office_db

__all__ = ["office_cluster", "office_db"]
