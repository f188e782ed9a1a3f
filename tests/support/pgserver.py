"""A throwaway PostgreSQL server for the tests and the storage benchmark (POSIX only).

``start()`` runs ``initdb`` into a new temporary folder, starts ``postgres`` on a free
port of 127.0.0.1 with its Unix socket in that folder, and makes a login role and a
database owned by it (the role is not a superuser: what a lab's administrator would
give a rig). ``stop()`` shuts the server down and removes the folder. As root (CI),
the server runs as the ``postgres`` user (or ``nobody``): PostgreSQL refuses root.

The binaries are looked for in ``$STICKSLIP_PG_BIN``, on ``PATH``, then in Debian's
``/usr/lib/postgresql/<version>/bin`` (the highest version); :class:`Unavailable` says
why a server cannot be had (the tests skip with that reason).
"""

from __future__ import annotations

import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from itertools import count
from pathlib import Path
from urllib.parse import quote

__all__ = ["PostgresServer", "Unavailable", "find_bin", "start", "write_pgpass"]

ROLE = "rig"
DATABASE = "stickslip"


class Unavailable(RuntimeError):
    """No PostgreSQL server can be started here (the message says why)."""


def find_bin() -> Path | None:
    """The folder with ``initdb``, ``pg_ctl`` and ``postgres``, or ``None``."""
    env = os.environ.get("STICKSLIP_PG_BIN")
    candidates = [Path(env)] if env else []
    on_path = shutil.which("initdb")
    if on_path:
        candidates.append(Path(os.path.realpath(on_path)).parent)
    debian = Path("/usr/lib/postgresql")
    if debian.is_dir():
        versions = sorted((p for p in debian.iterdir() if p.name.isdigit()), key=lambda p: int(p.name), reverse=True)
        candidates += [v / "bin" for v in versions]
    for c in candidates:
        if (c / "initdb").is_file() and (c / "postgres").is_file():
            return c
    return None


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@dataclass
class PostgresServer:
    """A running server: connect as :data:`ROLE` with :attr:`password` to :data:`DATABASE` on 127.0.0.1:``port``."""

    root: Path
    port: int
    bin: Path
    proc: subprocess.Popen[bytes]
    password: str
    _schemas: count[int] = field(default_factory=lambda: count(1))

    @property
    def socket_dir(self) -> Path:
        return self.root

    def admin(self, sql: str, dbname: str = DATABASE, schema: str | None = None) -> list[tuple[object, ...]]:
        """Run ``sql`` as the superuser over the Unix socket (trust), in ``schema`` if given; its last rows."""
        import psycopg

        with psycopg.connect(host=str(self.root), port=self.port, user="postgres", dbname=dbname, autocommit=True) as c:
            if schema:
                c.execute(f"SET search_path = {schema}".encode())
            cur = c.execute(sql.encode())
            rows: list[tuple[object, ...]] = []
            while True:
                if cur.description:
                    rows = list(cur.fetchall())
                if not cur.nextset():
                    return rows

    def new_schema(self) -> str:
        """A new empty schema owned by the rig's role (one per test: a fresh database in milliseconds)."""
        name = f"t{os.getpid()}_{next(self._schemas)}"
        self.admin(f"CREATE SCHEMA {name} AUTHORIZATION {ROLE}")
        return name

    def url(self, schema: str | None = None, with_password: bool = False) -> str:
        """``postgresql://rig@127.0.0.1:PORT/stickslip`` (the schema as the search_path, the password if asked)."""
        auth = f"{ROLE}:{quote(self.password, safe='')}" if with_password else ROLE
        url = f"postgresql://{auth}@127.0.0.1:{self.port}/{DATABASE}"
        if schema:
            url += f"?options=-csearch_path%3D{schema}"
        return url

    def stop(self) -> None:
        """Immediate shutdown (no checkpoint: the data is thrown away), then remove the folder."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGQUIT)
            try:
                self.proc.wait(20)
            except subprocess.TimeoutExpired:  # pragma: no cover - a server that does not stop
                self.proc.kill()
                self.proc.wait(10)
        shutil.rmtree(self.root, ignore_errors=True)


def _die_with_parent() -> Callable[[], None] | None:
    """Linux: the server gets SIGQUIT (an immediate shutdown) when the test process dies, even by ``kill -9``.

    Without it a killed test run would leave its server running. Elsewhere ``None``: the
    server is stopped by the session's teardown only.
    """
    if not sys.platform.startswith("linux"):
        return None
    import ctypes

    try:
        libc = ctypes.CDLL(None, use_errno=True)
        prctl = libc.prctl
    except (OSError, AttributeError):  # pragma: no cover - a libc without prctl
        return None
    pr_set_pdeathsig = 1

    def arm() -> None:  # in the child, after the user switch, before exec
        prctl(pr_set_pdeathsig, int(signal.SIGQUIT), 0, 0, 0)

    return arm


def _run_as() -> dict[str, int]:
    """``subprocess`` arguments that drop root (PostgreSQL refuses to run as root); empty otherwise."""
    if os.name != "posix" or os.geteuid() != 0:
        return {}
    import pwd

    for name in ("postgres", "nobody"):
        try:
            pw = pwd.getpwnam(name)
        except KeyError:
            continue
        return {"user": pw.pw_uid, "group": pw.pw_gid}
    raise Unavailable("running as root, and no 'postgres' or 'nobody' user to run the server as")


def start(durable: bool = False, timeout: float = 60.0) -> PostgresServer:
    """initdb, start, make the role and the database; :class:`Unavailable` when it cannot be done here.

    ``durable=False`` (tests) turns fsync off; ``durable=True`` (benchmarks) keeps
    PostgreSQL's defaults, to compare with SQLite's ``synchronous=FULL`` fairly.
    """
    if os.name != "posix":
        raise Unavailable("the throwaway PostgreSQL server helper is POSIX-only")
    try:
        import psycopg  # noqa: F401
    except ImportError:
        raise Unavailable("psycopg is not installed (pip install 'stickslip[postgres]')") from None
    bin_dir = find_bin()
    if bin_dir is None:
        raise Unavailable(
            "PostgreSQL's server binaries (initdb, postgres) were not found: install PostgreSQL "
            "(Debian: apt-get install postgresql) or set $STICKSLIP_PG_BIN"
        )
    who = _run_as()
    root = Path(tempfile.mkdtemp(prefix="stickslip-pg-"))
    if who:
        os.chown(root, who["user"], who["group"])
    password = "rig-" + secrets.token_hex(6) + ":@/%ä"
    env = {k: v for k, v in os.environ.items() if not k.startswith("PG")}
    env["LC_ALL"] = env["LANG"] = "C"
    try:
        out = subprocess.run(
            [str(bin_dir / "initdb"), "-D", str(root / "data"), "-U", "postgres", "-E", "UTF8", "--no-locale",
             "--auth-local=trust", "--auth-host=scram-sha-256", "--no-sync"],
            capture_output=True, env=env, cwd=root, timeout=timeout, check=False,
            user=who.get("user"), group=who.get("group"),
        )
        if out.returncode != 0:
            raise Unavailable(f"initdb failed: {out.stderr.decode(errors='replace').strip()[-300:]}")
        settings = ["fsync=off", "synchronous_commit=off", "full_page_writes=off"] if not durable else []
        for attempt in range(3):
            port = _free_port()
            log = open(root / "server.log", "ab")  # noqa: SIM115  (the server writes to it while it runs)
            args = [str(bin_dir / "postgres"), "-D", str(root / "data"), "-p", str(port), "-k", str(root),
                    "-c", "listen_addresses=127.0.0.1", "-c", "max_connections=60", "-c", "shared_buffers=32MB"]
            for s in settings:
                args += ["-c", s]
            proc = subprocess.Popen(
                args, stdout=log, stderr=subprocess.STDOUT, env=env, cwd=root, start_new_session=True,
                user=who.get("user"), group=who.get("group"), preexec_fn=_die_with_parent(),
            )
            log.close()
            server = PostgresServer(root, port, bin_dir, proc, password)
            if _wait_ready(server, timeout):
                break
            server.proc.kill()
            server.proc.wait(10)
            if attempt == 2:
                tail = (root / "server.log").read_text(errors="replace").strip()[-300:]
                raise Unavailable(f"the PostgreSQL server did not start: {tail}")
        server.admin(f"CREATE ROLE {ROLE} LOGIN PASSWORD '{password}'", dbname="postgres")
        server.admin(f"CREATE DATABASE {DATABASE} OWNER {ROLE}", dbname="postgres")
        return server
    except BaseException:
        shutil.rmtree(root, ignore_errors=True)
        raise


def _wait_ready(server: PostgresServer, timeout: float) -> bool:
    import psycopg

    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if server.proc.poll() is not None:
            return False
        try:
            with psycopg.connect(host=str(server.root), port=server.port, user="postgres", dbname="postgres",
                                 connect_timeout=2):
                return True
        except psycopg.OperationalError:
            time.sleep(0.05)
    return False


def write_pgpass(server: PostgresServer, path: Path) -> Path:
    """A libpq password file for the rig's role at ``path`` (mode 600): ``PGPASSFILE=path`` keeps it off screens."""
    esc = server.password.replace("\\", "\\\\").replace(":", "\\:")
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w", encoding="utf-8") as f:
        f.write(f"127.0.0.1:{server.port}:{DATABASE}:{ROLE}:{esc}\n")
    return path


if __name__ == "__main__":  # pragma: no cover - by hand: start one, print how to reach it, stop on Enter
    s = start()
    passfile = write_pgpass(s, s.root / "pgpass")
    print(f"PGPASSFILE={passfile} stickslip history --db {s.url()}", flush=True)  # the password stays in the file
    sys.stdin.readline()
    s.stop()
