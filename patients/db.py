"""Opening the clinical database: where it is, how it is connected, its schema version.

* URL: ``--db`` (a SQLAlchemy URL, or a plain path meaning an SQLite file), else
  ``TALUS_DATABASE_URL``, else ``talus.db`` in the user data directory (platformdirs).
  ``postgresql://`` URLs are driven by psycopg 3.
* SQLite: WAL (readers never wait for the writer), foreign keys on, a busy timeout, and
  ``secure_delete`` so erased identifying data is overwritten, not left in free pages. Every
  transaction starts with ``BEGIN IMMEDIATE``: writers on several processes queue at the start
  of their transaction instead of failing half-way when a read lock cannot be upgraded.
* Schema: Alembic migrations shipped in this package (``patients/migrations``), so an installed
  talus upgrades its own database (``talus db upgrade``).
"""
from __future__ import annotations

import os
from importlib import resources
from pathlib import Path
from typing import Any

import sqlalchemy as sa
from alembic import command
from alembic.config import Config
from alembic.runtime.migration import MigrationContext
from alembic.script import ScriptDirectory
from sqlalchemy.engine import URL, Engine, make_url

from patients.errors import DatabaseUnavailable

ENV_URL = "TALUS_DATABASE_URL"
#: SQLite: how long a writer waits for another one before giving up (ms).
SQLITE_BUSY_TIMEOUT_MS = 15_000


def default_sqlite_path() -> Path:
    import platformdirs
    return Path(platformdirs.user_data_dir("talus", appauthor=False)) / "talus.db"


def resolve_url(db: str | None = None) -> URL:
    """The database to use: ``db``, else $TALUS_DATABASE_URL, else the default SQLite file."""
    text = db or os.environ.get(ENV_URL) or str(default_sqlite_path())
    if "://" not in text:
        return URL.create("sqlite+pysqlite", database=str(Path(text).expanduser().resolve()))
    try:
        url = make_url(text)
    except sa.exc.ArgumentError as exc:
        raise DatabaseUnavailable(f"not a database URL: {text!r} ({exc})") from None
    if url.drivername in ("postgresql", "postgres", "postgresql+psycopg"):
        return url.set(drivername="postgresql+psycopg")
    if url.drivername in ("sqlite", "sqlite+pysqlite"):
        return url.set(drivername="sqlite+pysqlite")
    raise DatabaseUnavailable(f"unsupported database {url.drivername!r}: use a path, "
                              "sqlite:///FILE or postgresql://USER@HOST/DB")


def is_sqlite(url: URL) -> bool:
    return url.get_backend_name() == "sqlite"


def sqlite_file(url: URL) -> Path | None:
    """The SQLite database file, or None (PostgreSQL, in-memory)."""
    if not is_sqlite(url) or not url.database or url.database == ":memory:":
        return None
    return Path(url.database)


def describe(url: URL) -> str:
    """The URL without its password, for messages."""
    return url.render_as_string(hide_password=True)


def create_engine(url: URL, create: bool = False) -> Engine:
    """An engine for ``url``. An SQLite file must exist unless ``create``."""
    path = sqlite_file(url)
    if path is not None:
        if not path.exists():
            if not create:
                raise DatabaseUnavailable(
                    f"no database at {path}: create it with `talus users init` or "
                    "`talus db upgrade`, or name another one with --db")
            path.parent.mkdir(parents=True, exist_ok=True)
            # Clinical data: readable by its owner only (SQLite gives -wal/-shm the same mode).
            path.touch(mode=0o600, exist_ok=False)
        engine = sa.create_engine(url, connect_args={"timeout": SQLITE_BUSY_TIMEOUT_MS / 1000})
        _configure_sqlite(engine)
        return engine
    return sa.create_engine(url, pool_pre_ping=True)


def _configure_sqlite(engine: Engine) -> None:
    @sa.event.listens_for(engine, "connect")
    def _on_connect(dbapi_connection: Any, _record: Any) -> None:
        # Let SQLAlchemy's "begin" event decide how transactions start (SQLAlchemy's
        # documented recipe for pysqlite).
        dbapi_connection.isolation_level = None
        cur = dbapi_connection.cursor()
        cur.execute("PRAGMA journal_mode=WAL")
        cur.execute("PRAGMA foreign_keys=ON")
        cur.execute(f"PRAGMA busy_timeout={SQLITE_BUSY_TIMEOUT_MS}")
        cur.execute("PRAGMA secure_delete=ON")
        cur.close()

    @sa.event.listens_for(engine, "begin")
    def _on_begin(conn: sa.Connection) -> None:
        conn.exec_driver_sql("BEGIN IMMEDIATE")


# ---------------------------------------------------------------- migrations

def _alembic_config(connection: sa.Connection | None = None) -> Config:
    cfg = Config()
    cfg.set_main_option("script_location",
                        str(resources.files("patients") / "migrations"))
    cfg.attributes["connection"] = connection
    return cfg


def head_revision() -> str:
    head = ScriptDirectory.from_config(_alembic_config()).get_current_head()
    assert head is not None
    return head


def current_revision(engine: Engine) -> str | None:
    with engine.connect() as conn:
        return MigrationContext.configure(conn).get_current_revision()


def upgrade(engine: Engine, revision: str = "head") -> None:
    """Migrate the schema up to ``revision`` (idempotent)."""
    with engine.begin() as conn:
        command.upgrade(_alembic_config(conn), revision)


def downgrade(engine: Engine, revision: str) -> None:
    """Migrate the schema down to ``revision`` ("base" drops every table)."""
    with engine.begin() as conn:
        command.downgrade(_alembic_config(conn), revision)


def require_current(engine: Engine) -> None:
    """Refuse a database whose schema is not the one this talus was built for."""
    current, head = current_revision(engine), head_revision()
    if current != head:
        where = describe(engine.url)
        if current is None:
            raise DatabaseUnavailable(f"{where} holds no talus clinical record: create it "
                                      "with `talus users init` (or `talus db upgrade`)")
        raise DatabaseUnavailable(f"{where} is at schema {current}, this talus needs {head}: "
                                  "run `talus db upgrade` (after a backup)")
