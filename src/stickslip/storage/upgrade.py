"""Upgrading an older stickslip's database: its copy first, and its devices named by their controllers (schema 5).

Also the pieces of a whole-file copy that :meth:`Store.backup` shares (its temporary name, its removal).
"""

from __future__ import annotations

import os
import secrets
from pathlib import Path
from typing import Any

from ..devices.base import redact_text, redact_url
from ..measurements import Traverse
from ..records import temp_stem
from .backend import Backend
from .schema import StoreError, _content_keys, stored_device
from .spellings import merge_state

KEYED_AT = 5
"""The schema version from which every device is stored under :func:`~.schema.stored_device` as it is now (its
controller's name; from 4 to 5 its URL's key): an older store's devices are renamed and merged (:func:`key_devices`)."""


def row_traverse(r: Any) -> Traverse:
    """The measurement-table row of a stored traverse (a row of ``traverses`` with its session's ``day``)."""
    return Traverse(
        r["day"], int(r["joint"]), r["direction"], r["q1"], r["q2"], r["q3"], r["theta"], r["psi"], r["start"],
        r["end"], int(r["steps"]),
    )


def _part_file(dest: Path) -> Path:
    """A name beside ``dest`` for this copy alone, not yet a file.

    Not a fixed ``.NAME.part``: one left by a backup killed before its rename (SIGKILL, a
    power cut) made the next backup to ``dest`` fail (``file is not a database``, or a
    copy of a shared database ``UNIQUE constraint failed``), and two backups to one name at
    once wrote into the same file.
    """
    return dest.with_name(f".{temp_stem(dest.name)}.{os.getpid()}-{secrets.token_hex(4)}.part")


def _remove_part(tmp: Path) -> None:
    """A failed copy and what SQLite made beside it (``-wal``, ``-shm``, ``-journal``)."""
    for p in (tmp, *(tmp.with_name(tmp.name + end) for end in ("-wal", "-shm", "-journal"))):
        p.unlink(missing_ok=True)


def copy_name(path: Path, version: int) -> Path:
    """A free name beside ``path`` saying the schema version it holds: ``NAME.v3.db``, else ``NAME.v3-2.db`` ..."""
    stem, suffix = path.stem, path.suffix or ".db"
    for n in range(1, 1000):
        name = path.with_name(f"{stem}.v{version}{'' if n == 1 else f'-{n}'}{suffix}")
        if not os.path.lexists(name):
            return name
    raise StoreError(f"cannot upgrade the database {path}: {stem}.v{version}{suffix} to -999 exist beside it "
                     "(copies of earlier upgrades): move some away; it is left as it was")


def copy_before_upgrade(con: Backend, path: Path, version: int, upgrading_to: int) -> Path:
    """Copy the SQLite database at ``path`` (at schema ``version``) to :func:`copy_name`, whole or not at all.

    Called inside the upgrade's write transaction before anything is written, so the copy
    is the file as it was and no other process upgrades it meanwhile. Written beside it
    under a temporary name and renamed into place; a copy that cannot be written (a full
    disk, a read-only folder) is :class:`StoreError` saying so, and the upgrade is not made.
    """
    dest = copy_name(path, version)
    tmp = _part_file(dest)
    try:
        con.copy_as_read(tmp)
        os.replace(tmp, dest)
    except (OSError, StoreError) as e:
        _remove_part(tmp)
        why = e.strerror if type(e) is not StoreError and e.strerror else str(e)
        raise StoreError(
            f"cannot upgrade the database {path} from schema version {version} (an older stickslip's) to "
            f"{upgrading_to}: its copy {dest} cannot be written first ({why.replace(str(tmp), str(dest))}); "
            "it is left as it was"
        ) from None
    except BaseException:
        _remove_part(tmp)
        raise
    return dest


def secret_names(con: Backend) -> int:
    """How many device names hold a secret as written (``?password=...``, ``user:PASSWORD@``).

    A store written before URLs were redacted (2026-11-24) kept them; the upgrade to schema 4
    names every device by its key (no secret), but the copy made before it keeps the old names.
    """
    return sum(str(r["url"]) != redact_url(str(r["url"])) for r in con.execute("SELECT url FROM devices"))


def redact_texts(con: Backend) -> int:
    """Redact, in place, the how, source and reason kept with each traverse; the count of traverses changed.

    A store written before every text kept with a row went through the one redaction
    (2026-11-28) may hold a password in a source (``anc300://u:pw@h``) or a reason; an upgrade
    puts its texts through it as a write today would (the copy made before keeps them as they were).
    """
    changed = 0
    rows = con.execute("SELECT id, how, source, excluded FROM traverses").fetchall()
    for r in rows:
        was = (r["how"], r["source"], r["excluded"])
        now = tuple(None if v is None else redact_text(str(v)) for v in was)
        if now != was:
            con.execute("UPDATE traverses SET how = ?, source = ?, excluded = ? WHERE id = ?", (*now, r["id"]))
            changed += 1
    return changed


