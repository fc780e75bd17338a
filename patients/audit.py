"""The append-only, hash-chained audit log.

Each row carries ``hash = sha256(prev_hash || canonical(row))`` where ``canonical`` is the
row's fields as sorted-key JSON; the first row's ``prev_hash`` is 64 zeros. Editing a row
breaks its hash, deleting or inserting one breaks the next row's link, and truncating the tail
is caught by ``audit_head`` (the last seq and hash, updated in the same transaction).

Appends lock ``audit_head`` (``SELECT ... FOR UPDATE`` on PostgreSQL; SQLite's
``BEGIN IMMEDIATE`` already serializes writers), so two workstations never fork the chain.

Identifying data never enters the log: its entries name the fields read or changed, not their
values, so ``forget`` leaves nothing behind here.
"""
from __future__ import annotations

import datetime as dt
import hashlib
import json
from dataclasses import dataclass
from typing import Any, Iterator

import sqlalchemy as sa
from sqlalchemy.orm import Session

from patients.errors import AuditChainBroken, InputError
from patients.models import AuditEntry, AuditHead

GENESIS = "0" * 64
_FIELDS = ("seq", "at", "username", "action", "entity", "entity_key", "before", "after")


def canonical_json(value: Any) -> str:
    """Deterministic JSON (sorted keys, no spaces, ISO dates)."""
    return json.dumps(value, sort_keys=True, separators=(",", ":"), ensure_ascii=False,
                      default=_default)


def _default(value: Any) -> Any:
    if isinstance(value, (dt.datetime, dt.date)):
        return value.isoformat()
    raise TypeError(f"cannot put {type(value).__name__} in the audit log")


def row_hash(prev_hash: str, fields: dict[str, Any]) -> str:
    body = canonical_json({k: fields[k] for k in _FIELDS})
    return hashlib.sha256((prev_hash + body).encode()).hexdigest()


def append(db: Session, at: dt.datetime, username: str | None, action: str, entity: str,
           entity_key: str | None = None, before: Any = None, after: Any = None) -> AuditEntry:
    """Add one entry to the chain inside the caller's transaction (committed with it)."""
    head = db.execute(sa.select(AuditHead).where(AuditHead.id == 1)
                      .with_for_update()).scalar_one_or_none()
    if head is None:  # created by migration 0001; gone only if someone deleted it
        raise AuditChainBroken("the audit log's head record is missing: run `talus audit "
                               "verify` and restore the database from a backup")
    fields: dict[str, Any] = {
        "seq": head.seq + 1, "at": at.astimezone(dt.timezone.utc).isoformat(),
        "username": username, "action": action, "entity": entity, "entity_key": entity_key,
        "before": None if before is None else canonical_json(before),
        "after": None if after is None else canonical_json(after)}
    entry = AuditEntry(**fields, prev_hash=head.hash, hash=row_hash(head.hash, fields))
    db.add(entry)
    head.seq, head.hash = entry.seq, entry.hash
    db.flush()
    return entry


@dataclass(frozen=True)
class Verification:
    ok: bool
    entries: int
    problems: list[str]
    #: "SEQ:HASH" of the last entry: note it outside the database (a ticket, the paper log) and
    #: give it to a later ``verify(anchor=...)``; a chain rewritten from scratch cannot match.
    head: str

    def as_dict(self) -> dict[str, Any]:
        return {"ok": self.ok, "entries": self.entries, "problems": self.problems,
                "head": self.head}


def parse_anchor(text: str) -> tuple[int, str]:
    """"SEQ:HASH" (as printed by verify) -> (seq, hash)."""
    seq, _, digest = text.partition(":")
    if not seq.isdigit() or len(digest) != 64:
        raise InputError(f"anchor {text!r}: expected SEQ:HASH as printed by `talus audit verify`")
    return int(seq), digest.lower()


def verify(db: Session, anchor: tuple[int, str] | None = None) -> Verification:
    """Walk the chain; every broken link, edited row, gap and truncated tail is reported.

    ``anchor`` (seq, hash): an entry noted outside the database earlier, which must still be in
    the chain with that hash (catches a chain rewritten whole by someone with write access).
    """
    problems: list[str] = []
    anchor_seen = anchor is None
    prev, expected_seq, count = GENESIS, 1, 0
    for e in _entries(db):
        count += 1
        if e.seq > expected_seq:
            gap = str(expected_seq) if e.seq - 1 == expected_seq else f"{expected_seq}..{e.seq - 1}"
            problems.append(f"entries {gap} missing (deleted)")
        elif e.seq < expected_seq:
            problems.append(f"entry {e.seq} out of order")
        if e.prev_hash != prev:
            problems.append(f"entry {e.seq}: does not link to the entry before it "
                            "(an entry was deleted, inserted or edited)")
        fields = {k: getattr(e, k) for k in _FIELDS}
        if row_hash(e.prev_hash, fields) != e.hash:
            problems.append(f"entry {e.seq}: its content does not match its hash (edited)")
        if anchor is not None and e.seq == anchor[0]:
            anchor_seen = True
            if e.hash != anchor[1]:
                problems.append(f"entry {e.seq} is not the one noted (anchor hash differs): "
                                "the chain was rewritten")
        prev, expected_seq = e.hash, e.seq + 1
    head = db.get(AuditHead, 1)
    if head is None:
        problems.append("the chain's head record is missing (deleted)")
    elif head.seq != expected_seq - 1 or head.hash != prev:
        problems.append(f"the chain ends at entry {expected_seq - 1} but was last extended to "
                        f"entry {head.seq} (entries at the end were deleted or edited)")
    if not anchor_seen:
        assert anchor is not None
        problems.append(f"anchor entry {anchor[0]} is not in the chain (deleted or rewritten)")
    return Verification(not problems, count, problems, f"{expected_seq - 1}:{prev}")


def _entries(db: Session) -> Iterator[AuditEntry]:
    stmt = sa.select(AuditEntry).order_by(AuditEntry.seq).execution_options(yield_per=1000)
    yield from db.execute(stmt).scalars()


def export(db: Session) -> Iterator[dict[str, Any]]:
    """Every entry as a plain dict (before/after decoded), in chain order."""
    for e in _entries(db):
        yield {"seq": e.seq, "at": e.at, "username": e.username, "action": e.action,
               "entity": e.entity, "entity_key": e.entity_key,
               "before": None if e.before is None else json.loads(e.before),
               "after": None if e.after is None else json.loads(e.after),
               "prev_hash": e.prev_hash, "hash": e.hash}
