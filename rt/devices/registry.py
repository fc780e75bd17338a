"""Backends picked by name from config, imported lazily (CONVENTIONS item 1).

A machine without comedilib, an ISA card or a camera never imports their modules; choosing such
a backend there gives one clear ``BackendUnavailableError``.
"""
from __future__ import annotations

import importlib
from typing import Any

from rt.errors import BackendUnavailableError, ConfigurationError

#: kind -> backend name -> "module:Class". Modules are imported only when chosen.
BACKENDS: dict[str, dict[str, str]] = {
    "encoders": {
        "pcl833": "rt.drivers.pcl833:Pcl833Encoders",
        "sim": "rt.twin.backends:TwinEncoders",
        "twin_shm": "rt.twin.shm_backends:ShmEncoders",
    },
    "actuators": {
        "pci1720": "rt.drivers.pci1720:Pci1720Outputs",
        "sim": "rt.twin.backends:TwinActuators",
        "twin_shm": "rt.twin.shm_backends:ShmActuators",
    },
    "force_torque": {
        "ati_rdt": "rt.ati.rdt_client:RdtForceTorqueSensor",
        "ati_can": "rt.ati.can_client:AtiCanForceTorqueSensor",
        "sim": "rt.twin.backends:TwinForceTorque",
        "twin_shm": "rt.twin.shm_backends:ShmForceTorque",
    },
    "force_plate": {},
    "camera": {
        "opencv": "rt.drivers.camera_cv:OpenCvCamera",
        "synthetic": "rt.drivers.synthetic_frames:SyntheticMarkerCamera",
    },
    "amplifier_monitor": {
        "comedi_ai": "rt.drivers.comedi_ai:ComediAmplifierMonitor",
    },
    "digital_inputs": {
        "comedi": "rt.drivers.comedi_dio:ComediDigitalInputs",
        "sim": "rt.twin.backends:TwinDigitalInputs",
        "twin_shm": "rt.twin.shm_backends:ShmDigitalInputs",
    },
}


def register_backend(kind: str, name: str, target: str) -> None:
    """Register ``target`` ("package.module:ClassName") as backend ``name`` of device ``kind``."""
    if kind not in BACKENDS:
        raise ConfigurationError(f"unknown device kind {kind!r}; known: {sorted(BACKENDS)}")
    if ":" not in target:
        raise ConfigurationError(f"backend target {target!r} must look like 'module:Class'")
    BACKENDS[kind][name] = target


def backend_class(kind: str, name: str) -> type:
    """Import and return the class of backend ``name`` for device ``kind``."""
    if kind not in BACKENDS:
        raise ConfigurationError(f"unknown device kind {kind!r}; known: {sorted(BACKENDS)}")
    try:
        target = BACKENDS[kind][name]
    except KeyError:
        raise ConfigurationError(
            f"no {kind} backend named {name!r}; known: {sorted(BACKENDS[kind])}") from None
    module_name, _, class_name = target.partition(":")
    try:
        module = importlib.import_module(module_name)
    except (ImportError, OSError) as exc:
        raise BackendUnavailableError(
            f"{kind} backend {name!r} is unavailable on this machine: {exc}") from exc
    return getattr(module, class_name)


def create(kind: str, name: str, **config: Any):
    """Instantiate backend ``name`` of ``kind`` with ``config`` keyword arguments."""
    return backend_class(kind, name)(**config)