def key_devices(con: Backend) -> list[str]:
    """Rename every device to its stored name, merging two spellings of one device; one line per merge.

    A merged device's sessions, traverses, calibrations and state move to the device of
    that name (nothing is deleted: a day stored under both becomes one session; a state key
    both hold is kept under ``KEY (from OLD URL)``). The content keys of the moved or
    renamed traverses are recomputed under the new name. A URL that names no device
    (:func:`stored_device` refuses it) keeps its name, its secret redacted: the note that the copy alone holds
    the passwords is then true.
    """
    rows = [(int(r["id"]), str(r["url"])) for r in con.execute("SELECT id, url FROM devices ORDER BY id")]
    keys = {did: _key(url) for did, url in rows}
    owner = {url: did for did, url in rows if keys[did] == url}
    said: list[str] = []
    renamed: set[int] = set()
    origin: dict[int, dict[int, int]] = {}  # of a device merged into: each of its traverses' device before
    for did, url in rows:
        key = keys[did]
        if key == url:
            continue
        if key not in owner:
            con.execute("UPDATE devices SET url = ? WHERE id = ?", (key, did))
            owner[key] = did
        else:
            dst = owner[key]
            if dst not in origin:
                origin[dst] = dict.fromkeys(_traverse_ids(con, dst), dst)
            origin[dst].update(dict.fromkeys(_traverse_ids(con, did), did))
            said += _merge(con, did, dst, url, key, redact_url(dict(rows)[dst]))
        renamed.add(owner[key])
    for did in sorted(renamed):
        _rekey_content(con, did)
    for did, was in origin.items():
        twice = _stored_under_both(con, did, was)
        if twice:
            shown = ", ".join(map(str, twice[:20])) + (f" and {len(twice) - 20} more" if len(twice) > 20 else "")
            said.append(f"{len(twice)} traverse(s) of {_url(con, did)} were stored under two spellings as well (the "
                        f"same day, pose and steps), kept: ids {shown} (stickslip delete -t ID removes one)")
    return said


def _key(url: str) -> str:
    for name in (url, redact_url(url)):  # 'anc300://u:pw@h:xx' (a port that is no number) names no device
        try:
            return stored_device(name)
        except ValueError:
            pass
    return redact_url(url)  # kept as written but for its secret (an old store's name no URL rule reads)


def _url(con: Backend, did: int) -> str:
    return str(con.execute("SELECT url FROM devices WHERE id = ?", (did,)).fetchone()[0])


def _merge(con: Backend, src: int, dst: int, url: str, key: str, was: str) -> list[str]:
    """Move everything of device ``src`` (stored as ``url``) to ``dst`` (named ``key``, stored as ``was`` before
    the upgrade); the lines saying so (the merge, and what of their kept state the user must know of:
    :func:`~.spellings.merge_state`)."""
    n = int(con.execute(
        "SELECT COUNT(*) FROM traverses t JOIN sessions s ON s.id = t.session_id WHERE s.device_id = ?", (src,)
    ).fetchone()[0])
    days = [(int(r[0]), r[1]) for r in con.execute("SELECT id, day FROM sessions WHERE device_id = ?", (src,))]
    for sid, day in days:
        same = con.execute("SELECT id FROM sessions WHERE device_id = ? AND day = ?", (dst, day)).fetchone()
        if same is None:
            con.execute("UPDATE sessions SET device_id = ? WHERE id = ?", (dst, sid))
        else:
            con.execute("UPDATE traverses SET session_id = ? WHERE session_id = ?", (int(same[0]), sid))
            con.execute("DELETE FROM sessions WHERE id = ?", (sid,))
    cals = con.execute("UPDATE calibrations SET device_id = ? WHERE device_id = ?", (dst, src)).rowcount
    problems = merge_state(con, src, dst, url, key, was)
    con.execute("UPDATE devices SET model = (SELECT model FROM devices WHERE id = ?) WHERE id = ? AND model IS NULL",
                (src, dst))
    con.execute("DELETE FROM devices WHERE id = ?", (src,))
    return [f"the devices {redact_url(url)} and {key} are one device now, {key} (docs/storage.md): the {n} "
            f"traverse(s) and {max(cals, 0)} calibration(s) of {redact_url(url)} moved to it, none deleted",
            *problems]


def _rekey_content(con: Backend, did: int) -> None:
    """Recompute the content keys of device ``did``'s traverses under its (new) name."""
    rows = con.execute(
        "SELECT t.*, s.day AS day FROM traverses t JOIN sessions s ON s.id = t.session_id WHERE s.device_id = ?",
        (did,),
    ).fetchall()
    keys = _content_keys([row_traverse(r) for r in rows], _url(con, did))
    con.executemany("UPDATE traverses SET content = ? WHERE id = ?",
                    [(k, int(r["id"])) for k, r in zip(keys, rows, strict=True)])


def _traverse_ids(con: Backend, did: int) -> list[int]:
    sql = "SELECT t.id FROM traverses t JOIN sessions s ON s.id = t.session_id WHERE s.device_id = ?"
    return [int(r[0]) for r in con.execute(sql, (did,))]


def _stored_under_both(con: Backend, did: int, origin: dict[int, int]) -> list[int]:
    """The ids of device ``did``'s traverses whose content an earlier one of another former spelling has."""
    first: dict[str, tuple[int, int]] = {}  # content -> (the first id, its former device)
    twice: list[int] = []
    for tid, content in con.execute(
        "SELECT t.id, t.content FROM traverses t JOIN sessions s ON s.id = t.session_id WHERE s.device_id = ? "
        "ORDER BY t.id", (did,),
    ):
        seen = first.setdefault(str(content), (int(tid), origin.get(int(tid), did)))
        if seen[0] != int(tid) and seen[1] != origin.get(int(tid), did):
            twice.append(int(tid))
    return twice
