"""A local PostgreSQL cluster for a one-office install: `initdb` and `pg_ctl` run as an
unprivileged user (the server refuses to run as root), the socket in the data directory, no TCP
port, so a farm needs no database administrator and two clusters on one host never collide."""

from __future__ import annotations

import contextlib
import os
import pwd
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path
from typing import Final

from topdress.errors import OfficeError, OfficeUnavailable

DATABASE: Final = "topdress"
SUPERUSER: Final = "topdress"  # the cluster's own superuser name (local trust only)
#: the system users a cluster started by root runs as, the first that exists
SERVICE_USERS: Final = ("postgres", "nobody")


def pg_bindir() -> Path:
    """The newest installed PostgreSQL's programs (Debian keeps them per major version)."""
    found = sorted(
        Path("/usr/lib/postgresql").glob("*/bin/initdb"), key=lambda p: int(p.parent.parent.name)
    )
    if found:
        return found[-1].parent
    on_path = shutil.which("initdb")
    if on_path:
        return Path(on_path).parent
    raise OfficeError(
        "PostgreSQL's initdb is not installed (Debian: apt-get install postgresql postgis, "
        "or `make office`)"
    )


@dataclass(frozen=True)
class Cluster:
    """The cluster in `data`: the server's files in data/pg, its socket in data/run."""

    data: Path

    @property
    def pgdata(self) -> Path:
        return self.data / "pg"

    @property
    def socket_dir(self) -> Path:
        return self.data / "run"

    @property
    def conninfo(self) -> str:
        return f"host={self.socket_dir} dbname={DATABASE} user={SUPERUSER}"

    def initialised(self) -> bool:
        return (self.pgdata / "PG_VERSION").is_file()

    def running(self) -> bool:
        if not self.initialised():
            return False
        done = self._run("pg_ctl", "status", "-D", str(self.pgdata), check=False)
        return done.returncode == 0

    def start(self) -> bool:
        """Initialise (first time) and start the cluster, with PostGIS available in the
        topdress database; False when it was running already."""
        if self.running():
            return False
        self.data.mkdir(parents=True, exist_ok=True)
        self.socket_dir.mkdir(exist_ok=True)
        self._give_away()
        if not self.initialised():
            self._run(
                "initdb",
                "-D",
                str(self.pgdata),
                "-U",
                SUPERUSER,
                "--auth=trust",
                "-E",
                "UTF8",
                "--no-instructions",
            )
        opts = f"-k {self.socket_dir} -c listen_addresses='' -c max_connections=40"
        self._run(
            "pg_ctl",
            "start",
            "-w",
            "-D",
            str(self.pgdata),
            "-l",
            str(self.data / "server.log"),
            "-o",
            opts,
        )
        self._create_database()
        return True

    def stop(self) -> None:
        if self.running():
            self._run("pg_ctl", "stop", "-w", "-m", "fast", "-D", str(self.pgdata))

    def _create_database(self) -> None:
        import psycopg

        admin = f"host={self.socket_dir} dbname=postgres user={SUPERUSER}"
        with psycopg.connect(admin, autocommit=True) as conn:
            have = conn.execute("SELECT 1 FROM pg_database WHERE datname = %s", (DATABASE,))
            if have.fetchone() is None:
                conn.execute(f"CREATE DATABASE {DATABASE}")

    def _user(self) -> str | None:
        """The user the server runs as: ourselves, or a system user when we are root."""
        if os.geteuid() != 0:
            return None
        for name in SERVICE_USERS:
            with contextlib.suppress(KeyError):
                pwd.getpwnam(name)
                return name
        raise OfficeError("running as root and no unprivileged user (postgres, nobody) to run as")

    def _give_away(self) -> None:
        """The data directory belongs to the server's user (it refuses another owner)."""
        user = self._user()
        if user is None:
            return
        pw = pwd.getpwnam(user)
        for path in (self.data, self.socket_dir, *([self.pgdata] if self.pgdata.exists() else [])):
            os.chown(path, pw.pw_uid, pw.pw_gid)
        log = self.data / "server.log"
        if log.exists():
            os.chown(log, pw.pw_uid, pw.pw_gid)
        # the server's user must reach the directory: every parent must let it through
        for parent in self.data.resolve().parents:
            if not os.stat(parent).st_mode & 0o001:
                raise OfficeError(
                    f"{self.data}: the server runs as {user}, who cannot enter {parent}; "
                    "choose a data directory outside it"
                )

    def _run(self, tool: str, *args: str, check: bool = True) -> subprocess.CompletedProcess[str]:
        cmd = [str(pg_bindir() / tool), *args]
        user = self._user()
        if user is not None:
            cmd = ["runuser", "-u", user, "--", *cmd]
        done = subprocess.run(cmd, capture_output=True, text=True, cwd="/", check=False)
        if check and done.returncode != 0:
            tail = (done.stderr or done.stdout).strip().splitlines()[-3:]
            raise OfficeUnavailable(f"{tool} failed: {' / '.join(tail)}")
        return done
