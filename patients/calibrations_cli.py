"""``talus calibrations``: force-plate calibration records in the clinical database.

``add --record CAL.json [--certificate CAL.pdf]`` stores the record ``talus calibrate fit``
wrote (kept whole, its headline figures as columns, audited); ``certify ID --certificate PDF``
names its PDF certificate once it exists (``talus report calibration``); ``list`` and ``show``
read them. Engineers write; every role reads (``patients.roles``). Files are read, never
changed; the certificate is identified by its sha256, computed here.
"""
from __future__ import annotations

import argparse
import hashlib
import json
from pathlib import Path
from typing import Any

from patients.cli_common import add_common, command, emit, login, open_record, table
from patients.errors import InputError

#: A calibration record is a few hundred kB at most (the COP map dominates).
MAX_RECORD_BYTES = 16 << 20


def register(commands: argparse._SubParsersAction) -> None:
    p = commands.add_parser("add", help="store a calibration record (engineer)")
    add_common(p)
    p.add_argument("--record", required=True, help="calibration_record.json (talus calibrate fit)")
    p.add_argument("--certificate", default=None, help="its PDF certificate, if made already")
    p.set_defaults(func=_add)

    p = commands.add_parser("certify", help="name a stored calibration's PDF certificate (once)")
    add_common(p)
    p.add_argument("record_id")
    p.add_argument("--certificate", required=True, help="the PDF (talus report calibration)")
    p.set_defaults(func=_certify)

    p = commands.add_parser("list", help="stored calibrations, oldest first")
    add_common(p)
    p.add_argument("--plate-serial", default=None, help="one plate's calibrations")
    p.set_defaults(func=_list)

    p = commands.add_parser("show", help="one calibration: figures, matrix, certificate")
    add_common(p)
    p.add_argument("record_id")
    p.set_defaults(func=_show)


def read_record(path: str) -> dict[str, Any]:
    """The record file as JSON (bounded); refused clearly when it is not one."""
    f = Path(path)
    if not f.is_file():
        raise InputError(f"{f}: no such record file")
    if f.stat().st_size > MAX_RECORD_BYTES:
        raise InputError(f"{f}: larger than {MAX_RECORD_BYTES >> 20} MB; not a calibration record")
    try:
        data = json.loads(f.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise InputError(f"{f}: not a JSON calibration record ({exc})") from None
    if not isinstance(data, dict):
        raise InputError(f"{f}: not a calibration record (not a JSON object)")
    return data


def certificate(path: str) -> tuple[str, str]:
    """(absolute path, sha256) of an existing certificate file."""
    f = Path(path)
    if not f.is_file():
        raise InputError(f"{f}: no such certificate file")
    h = hashlib.sha256()
    with open(f, "rb") as stream:
        for block in iter(lambda: stream.read(1 << 20), b""):
            h.update(block)
    return str(f.resolve()), h.hexdigest()


@command
def _add(args: argparse.Namespace) -> int:
    record = read_record(args.record)
    cert, digest = certificate(args.certificate) if args.certificate else (None, None)
    with open_record(args) as db:
        stored = db.add_calibration(login(db, args), record, cert, digest)
    emit(args, stored, _describe)
    return 0


@command
def _certify(args: argparse.Namespace) -> int:
    cert, digest = certificate(args.certificate)
    with open_record(args) as db:
        stored = db.attach_calibration_certificate(login(db, args), args.record_id, cert, digest)
    emit(args, stored, _describe)
    return 0


@command
def _list(args: argparse.Namespace) -> int:
    with open_record(args) as db:
        rows = db.list_calibrations(login(db, args), args.plate_serial)
    emit(args, rows, lambda r: table(r, ["record_id", "plate_name", "plate_serial",
                                         "created_at", "passed", "cop_rms_mm", "force_pct_fs",
                                         "certificate_path"]))
    return 0


@command
def _show(args: argparse.Namespace) -> int:
    with open_record(args) as db:
        cal = db.get_calibration(login(db, args), args.record_id)
    emit(args, cal, _describe)
    return 0


def _describe(c: dict[str, Any]) -> str:
    keys = ("plate_name", "plate_serial", "reference_serial", "created_at", "operator",
            "passed", "figures_stage", "cop_rms_mm", "cop_max_mm", "force_pct_fs",
            "certificate_path", "certificate_sha256", "record_sha256", "added_by", "added_at")
    return "\n".join([f"calibration {c['record_id']}"] + [
        f"  {k:18s} {'-' if c.get(k) is None else c[k]}" for k in keys])
