"""Session log: contents, schema, loss accounting, unwritable path, full disk."""

from __future__ import annotations

import sqlite3
import threading
import time
from pathlib import Path

import can
import pytest

from topdress.cli.main import main
from topdress.errors import LogError
from topdress.log.model import StateRow
from topdress.log.session import SCHEMA_VERSION, SessionLog, SessionReader

CONFIG = '[machine]\nworking_width_m = 3.6\n[log]\ndirectory = "x"\n'
RMC = "$GPRMC,123519,A,4807.038,N,01131.000,E,3.78,084.4,230394,003.1,W*6E"


def state_row(t: float, v: float = 5.0) -> StateRow:
    return StateRow(
        t=t,
        lat=45.75,
        lon=126.63,
        v_gnss_kmh=v,
        v_wheel_kmh=v - 0.1,
        v_kmh=v,
        source="gnss",
        cv_pct=1.25,
        ndvi=0.83,
        rate_kg_ha_upper=150.0,
        rate_kg_ha_lower=120.0,
        target_rpm_upper=1.5,
        target_rpm_lower=1.2,
        meter_rpm_upper=1.49,
        meter_rpm_lower=1.21,
        fan_rpm_upper=3000.0,
        fan_rpm_lower=2980.0,
        faults=0x02,
    )


def test_every_input_and_state_is_stored_in_order(tmp_path: Path) -> None:
    with SessionLog.create(tmp_path, CONFIG) as log:
        log.raw("nmea", 10.0, RMC)
        log.raw("crop", 10.01, "2,0.0412,0.2104,0.4419,0.3541,0.8295")
        log.raw("can_rx", 10.02, (0x185C6465, bytes([0x0A, 0xF4, 0x01, 0, 0, 150, 149, 50])))
        log.raw("can_tx", 10.03, (0x0A5C6465, b"\x0a\xb8\x0b\x98\x3a\x00\x00\x37"))
        log.state(state_row(10.05))
        assert log.ok
    assert log.errors == 0 and log.dropped == 0 and log.lost == 0
    with SessionReader(log.path) as reader:
        raw = list(reader.raw())
        assert [r.kind for r in raw] == ["nmea", "crop", "can_rx", "can_tx"]
        assert raw[0].line == RMC and raw[0].t == 10.0
        assert raw[1].line == "2,0.0412,0.2104,0.4419,0.3541,0.8295"
        assert raw[2].can_id == 0x185C6465 and raw[2].data == bytes(
            [10, 244, 1, 0, 0, 150, 149, 50]
        )
        assert raw[3].can_id == 0x0A5C6465 and raw[3].line is None
        assert list(reader.states()) == [state_row(10.05)]
        assert reader.config_toml == CONFIG
        assert reader.meta["dropped"] == "0" and reader.meta["errors"] == "0"


def test_file_is_wal_versioned_and_one_per_session(tmp_path: Path) -> None:
    a = SessionLog.create(tmp_path, CONFIG, name="field7")
    b = SessionLog.create(tmp_path, CONFIG, name="field7")
    assert a.path != b.path and a.path.name == "field7.sqlite" and b.path.name == "field7-1.sqlite"
    a.close()
    b.close()
    conn = sqlite3.connect(a.path)
    assert conn.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    assert conn.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION
    conn.execute("PRAGMA user_version = 99")
    conn.close()
    with pytest.raises(LogError, match="schema 99"):
        SessionReader(a.path)


def test_commits_within_the_period_without_close(tmp_path: Path) -> None:
    log = SessionLog.create(tmp_path, CONFIG, commit_period_s=0.1)
    log.raw("nmea", 1.0, RMC)
    conn = sqlite3.connect(log.path)
    # Another process sees the row once the writer committed; poll, never assert a duration.
    for _ in range(200):
        if conn.execute("SELECT count(*) FROM raw").fetchone()[0] == 1:
            break
        time.sleep(0.01)
    assert conn.execute("SELECT line FROM raw").fetchone()[0] == RMC
    conn.close()
    log.close()


def test_unwritable_path_is_reported_not_raised(tmp_path: Path) -> None:
    blocker = tmp_path / "not-a-dir"
    blocker.write_text("x")
    log = SessionLog.create(blocker / "logs", CONFIG)
    assert not log.ok
    assert log.errors == 1
    assert log.last_error is not None and "Not a directory" in log.last_error
    log.raw("nmea", 1.0, RMC)
    log.state(state_row(1.0))
    assert log.dropped == 2
    assert not log.sync()
    log.close()


def test_can_message_payload_is_taken(tmp_path: Path) -> None:
    msg = can.Message(arbitration_id=0x0A5C6465, data=bytes.fromhex("0ab80b983a000037"))
    with SessionLog.create(tmp_path, CONFIG) as log:
        log.raw("can_tx", 2.0, msg)
    with SessionReader(log.path) as reader:
        (rec,) = reader.raw()
    assert (rec.kind, rec.can_id, rec.data) == ("can_tx", 0x0A5C6465, bytes(msg.data))


def test_bad_kind_is_counted_and_not_raised(tmp_path: Path) -> None:
    with SessionLog.create(tmp_path, CONFIG) as log:
        log.raw("gps", 1.0, RMC)
        log.raw("nmea", 1.0, (1, b"\x00"))
        log.raw("can_rx", 1.0, "00")
        log.raw("can_rx", 1.0, ("0x185C6465", b"\x00"))
        log.raw("can_tx", 1.0, (1, 2, 3))
        log.raw("nmea", 1.1, RMC)
    assert log.dropped == 5 and log.errors == 5
    with SessionReader(log.path) as reader:
        assert reader.count("raw") == 1


