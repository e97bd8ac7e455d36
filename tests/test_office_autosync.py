"""The cab's own sync to the office: a session sent while it is recorded, in a thread of its
own, and a cab that goes on when the office is down."""

from __future__ import annotations

import time
from pathlib import Path

import psycopg

from office_rig import FARM, config, fill, needs_postgres
from topdress.config import OfficeConfig
from topdress.log.session import SessionLog
from topdress.office.autosync import OfficeSync

pytestmark = needs_postgres


def _office_rows(db: str) -> tuple[int, bool] | None:
    with psycopg.connect(db) as conn:
        row = conn.execute("SELECT state_rows, closed FROM session").fetchone()
    return None if row is None else (int(row[0]), bool(row[1]))


def _wait(db: str, want: tuple[int, bool], timeout_s: float = 20.0) -> None:
    end = time.monotonic() + timeout_s
    while _office_rows(db) != want:
        assert time.monotonic() < end, _office_rows(db)
        time.sleep(0.05)


def test_cab_sends_a_growing_session_by_itself(office_db: str, tmp_path: Path) -> None:
    office = OfficeSync(OfficeConfig(url=office_db, farm=FARM), tmp_path, interval_s=0.05)
    log = SessionLog.create(tmp_path, config("m1"), name="live")
    office.start()
    try:
        fill(log, 0.0, 10.0)
        assert log.sync()
        _wait(office_db, (100, False))
        fill(log, 0.0, 5.0, start=100)
        log.close()
        _wait(office_db, (150, True))
    finally:
        office.stop()
    assert office.state.last_error is None and office.state.sent_rows == 150
    assert not office._thread.is_alive()


def test_cab_goes_on_with_the_office_down(tmp_path: Path) -> None:
    told: list[str] = []
    down = f"host={tmp_path / 'nowhere'} dbname=x user=topdress connect_timeout=1"
    office = OfficeSync(OfficeConfig(url=down), tmp_path, interval_s=60, on_message=told.append)
    with SessionLog.create(tmp_path, config("m1"), name="live") as log:
        fill(log, 0.0, 2.0)
        office.round()  # never raises
        office.round()
        assert log.sync() and log.ok
    assert office.state.rounds == 2
    assert "cannot reach the office database" in (office.state.last_error or "")
    assert len(told) == 1  # said once, not every round
