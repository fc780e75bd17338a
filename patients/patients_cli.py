"""``talus patients``: register, list, show, edit, limits, ankle, plans, forget, export,
import."""
from __future__ import annotations

import argparse
import datetime as dt
import json
from pathlib import Path
from typing import Any

from patients.cli_common import add_common, command, emit, login, open_record, table, write_new_file
from patients.errors import InputError

_CLINICAL_ARGS = (("--mass-kg", "body_mass_kg", float, "body mass (kg): doses gait loading"),
                  ("--height-m", "height_m", float, "height (m)"),
                  ("--side", "affected_side", str, "affected side: left, right or both"),
                  ("--diagnosis", "diagnosis", str, "diagnosis (no names in free text)"),
                  ("--notes", "notes", str, "clinical notes (no names in free text)"))
_LIMIT_ARGS = (("--roll-min-deg", "roll_min_deg"), ("--roll-max-deg", "roll_max_deg"),
               ("--pitch-min-deg", "pitch_min_deg"), ("--pitch-max-deg", "pitch_max_deg"),
               ("--max-force-n", "max_force_n"),
               ("--max-speed-deg-s", "max_angular_speed_deg_s"),
               ("--rom-tolerance-deg", "rom_tolerance_deg"))
_ROM_ARGS = ("dorsiflexion", "plantarflexion", "inversion", "eversion")


def _clinical_options(p: argparse.ArgumentParser) -> None:
    for flag, dest, kind, help_text in _CLINICAL_ARGS:
        p.add_argument(flag, dest=dest, type=kind, default=None, help=help_text)


def _identity_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("identifying data (kept apart; erased by `forget`)")
    g.add_argument("--name", default=None, help="full name")
    g.add_argument("--birth-date", default=None, help="YYYY-MM-DD")
    g.add_argument("--national-id", default=None)
    g.add_argument("--contact", default=None)


