"""A real, throw-away PostgreSQL server for the tests (a pytest plugin, see conftest.py).

Debian's server binaries (``make`` installs the ``postgresql`` package) refuse to run as root,
so ``initdb``/``pg_ctl`` run as the ``postgres`` user on a temporary directory it owns, with
TCP off and a Unix socket in that directory (PLATFORM.md). One server per test run; one fresh
database per test.

Fixtures:
* ``postgres``: the server (session scope; started on first use, ≈ 2 s).
* ``database_url``: parametrized ``sqlite`` / ``postgresql``: a new empty database URL, so a test
  that takes it runs on both back ends.

Without the binaries the PostgreSQL half fails with what to install; set
``TALUS_SKIP_POSTGRES=1`` to skip it instead (never in CI).
"""
from __future__ import annotations

import itertools
import os
import pwd
import shutil
import subprocess
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest

PG_BIN = Path(os.environ.get("TALUS_PG_BIN", "/usr/lib/postgresql/15/bin"))
RUN_AS = "postgres"
PORT = 5432  # names the socket file only: TCP is off


class PostgresServer:
    """``initdb`` + ``pg_ctl start`` on a temporary directory; ``stop()`` removes it all."""

    def __init__(self) -> None:
        self.root = Path(tempfile.mkdtemp(prefix="talus-pg-"))
        self.data = self.root / "data"
        self.log = self.root / "server.log"
        self._names = itertools.count(1)
        self.user = RUN_AS if os.geteuid() == 0 else pwd.getpwuid(os.geteuid()).pw_name
        if os.geteuid() == 0:  # the server refuses root: hand the directory to postgres
            owner = pwd.getpwnam(RUN_AS)
            os.chown(self.root, owner.pw_uid, owner.pw_gid)

    def _run(self, *args: str) -> None:
        cmd = ["runuser", "-u", RUN_AS, "--", *args] if os.geteuid() == 0 else list(args)
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
        if done.returncode != 0:
            log = self.log.read_text() if self.log.exists() else ""
            raise RuntimeError(f"{' '.join(args)} failed: {done.stderr}{done.stdout}\n{log}")

    def start(self) -> None:
        self._run(str(PG_BIN / "initdb"), "-D", str(self.data), "-U", self.user, "-A", "trust",
                  "-E", "UTF8", "--no-sync")
        options = (f"-c listen_addresses='' -k {self.root} -p {PORT} -c fsync=off "
                   "-c synchronous_commit=off -c full_page_writes=off")
        self._run(str(PG_BIN / "pg_ctl"), "-D", str(self.data), "-l", str(self.log),
                  "-o", options, "-w", "-t", "60", "start")

    def stop(self) -> None:
        try:
            if self.data.exists():
                self._run(str(PG_BIN / "pg_ctl"), "-D", str(self.data), "-m", "fast", "-w",
                          "stop")
        finally:
            shutil.rmtree(self.root, ignore_errors=True)

    def url(self, database: str = "postgres") -> str:
        return f"postgresql+psycopg://{self.user}@/{database}?host={self.root}&port={PORT}"

    def create_database(self) -> str:
        """A new empty database; returns its URL."""
        import sqlalchemy as sa
        name = f"talus_test_{next(self._names)}"
        engine = sa.create_engine(self.url(), isolation_level="AUTOCOMMIT")
        try:
            with engine.connect() as conn:
                conn.exec_driver_sql(f"CREATE DATABASE {name}")
        finally:
            engine.dispose()
        return self.url(name)

    def pg_dump(self, url: str) -> str:
        """The plain-SQL dump of the database at ``url`` (its text)."""
        from sqlalchemy.engine import make_url
        database = make_url(url).database or "postgres"
        cmd = [str(PG_BIN / "pg_dump"), "-h", str(self.root), "-p", str(PORT), "-U", self.user,
               database]
        if os.geteuid() == 0:
            cmd = ["runuser", "-u", RUN_AS, "--", *cmd]
        return subprocess.run(cmd, capture_output=True, text=True, check=True).stdout


@pytest.fixture(scope="session")
def postgres() -> Iterator[PostgresServer]:
    if not (PG_BIN / "initdb").exists():
        message = (f"PostgreSQL server binaries not found in {PG_BIN}: `make setup` installs "
                   "Debian's postgresql package (or set TALUS_PG_BIN)")
        if os.environ.get("TALUS_SKIP_POSTGRES") == "1":
            pytest.skip(message)
        pytest.fail(message)
    server = PostgresServer()
    try:
        server.start()
        yield server
    finally:
        server.stop()


@pytest.fixture(params=["sqlite", "postgresql"])
def database_url(request: pytest.FixtureRequest, tmp_path: Path) -> str:
    """An empty database on each back end (the test runs twice)."""
    if request.param == "sqlite":
        return str(tmp_path / "talus.db")
    server: PostgresServer = request.getfixturevalue("postgres")
    return server.create_database()
