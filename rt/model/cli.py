"""``talus model describe|ik|fk|dynamics|demo``.

``ik``, ``fk`` and ``dynamics`` read JSON lines on stdin and answer one JSON line each (SI
units, angles in radians). A bad line is answered ``{"error": "..."}`` naming the problem; the
other lines are still answered and the exit code is 2.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from typing import Any, Callable, TextIO

import numpy as np

from rt.errors import InputError, TalusError
from rt.model import RobotModel
from rt.model.dynamics import Payload
from rt.model.robot_option import add_robot_option


def register(commands: argparse._SubParsersAction) -> None:
    for name, func, help_text in (
        ("describe", _describe, "geometry, limits, bodies, drive and base parameters as JSON"),
        ("ik", _ik, 'JSON lines {"z","roll","pitch"} -> {"q","x","y","yaw","phi"}'),
        ("fk", _fk, 'JSON lines {"q":[..]} -> pose and parasitic terms'),
        ("dynamics", _dynamics, 'JSON lines {"q","qd","qdd"[,"payload"][,"wrench"]} -> '
                                 'M, C, G, F, tau'),
        ("demo", _demo, "human-readable tour of the model on the twin's nominal description"),
    ):
        p = commands.add_parser(name, help=help_text)
        add_robot_option(p)
        p.set_defaults(func=func)


# ---------------------------------------------------------------------- input validation
def _number(obj: dict, key: str) -> float:
    if key not in obj:
        raise InputError(f'missing key "{key}"')
    value = obj[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise InputError(f'"{key}" must be a finite number, got {value!r}')
    return float(value)


def _vector(obj: dict, key: str, n: int = 3, default: list[float] | None = None) -> list[float]:
    if key not in obj:
        if default is not None:
            return default
        raise InputError(f'missing key "{key}" (a list of {n} numbers)')
    value = obj[key]
    if not isinstance(value, list) or len(value) != n:
        raise InputError(f'"{key}" must be a list of {n} numbers, got {value!r}')
    for v in value:
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise InputError(f'"{key}" must hold finite numbers, got {v!r}')
    return [float(v) for v in value]


def _only_keys(obj: dict, allowed: set[str]) -> None:
    extra = sorted(set(obj) - allowed)
    if extra:
        raise InputError(f"unknown key(s) {extra}; allowed: {sorted(allowed)}")


def _payload(obj: dict) -> Payload | None:
    if "payload" not in obj or obj["payload"] is None:
        return None
    p = obj["payload"]
    if not isinstance(p, dict):
        raise InputError('"payload" must be an object {"mass_kg", "com_m", "inertia_kg_m2"}')
    _only_keys(p, {"mass_kg", "com_m", "inertia_kg_m2"})
    mass = _number(p, "mass_kg")
    com = _vector(p, "com_m", default=[0.0, 0.0, 0.0])
    inertia = p.get("inertia_kg_m2", [[0.0] * 3] * 3)
    if (not isinstance(inertia, list) or len(inertia) != 3
            or not all(isinstance(r, list) and len(r) == 3 for r in inertia)):
        raise InputError('"payload.inertia_kg_m2" must be a 3x3 list of numbers')
    rows = [_vector({"row": r}, "row") for r in inertia]
    return Payload(mass, tuple(com), tuple(tuple(r) for r in rows))


def _json_lines(stdin: TextIO, stdout: TextIO, handle: Callable[[dict], dict]) -> int:
    status = 0
    for lineno, line in enumerate(stdin, start=1):
        if not line.strip():
            continue
        try:
            try:
                obj = json.loads(line)
            except json.JSONDecodeError as exc:
                raise InputError(f"line {lineno} is not valid JSON: {exc.msg}") from None
            if not isinstance(obj, dict):
                raise InputError(f"line {lineno} must be a JSON object")
            answer = handle(obj)
        except TalusError as exc:
            answer = {"error": str(exc), "line": lineno}
            status = 2
        stdout.write(json.dumps(answer) + "\n")
        stdout.flush()
    return status


def _load(args) -> RobotModel:
    return RobotModel.load(args.robot)


def _run_lines(args, handle: Callable[[RobotModel, dict], dict]) -> int:
    try:
        model = _load(args)
    except TalusError as exc:
        print(json.dumps({"error": str(exc)}))
        return 2
    return _json_lines(sys.stdin, sys.stdout, lambda obj: handle(model, obj))


# ---------------------------------------------------------------------- commands
def _ik(args) -> int:
    def handle(model: RobotModel, obj: dict) -> dict:
        _only_keys(obj, {"z", "roll", "pitch"})
        cfg = model.kin.ik(_number(obj, "z"), _number(obj, "roll"), _number(obj, "pitch"))
        return {"q": list(cfg.q), "x": cfg.x, "y": cfg.y, "yaw": cfg.yaw, "phi": list(cfg.phi)}
    return _run_lines(args, handle)


def _fk(args) -> int:
    def handle(model: RobotModel, obj: dict) -> dict:
        _only_keys(obj, {"q"})
        cfg = model.kin.fk(_vector(obj, "q"))
        return {"z": cfg.z, "roll": cfg.roll, "pitch": cfg.pitch, "x": cfg.x, "y": cfg.y,
                "yaw": cfg.yaw, "phi": list(cfg.phi), "iterations": cfg.iterations}
    return _run_lines(args, handle)


def _dynamics(args) -> int:
    def handle(model: RobotModel, obj: dict) -> dict:
        _only_keys(obj, {"q", "qd", "qdd", "payload", "wrench"})
        q = _vector(obj, "q")
        qd = _vector(obj, "qd", default=[0.0, 0.0, 0.0])
        qdd = _vector(obj, "qdd", default=[0.0, 0.0, 0.0])
        wrench = _vector(obj, "wrench", 6, default=[0.0] * 6)
        dyn = model.dyn
        dyn.set_payload(_payload(obj))
        st = dyn.state(q, qd)
        m, c, g = dyn.mcg(st)
        f = dyn.friction(st.qd)
        tau = m @ np.array(qdd) + c @ st.qd + g + f - dyn.wrench_jacobian(st).T @ np.array(wrench)
        return {"M": m.tolist(), "C": c.tolist(), "G": g.tolist(), "F": f.tolist(),
                "tau": tau.tolist()}
    return _run_lines(args, handle)


def describe(model: RobotModel) -> dict[str, Any]:
    """Everything about the model a user or a tool needs, as one JSON-able object."""
    from rt.model.regressor import Regressor
    from rt.model.workspace import heave_range

    d = model.description
    kin = model.kin
    z_lo, z_hi = heave_range(kin)
    mid = 0.5 * (z_lo + z_hi)
    frames = {
        "B": "base: origin at the base centre, z up; guide i vertical at "
             "base_radius (cos θi, sin θi, 0); q_i = 0 at the bottom of the stroke",
        "Li": "leg i: origin on guide i at the slider, x radial outward, y tangent, z up",
        "Ri": "rod i: origin at the slider's revolute joint, z along the rod to the sphere",
        "P": "platform: origin at the centre of the three spheres, z normal to the platform",
        "S": "ATI sensor: origin at sensor.offset_m in P, axes parallel to P",
    }
    body_frames = {"slider": "Li", "rod": "Ri", "platform": "P", "sensor": "P"}
    bodies = {}
    for name, frame in body_frames.items():
        b = getattr(d.bodies, name)
        bodies[name] = {"mass_kg": b.mass_kg, "com_m": b.com_m, "inertia_kg_m2": b.inertia_kg_m2,
                        "frame": frame, "inertia_about": "COM, axes of " + frame}
    reg = Regressor(model.dyn)
    return {
        "name": d.name,
        "schema_version": d.schema_version,
        "units": "SI (m, kg, s, N, rad)",
        "frames": frames,
        "geometry": d.geometry.model_dump(),
        "limits": d.limits.model_dump(),
        "bodies": bodies,
        "sensor_offset_m": d.sensor.offset_m,
        "drive": {**d.drive.model_dump(), "reflected_inertia_kg": d.drive.reflected_inertia_kg,
                  "force_per_volt_n": d.drive.force_per_volt_n},
        "friction": d.friction.model_dump(),
        "encoder": d.encoder.model_dump(),
        "dac": d.dac.model_dump(),
        "workspace": {
            "heave_level_m": [z_lo, z_hi],
            "home": {"z": mid, "roll": 0.0, "pitch": 0.0, "q": list(kin.ik(mid, 0.0, 0.0).q)},
        },
        "base_parameters": reg.base.describe(),
    }


def _describe(args) -> int:
    try:
        model = _load(args)
    except TalusError as exc:
        print(json.dumps({"error": str(exc)}))
        return 2
    print(json.dumps(describe(model), indent=2))
    return 0


def _demo(args) -> int:
    from rt.model.demo import run_demo

    try:
        model = _load(args)
    except TalusError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    run_demo(model, sys.stdout)
    return 0