def register(commands: argparse._SubParsersAction) -> None:
    p = commands.add_parser("add", help="register a patient (a pseudonymous code is generated "
                                        "unless --code)")
    add_common(p)
    p.add_argument("--code", default=None, help="pseudonymous code (A-Z, 0-9, -); never a name")
    _clinical_options(p)
    _identity_options(p)
    p.set_defaults(func=_add)

    p = commands.add_parser("list", help="patients (pseudonymous; --identity adds names)")
    add_common(p)
    p.add_argument("--identity", action="store_true", help="include identifying data (audited)")
    p.set_defaults(func=_list)

    p = commands.add_parser("show", help="one patient: clinical data, limits in force, plans")
    add_common(p)
    p.add_argument("code")
    p.add_argument("--identity", action="store_true", help="include identifying data (audited)")
    p.set_defaults(func=_show)

    p = commands.add_parser("edit", help="change clinical and/or identifying data")
    add_common(p)
    p.add_argument("code")
    p.add_argument("--version", type=int, default=None,
                   help="the version you looked at (from `show`): refused if someone saved "
                        "since")
    _clinical_options(p)
    _identity_options(p)
    p.set_defaults(func=_edit)

    p = commands.add_parser(
        "limits", help="show the limits in force and their history, or prescribe new ones",
        description="Without limit options: the limits in force and their history. With them: "
                    "a new prescription (unset fields keep their values). Clinical ROM "
                    "(--dorsiflexion ... --eversion, deg from neutral) maps to the robot's "
                    "roll/pitch by the foot (--side, default the affected side): pitch>0 is "
                    "plantarflexion; roll>0 is inversion of a right foot, eversion of a left "
                    "foot (patients/anatomy.py).")
    add_common(p)
    p.add_argument("code")
    for flag, dest in _LIMIT_ARGS:
        p.add_argument(flag, dest=dest, type=float, default=None)
    for name in _ROM_ARGS:
        p.add_argument(f"--{name}", type=float, default=None, help="deg from neutral")
    p.add_argument("--side", choices=("left", "right"), default=None,
                   help="the foot on the platform (for the clinical ROM options)")
    p.add_argument("--reason", default=None, help="why (kept with the prescription)")
    p.set_defaults(func=_limits)

    p = commands.add_parser(
        "ankle", help="show or enter where the patient's ankle centre sits on the platform",
        description="Without options: the ankle setup in force. With them: a new entry (unset "
                    "fields keep their values; --side defaults to the affected side). The "
                    "ankle joint centre (midpoint of the malleoli) relative to the platform: "
                    "height above the sole, and its horizontal offset from the platform's "
                    "centre along the foot (+ towards the toes) and across it, in m "
                    "(rt/model/ankle.py). Ankle exercises turn the foot about it.")
    add_common(p)
    p.add_argument("code")
    for flag in _ANKLE_ARGS:
        p.add_argument(f"--{flag.replace('_', '-')}", dest=flag, type=float, default=None,
                       help="m")
    p.add_argument("--side", choices=("left", "right"), default=None)
    p.add_argument("--source", choices=("entered", "camera"), default=None,
                   help="entered by hand (default) or measured with the camera")
    p.add_argument("--reason", default=None, help="why (kept with the entry)")
    p.add_argument("--measure", action="store_true",
                   help="measure the ankle centre with the camera (ArUco markers on both "
                        "malleoli and the platform's board, patients/ankle_camera.py): from "
                        "--frame, or on the twin from --twin-truth; stored with "
                        "source=camera and its uncertainty in the reason")
    p.add_argument("--frame", type=Path, default=None,
                   help="with --measure: a camera frame (image file) showing the board and "
                        "both malleolus markers")
    p.add_argument("--twin-truth", default=None, metavar="H,X,Y",
                   help="with --measure: the twin camera renders a foot whose ankle centre is "
                        "H m above the sole, X, Y m from the sensor's axis (default "
                        "0.07,0,0)")
    p.set_defaults(func=_ankle)

    p = commands.add_parser("plan", help="assign a protocol (YAML file, validated) to a "
                                         "patient, or --end a plan")
    add_common(p)
    p.add_argument("code")
    what = p.add_mutually_exclusive_group(required=True)
    what.add_argument("--protocol", help="protocol YAML file to assign")
    what.add_argument("--end", type=int, metavar="PLAN_ID", help="end this plan")
    p.add_argument("--parameters", default=None, help="JSON object of plan parameters")
    p.set_defaults(func=_plan)

    p = commands.add_parser("forget", help="erase a patient's identifying data, keep the "
                                           "pseudonymous history (GDPR art. 17; admin)")
    add_common(p)
    p.add_argument("code")
    p.add_argument("--yes", action="store_true", help="confirm: this cannot be undone")
    p.set_defaults(func=_forget)

    p = commands.add_parser("export", help="a patient's pseudonymous record as JSON")
    add_common(p)
    p.add_argument("code")
    p.add_argument("--out", required=True, help="JSON file to write")
    p.add_argument("--force", action="store_true", help="replace an existing --out")
    p.set_defaults(func=_export)

    p = commands.add_parser("import", help="import a record written by `patients export`")
    add_common(p)
    p.add_argument("file")
    p.set_defaults(func=_import)


def _identity(args: argparse.Namespace) -> Any:
    from patients.service import Identity
    given = [args.name, args.birth_date, args.national_id, args.contact]
    if not any(v is not None for v in given):
        return None
    if not args.name:
        raise InputError("identifying data needs --name")
    birth = None
    if args.birth_date:
        try:
            birth = dt.date.fromisoformat(args.birth_date)
        except ValueError:
            raise InputError(f"--birth-date {args.birth_date!r}: use YYYY-MM-DD") from None
    return Identity(args.name, birth, args.national_id, args.contact)


