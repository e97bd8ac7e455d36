"""A throwaway PostgreSQL + PostGIS cluster for the office tests (one per test run, removed
after), a fresh database from an initialised template for each test, sessions of machines
driving side by side, and a TCP proxy that cuts the link where it is told."""

from __future__ import annotations

import contextlib
import itertools
import math
import shutil
import socket
import tempfile
import threading
from collections.abc import Iterator
from pathlib import Path

import psycopg
import pytest

from topdress.errors import OfficeError
from topdress.log.model import LogEvent, StateRow
from topdress.log.session import SessionLog
from topdress.office import schema
from topdress.office.cluster import SUPERUSER, Cluster, pg_bindir

LAT0, LON0 = 43.8853, 125.3245
UTC0 = 1_780_000_000.0  # 2026-05-28
FARM = "Test Farm"
M_PER_DEG_LAT = 111_320.0
_dbs = itertools.count()


def missing_postgres() -> str | None:
    try:
        bindir = pg_bindir()
    except OfficeError as exc:
        return str(exc)
    major = bindir.parent.name
    if not Path(f"/usr/share/postgresql/{major}/extension/postgis.control").exists():
        return f"PostGIS for PostgreSQL {major} is not installed (make office)"
    return None


needs_postgres = pytest.mark.skipif(missing_postgres() is not None, reason=str(missing_postgres()))


@pytest.fixture(scope="session")
def office_cluster() -> Iterator[Cluster]:
    # Not under pytest's tmp_path: when root runs the tests, the server runs as another user,
    # who must be able to enter every parent of the directory.
    data = Path(tempfile.mkdtemp(prefix="topdress-office-test-"))
    cluster = Cluster(data)
    cluster.start()
    with psycopg.connect(cluster.conninfo) as conn:
        schema.init(conn, FARM)
    try:
        yield cluster
    finally:
        cluster.stop()
        shutil.rmtree(data, ignore_errors=True)


def conninfo_of(cluster: Cluster, db: str) -> str:
    return f"host={cluster.socket_dir} dbname={db} user={SUPERUSER}"


@pytest.fixture
def office_db(office_cluster: Cluster) -> Iterator[str]:
    """A fresh, initialised office database of farm FARM: its connection string."""
    name = f"t{next(_dbs)}"
    admin = conninfo_of(office_cluster, "postgres")
    with psycopg.connect(admin, autocommit=True) as conn:
        conn.execute(f"CREATE DATABASE {name} TEMPLATE topdress")
    try:
        yield conninfo_of(office_cluster, name)
    finally:
        with psycopg.connect(admin, autocommit=True) as conn:
            conn.execute(f"DROP DATABASE {name} WITH (FORCE)")


def latlon(east_m: float, north_m: float) -> tuple[float, float]:
    lat = LAT0 + north_m / M_PER_DEG_LAT
    return lat, LON0 + east_m / (M_PER_DEG_LAT * math.cos(math.radians(LAT0)))


def config(machine: str, farm: str = FARM) -> str:
    return f'[machine]\nwidth_m = 3.6\n\n[office]\nmachine = "{machine}"\nfarm = "{farm}"\n'


def fill(log: SessionLog, north_m: float, seconds: float, start: int = 0, v_kmh: float = 8.0):
    """`seconds` of driving east at `north_m`, metering 150 + 120 kg/ha (from row `start`)."""
    v = v_kmh / 3.6
    if start == 0:
        log.event(LogEvent(100.0, "operator.start", {"was": "stopped"}))
    for i in range(start, start + round(seconds * 10)):
        lat, lon = latlon(v * i * 0.1, north_m)
        log.state(
            StateRow(
                100.0 + i * 0.1, lat, lon, v_kmh, v_kmh, v_kmh, "gnss", 1.2, 0.8, 150.0, 120.0,
                20.0 * v_kmh / 8.0, 16.0 * v_kmh / 8.0, 20.0 * v_kmh / 8.0, 16.0 * v_kmh / 8.0,
                3000.0, 3000.0, 0, utc=UTC0 + i * 0.1, utc_source="gnss", heading_deg=90.0,
                outlet_lat=lat, outlet_lon=lon, zone=None, prescription_kg_ha=None,
            )
        )  # fmt: skip


def session(
    directory: Path, machine: str, north_m: float = 0.0, seconds: float = 60.0, farm: str = FARM
) -> Path:
    with SessionLog.create(directory, config(machine, farm), name=machine) as log:
        fill(log, north_m, seconds)
    return log.path


class CuttingProxy:
    """127.0.0.1:port -> the cluster's socket; `cut_after(n)` closes every link once n more
    bytes went through it (both ways), at whatever point of the protocol that is."""

    def __init__(self, cluster: Cluster) -> None:
        self.target = str(cluster.socket_dir / ".s.PGSQL.5432")
        self.listener = socket.create_server(("127.0.0.1", 0))
        self.port = self.listener.getsockname()[1]
        self.budget: int | None = None
        self.cuts = 0
        self._lock = threading.Lock()
        self._open: list[socket.socket] = []
        threading.Thread(target=self._accept, daemon=True).start()

    def conninfo(self, db: str) -> str:
        return f"host=127.0.0.1 port={self.port} dbname={db} user={SUPERUSER} sslmode=disable"

    def cut_after(self, n: int | None) -> None:
        with self._lock:
            self.budget = n

    def close(self) -> None:
        self.listener.close()
        self._cut()

    def _accept(self) -> None:
        while True:
            try:
                client, _ = self.listener.accept()
            except OSError:
                return
            server = socket.socket(socket.AF_UNIX)
            server.connect(self.target)
            with self._lock:
                self._open += [client, server]
            for a, b in ((client, server), (server, client)):
                threading.Thread(target=self._pump, args=(a, b), daemon=True).start()

    def _pump(self, src: socket.socket, dst: socket.socket) -> None:
        while True:
            try:
                data = src.recv(65536)
            except OSError:
                return
            if not data:
                self._cut()
                return
            with self._lock:
                if self.budget is not None:
                    if len(data) >= self.budget:
                        data = data[: self.budget]
                        self.budget = None
                        cut = True
                    else:
                        self.budget -= len(data)
                        cut = False
                else:
                    cut = False
            try:
                if data:
                    dst.sendall(data)
            except OSError:
                return
            if cut:
                self.cuts += 1
                self._cut()
                return

    def _cut(self) -> None:
        with self._lock:
            socks, self._open = self._open, []
        for s in socks:
            with contextlib.suppress(OSError):
                s.shutdown(socket.SHUT_RDWR)
            s.close()