def test_full_disk_is_counted_and_the_file_stays_sound(tmp_path: Path) -> None:
    log = SessionLog.create(tmp_path, CONFIG, max_bytes=64 * 1024, commit_period_s=0.05)
    total = 3000
    line = RMC + "," * 150
    for i in range(total):
        log.raw("nmea", float(i), line)  # never raises, never blocks
        if i % 100 == 0:
            log.sync()
    log.sync()
    assert log.errors > 0 and log.lost > 0
    assert log.last_error is not None and "full" in log.last_error
    assert not log.ok
    log.close()
    with SessionReader(log.path) as reader:
        written = reader.count("raw")
    assert 0 < written < total
    assert written + log.lost + log.dropped == total
    conn = sqlite3.connect(log.path)
    assert conn.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
    conn.close()


def test_full_queue_drops_and_counts_instead_of_blocking(tmp_path: Path) -> None:
    log = SessionLog.create(tmp_path, CONFIG, queue_size=10, commit_period_s=0.01)
    # Another connection holds the write lock: the writer's commit waits on it.
    blocker = sqlite3.connect(log.path, isolation_level=None)
    blocker.execute("BEGIN IMMEDIATE")
    log.raw("nmea", 0.0, RMC)
    time.sleep(0.1)  # let the writer pick the row up and block in its commit
    for i in range(1, 200):
        log.raw("nmea", float(i), RMC)
    assert log.dropped >= 150
    blocker.execute("COMMIT")
    blocker.close()
    log.close()
    with SessionReader(log.path) as reader:
        written = reader.count("raw")
    assert written + log.dropped + log.lost == 200


def test_reader_rejects_missing_and_foreign_files(tmp_path: Path) -> None:
    with pytest.raises(LogError, match="no such session"):
        SessionReader(tmp_path / "nothing.sqlite")
    junk = tmp_path / "junk.sqlite"
    junk.write_bytes(b"this is not a database" * 100)
    with pytest.raises(LogError, match="not a readable session log"):
        SessionReader(junk)
    with pytest.raises(LogError, match="not a file"):
        SessionReader(tmp_path)
    # an empty file and another program's database are valid SQLite, but no session
    empty = tmp_path / "empty.sqlite"
    empty.write_bytes(b"")
    other = tmp_path / "other.sqlite"
    with sqlite3.connect(other) as conn:
        conn.execute("CREATE TABLE t (x)")
    conn.close()
    for path in (empty, other):
        with pytest.raises(LogError, match="not a topdress session log"):
            SessionReader(path)


def test_damaged_page_is_a_clear_error_when_read(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with SessionLog.create(tmp_path, CONFIG) as log:
        for i in range(3000):
            log.state(state_row(float(i) / 10))
    data = bytearray(log.path.read_bytes())
    page = 4096
    assert len(data) > 20 * page
    # a worn SD card: pages in the middle of the state table turn to noise
    noise = bytes((i * 151 + 17) % 256 for i in range(4 * page))
    data[10 * page : 14 * page] = noise
    log.path.write_bytes(bytes(data))
    with SessionReader(log.path) as reader, pytest.raises(LogError, match="damaged session log"):
        list(reader.states())
    assert main(["log", "summary", str(log.path)]) == 2
    assert f"topdress log salvage {log.path} --out" in capsys.readouterr().err


def test_sessions_created_at_once_in_one_directory_each_get_their_own_file(
    tmp_path: Path,
) -> None:
    # The name was checked, then created: a second terminal took it in between and one
    # session's rows went into the other's file. 40 at once, same name, one directory.
    barrier = threading.Barrier(40)
    logs: list[SessionLog] = []
    lock = threading.Lock()

    def make(k: int) -> None:
        barrier.wait()
        log = SessionLog.create(tmp_path, f"# terminal {k}\n", name="field")
        with lock:
            logs.append(log)

    threads = [threading.Thread(target=make, args=(k,)) for k in range(40)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    for log in logs:
        log.close()
    assert all(log.errors == 0 for log in logs)
    assert len({log.path for log in logs}) == 40
    configs = {SessionReader(log.path).config_toml for log in logs}
    assert configs == {f"# terminal {k}\n" for k in range(40)}  # no file written twice


def test_a_file_that_cannot_get_its_schema_is_not_left_behind(tmp_path: Path) -> None:
    # A disk full at start left a 0-byte .sqlite that later looked like a damaged session.
    log = SessionLog.create(tmp_path, "# cfg\n", max_bytes=1)  # 1 page: the schema cannot fit
    assert not log.ok and log.errors == 1
    assert log.last_error is not None and "full" in log.last_error
    log.close()
    assert list(tmp_path.iterdir()) == []


def test_a_name_with_a_left_over_wal_is_not_taken(tmp_path: Path) -> None:
    # session.sqlite deleted by hand, its -wal left: SQLite would replay that WAL into a new
    # file of the same name and mix an old session into the new one.
    (tmp_path / "field.sqlite-wal").write_bytes(b"old wal")
    log = SessionLog.create(tmp_path, "# new\n", name="field")
    log.close()
    assert log.path.name == "field-1.sqlite" and log.errors == 0
    assert (tmp_path / "field.sqlite-wal").read_bytes() == b"old wal"