def _clinical(args: argparse.Namespace) -> dict[str, Any]:
    return {dest: getattr(args, dest) for _, dest, _, _ in _CLINICAL_ARGS
            if getattr(args, dest) is not None}


@command
def _add(args: argparse.Namespace) -> int:
    with open_record(args) as record:
        actor = login(record, args)
        patient = record.add_patient(actor, args.code, identity=_identity(args), **_clinical(args))
    emit(args, patient, f"patient {patient['code']} registered")
    return 0


_LIST_COLUMNS = ["code", "body_mass_kg", "height_m", "affected_side", "diagnosis", "created_at",
                 "forgotten_at"]


@command
def _list(args: argparse.Namespace) -> int:
    with open_record(args) as record:
        patients = record.list_patients(login(record, args), include_identity=args.identity)
    def human(rows: list[dict[str, Any]]) -> str:
        if args.identity:
            rows = [{**r, "name": (r["identity"] or {}).get("full_name")} for r in rows]
            return table(rows, ["code", "name", *_LIST_COLUMNS[1:]])
        return table(rows, _LIST_COLUMNS)
    emit(args, patients, human)
    return 0


@command
def _show(args: argparse.Namespace) -> int:
    with open_record(args) as record:
        actor = login(record, args)
        patient = record.get_patient(actor, args.code, include_identity=args.identity)
        patient["plans"] = record.plans(actor, args.code)
    emit(args, patient, _describe)
    return 0


def _describe(p: dict[str, Any]) -> str:
    lines = [f"patient {p['code']} (version {p['version']})"]
    if p.get("identity"):
        lines += [f"  {k:22s} {'-' if v is None else v}" for k, v in p["identity"].items()]
    elif p.get("forgotten_at"):
        lines.append(f"  identifying data erased {p['forgotten_at']}")
    for k in ("body_mass_kg", "height_m", "affected_side", "diagnosis", "notes", "created_at",
              "created_by"):
        lines.append(f"  {k:22s} {'-' if p.get(k) is None else p[k]}")
    lim = p.get("limits")
    lines.append("  limits in force        " + (_limits_text(lim) if lim else "none prescribed"))
    for plan in p.get("plans", []):
        lines.append(f"  plan {plan['id']}: {plan['protocol_name']} ({plan['protocol_kind']}, "
                     f"sha256 {plan['protocol_sha256'][:12]}…) by {plan['assigned_by']} "
                     f"{plan['assigned_at']}")
    return "\n".join(lines)


def _limits_text(lim: dict[str, Any]) -> str:
    text = (f"roll {lim['roll_min_deg']:+.1f}..{lim['roll_max_deg']:+.1f} deg, pitch "
            f"{lim['pitch_min_deg']:+.1f}..{lim['pitch_max_deg']:+.1f} deg, force "
            f"{lim['max_force_n']:.0f} N, speed {lim['max_angular_speed_deg_s']:.0f} deg/s")
    c = lim.get("clinical")
    if c:
        text += (f" (dorsi {c['dorsiflexion_deg']:.1f}, plantar {c['plantarflexion_deg']:.1f}, "
                 f"inversion {c['inversion_deg']:.1f}, eversion {c['eversion_deg']:.1f} deg)")
    return text + f"; set by {lim['set_by']} {lim['set_at']}"


@command
def _edit(args: argparse.Namespace) -> int:
    changes, identity = _clinical(args), _identity(args)
    if not changes and identity is None:
        raise InputError("nothing to change: give clinical options and/or identifying data")
    with open_record(args) as record:
        actor = login(record, args)
        if changes:
            record.update_patient(actor, args.code, args.version, **changes)
        if identity is not None:
            record.set_identity(actor, args.code, identity)
        patient = record.get_patient(actor, args.code)
    emit(args, patient, f"patient {args.code} updated (version {patient['version']})")
    return 0


@command
def _limits(args: argparse.Namespace) -> int:
    from patients import anatomy
    raw = {dest: getattr(args, dest) for _, dest in _LIMIT_ARGS if getattr(args, dest) is not None}
    rom = {n: getattr(args, n) for n in _ROM_ARGS if getattr(args, n) is not None}
    with open_record(args) as record:
        actor = login(record, args)
        if rom:
            if set(rom) != set(_ROM_ARGS):
                raise InputError("clinical ROM needs all four of --dorsiflexion, "
                                 "--plantarflexion, --inversion, --eversion")
            clash = set(raw) & {"roll_min_deg", "roll_max_deg", "pitch_min_deg", "pitch_max_deg"}
            if clash:
                raise InputError(f"give the ROM either clinically or as roll/pitch, not both "
                                 f"({sorted(clash)})")
            side = args.side or record.get_patient(actor, args.code)["affected_side"]
            raw.update(anatomy.to_robot(anatomy.ClinicalRom(**{f"{k}_deg": v
                                                               for k, v in rom.items()}), side))
        if raw:
            new = record.set_limits(actor, args.code, reason=args.reason, **raw)
            emit(args, new, "new limits in force: " + _limits_text(new))
            return 0
        history = record.limits_history(actor, args.code)
    emit(args, history, lambda h: "\n".join(
        [f"{i + 1}. {_limits_text(x)}" + (f" — {x['reason']}" if x["reason"] else "")
         for i, x in enumerate(h)] or ["no limits prescribed"]))
    return 0


_ANKLE_ARGS = ("height_above_sole_m", "offset_x_m", "offset_y_m", "sole_above_sensor_m")


def _ankle_text(a: dict[str, Any]) -> str:
    return (f"{a['side']} foot, ankle centre {a['height_above_sole_m'] * 1e3:.0f} mm above the "
            f"sole, offsets {a['offset_x_m'] * 1e3:+.0f} mm (toes +), "
            f"{a['offset_y_m'] * 1e3:+.0f} mm across ({a['source']})")


def _measure_ankle(args: argparse.Namespace, side: str) -> tuple[dict[str, Any], str]:
    """The camera's ankle setup (fields for ``set_ankle``) and the uncertainty's words."""
    import cv2
    from pydantic import ValidationError

    from patients.ankle_camera import (
        MalleoliRig,
        measure_malleoli,
        render_malleoli,
        twin_malleoli,
    )
    from rt.errors import InputError as RtInputError
    from rt.errors import validation_summary
    from rt.model.ankle import AnkleSetup
    from rt.model.description import load_description

    offset = list(load_description().sensor.offset_m)
    rig = MalleoliRig()
    sole = args.sole_above_sensor_m or 0.0
    if args.frame is not None:
        if args.twin_truth is not None:
            raise InputError("--frame and --twin-truth: give one (a camera frame, or the twin)")
        frame = cv2.imread(str(args.frame), cv2.IMREAD_COLOR)
        if frame is None:
            raise InputError(f"--frame {args.frame}: not a readable image file")
    else:
        try:
            h, x, y = (float(v) for v in (args.twin_truth or "0.07,0,0").split(","))
        except ValueError:
            raise InputError(f"--twin-truth {args.twin_truth!r}: give H,X,Y in m, e.g. "
                             "0.07,0.01,0") from None
        try:
            truth = AnkleSetup.model_validate({
                "side": side, "height_above_sole_m": h, "offset_x_m": x, "offset_y_m": y,
                "sole_above_sensor_m": sole})
        except ValidationError as exc:
            raise InputError(f"--twin-truth: {validation_summary(exc)}") from None
        frame = render_malleoli(rig, *twin_malleoli(truth, offset))
    try:
        m = measure_malleoli(frame, rig, side, offset, sole)
    except RtInputError as exc:
        raise InputError(str(exc)) from None
    sigma = ", ".join(f"{v * 1e3:.1f}" for v in m.centre_sigma_m)
    words = (f"measured with the camera: centre σ (x, y, z) = {sigma} mm, reprojection "
             f"{m.reprojection_rms_px:.2f} px RMS")
    fields = {k: v for k, v in m.setup.model_dump().items() if k != "side"}
    return fields, words


@command
def _ankle(args: argparse.Namespace) -> int:
    fields = {k: getattr(args, k) for k in (*_ANKLE_ARGS, "side", "source")
              if getattr(args, k) is not None}
    if not args.measure and (args.frame is not None or args.twin_truth is not None):
        raise InputError("--frame and --twin-truth go with --measure")
    if args.measure and set(fields) - {"side", "sole_above_sensor_m"}:
        raise InputError("--measure: the camera measures the height and offsets; give only "
                         "--side and --sole-above-sensor-m with it")
    with open_record(args) as record:
        actor = login(record, args)
        if args.measure:
            side = args.side or (record.ankle_in_force(actor, args.code) or {}).get("side") \
                or record.get_patient(actor, args.code).get("affected_side")
            if side not in ("left", "right"):
                raise InputError("--measure: which foot? give --side left|right")
            measured, words = _measure_ankle(args, side)
            reason = words if not args.reason else f"{args.reason} ({words})"
            new = record.set_ankle(actor, args.code, reason=reason, side=side, **measured)
            emit(args, {**new, "uncertainty": words},
                 "ankle setup in force: " + _ankle_text(new) + "; " + words)
            return 0
        if fields:
            new = record.set_ankle(actor, args.code, reason=args.reason, **fields)
            emit(args, new, "ankle setup in force: " + _ankle_text(new))
            return 0
        current = record.ankle_in_force(actor, args.code)
    emit(args, current, lambda a: _ankle_text(a) if a else "no ankle setup entered")
    return 0


@command
def _plan(args: argparse.Namespace) -> int:
    if args.end is not None:
        with open_record(args) as record:
            ended = record.end_plan(login(record, args), args.code, args.end)
        emit(args, ended, f"plan {args.end} of {args.code} ended")
        return 0
    try:
        text = Path(args.protocol).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read {args.protocol}: {exc}") from None
    try:
        params = json.loads(args.parameters) if args.parameters else None
    except json.JSONDecodeError as exc:
        raise InputError(f"--parameters is not JSON: {exc}") from None
    if params is not None and not isinstance(params, dict):
        raise InputError("--parameters must be a JSON object")
    with open_record(args) as record:
        plan = record.assign_plan(login(record, args), args.code, text, params)
    emit(args, plan, f"plan {plan['id']}: {plan['protocol_name']} assigned to {args.code}")
    return 0


@command
def _forget(args: argparse.Namespace) -> int:
    if not args.yes:
        raise InputError(f"forgetting {args.code} erases its identifying data for good: "
                         "add --yes")
    with open_record(args) as record:
        result = record.forget_patient(login(record, args), args.code)
    emit(args, result, f"patient {args.code}: identifying data erased"
         if result["identity_erased"] else f"patient {args.code} had no identifying data")
    return 0


@command
def _export(args: argparse.Namespace) -> int:
    with open_record(args) as record:
        doc = record.export_patient(login(record, args), args.code)
    write_new_file(args.out, json.dumps(doc, indent=1, ensure_ascii=False) + "\n", args.force)
    summary = {"code": args.code, "out": args.out, "sessions": len(doc["sessions"]),
               "recordings": doc["recordings"]}
    emit(args, summary, f"{args.code}: {len(doc['sessions'])} sessions exported to {args.out}")
    return 0


@command
def _import(args: argparse.Namespace) -> int:
    try:
        doc = json.loads(Path(args.file).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"cannot read {args.file}: {exc}") from None
    with open_record(args) as record:
        patient = record.import_patient(login(record, args), doc)
    emit(args, patient, f"patient {patient['code']} imported")
    return 0
