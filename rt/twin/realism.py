"""The rig's imperfections: what the twin simulates and the lab's model does not know.

Two things separate a real rig from the model its controllers use:

1. **Its true parameters differ from the description the lab believes** (``perturbed_truth``):
   bodies are weighed and CAD-estimated to a few per cent, COMs to a centimetre, friction differs
   from axis to axis by tens of per cent (seals, preload, lubrication), rotor inertias by the
   coupling's and screw's own inertia. The default twin runs a truth perturbed from the nominal
   description by a seeded, documented amount (``TruthPerturbation``); ``--truth FILE`` gives
   an explicit one.
2. **Effects the rigid-body model leaves out** (``RigImperfections``), each set from physics
   and datasheet orders of magnitude *before* any comparison with the thesis (none of them is
   fitted to the thesis's figures):

   * current loop (``amplifier_dynamics``): a first-order lag of the truth description's
     ``drive.current_loop_bandwidth_hz`` (analog servo amplifiers in current mode close their
     loop at 1-3 kHz; the nominal file takes 1 kHz) after its transport delay
     ``drive.amplifier_delay_s`` (DAC settling + one 10-20 kHz PWM period ≈ 100 µs). They are
     the amplifier's datasheet figures, so they live in the robot description (the lab's
     model knows them too, and identification uses them); the twin runs its truth's, so a
     truth file with another amplifier is another rig. Off, the current follows the command
     at once;
   * ball-screw transmission: axial stiffness ``screw_stiffness_n_per_m`` between the motor
     (rotor inertia) and the slider: screw shaft E·A/L (16 mm shaft, 0.4 m: ≈ 1e8 N/m) in
     series with nut (≈ 3e8) and support bearings (≈ 4e8), ≈ 6e7 N/m; structural damping ratio
     ``screw_damping_ratio`` 5 %; ``backlash_m`` 20 µm total (a rolled, non-preloaded nut plus
     coupling slack: catalogue values 10-50 µm);
   * friction split across the screw (``motor_side_friction``: half of the friction the lab
     measures at the slider acts on the motor side — the screw's support bearings and the
     nut's preload drag torque — and half on the slider — linear guides and seals); it
     matters once the screw is compliant and backlashed;
   * friction: the Coulomb level ripples with position (``friction_ripple``, ±8 % once per screw
     revolution: nut preload varies with the screw's straightness and the balls' recirculation),
     and viscous and Coulomb levels fall as the grease warms (``viscous_per_k`` −1.5 %/K,
     ``coulomb_per_k`` −0.3 %/K, lubricant viscosity-temperature data) with a first-order
     thermal model per axis (heat capacity of nut + screw ≈ 800 J/K, 0.5 K/W to the air);
   * encoders: rotary encoders on the motor shafts (collocated with the drive: the rig's
     encoders count motor turns, so screw compliance and backlash are *not* seen by them) read
     the position ``encoder_latency_s`` late (latch-to-read on the ISA card ≈ 50 µs);
   * the ATI sensor's output low-pass filter ``ati_filter_hz`` (the Net F/T's selectable IIR
     filters; the lab's setting assumed 150 Hz);
   * a spring-applied holding brake per motor (``brake_holding_force_n`` at the slider:
     a 2 N m brake through a 5 mm lead ≈ 2500 N) that engages ``brake_engage_s`` after the
     drives are disabled (spring brakes: 15-30 ms) and releases ``brake_release_s`` after they
     are enabled again;
   * the ATI's own mass on its measuring side: the tool-side half of the transducer, its
     adapter and the tool tip (``ati_tool_mass_kg`` 0.4 kg, COM ``ati_tool_com_m`` 30 mm
     above the measurement origin) hang on the gauges, so the reading carries their weight,
     turning with the platform's tilt (the product must bias the sensor before force work);
   * the ATI cable, hanging from the platform to a fixed point: its weight share and the
     stiffness of the loop it forms pull the platform down (``cable_weight_n`` 2 N at home,
     ``cable_stiffness_n_per_m`` 30 N/m per metre of heave);
   * a constant offset at each amplifier's input (``amplifier_offset_v``, per axis drawn
     uniformly in ± that amount with ``amplifier_offset_seed``), added while the drives are
     enabled: the PCI-1720's zero-scale error (±1 LSB, 4.9 mV) plus the residual input offset
     of an analog servo amplifier after its balance trim (≈ ±10 mV, drifting with
     temperature) — ±15 mV, i.e. up to ±5 N at the slider (339 N/V). The same term stands for
     a direction asymmetry of the screw's Coulomb friction while an axis slides (lifting vs
     lowering the gravity share through a screw of forward/backward efficiency 0.9/0.8 differs
     by ≈ 4 N): a constant force while moving either way is indistinguishable from it.
     On by default (±15 mV, the identification engineer's value). It was off for a while: the
     supervisor's frozen-encoder check stopped the calibration's shear pushes with it; the
     check now balances each axis' applied force against the measured contact's share and
     the static load (``rt.safety.supervisor``, issue 15). The offset used to tip the hybrid
     force/angle loop into a limit cycle during a shear push's roll against the plate's stuck
     tip (twin figures: 28 Hz, drives saturated both ways, ATI 0-1.4 kN): a margin problem of
     that force law against the plate's stiffness, which its gain schedule on the contact's
     stiffness removed (``rt.control.force``; ``tests/test_force_stiff_contact.py``).

``RigImperfections.none()`` switches every effect off (an ideal twin: for tests of the ideal
physics). Units: SI throughout.
"""
from __future__ import annotations

import math
from functools import lru_cache
from typing import Annotated

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from rt.model.description import RobotDescription, load_description

NonNeg = Annotated[float, Field(ge=0.0, allow_inf_nan=False)]
Fraction = Annotated[float, Field(ge=0.0, lt=1.0, allow_inf_nan=False)]

#: Seed of the default truth: fixed, so every default twin is the same rig.
DEFAULT_TRUTH_SEED = 2012


class RigImperfections(BaseModel):
    """The unmodelled effects the twin simulates (see module docstring for every value's
    reasoning). A zero switches an effect off."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    amplifier_dynamics: bool = True
    screw_stiffness_n_per_m: NonNeg = 6.0e7
    screw_damping_ratio: NonNeg = 0.05
    backlash_m: Annotated[float, Field(ge=0.0, le=0.001)] = 2.0e-5
    motor_side_friction: Fraction = 0.5
    friction_ripple: Fraction = 0.08
    friction_ripple_period_m: Annotated[float, Field(gt=0.0)] = 0.005
    viscous_per_k: Annotated[float, Field(ge=-0.05, le=0.0)] = -0.015
    coulomb_per_k: Annotated[float, Field(ge=-0.05, le=0.0)] = -0.003
    heat_capacity_j_per_k: Annotated[float, Field(gt=0.0)] = 800.0
    thermal_resistance_k_per_w: Annotated[float, Field(gt=0.0)] = 0.5
    initial_temperature_rise_k: Annotated[float, Field(ge=0.0, le=40.0)] = 0.0
    encoder_latency_s: Annotated[float, Field(ge=0.0, le=0.001)] = 5.0e-5
    ati_filter_hz: NonNeg = 150.0
    brake_holding_force_n: NonNeg = 2500.0
    brake_engage_s: NonNeg = 0.02
    brake_release_s: NonNeg = 0.03
    ati_tool_mass_kg: NonNeg = 0.4
    ati_tool_com_m: Annotated[float, Field(ge=0.0, le=0.5)] = 0.03
    cable_weight_n: NonNeg = 2.0
    cable_stiffness_n_per_m: NonNeg = 30.0
    amplifier_offset_v: Annotated[float, Field(ge=0.0, le=0.5, allow_inf_nan=False)] = 0.015
    amplifier_offset_seed: int = 2012

    def amplifier_offsets_v(self) -> np.ndarray:
        """The per-axis amplifier input offsets (V): the seeded draw of the docstring."""
        rng = np.random.default_rng(self.amplifier_offset_seed)
        return self.amplifier_offset_v * rng.uniform(-1.0, 1.0, 3)

    @classmethod
    def none(cls) -> RigImperfections:
        """Every effect off: the ideal twin (rigid, instantaneous, no brake, no cable)."""
        return cls(amplifier_dynamics=False, motor_side_friction=0.0,
                   screw_stiffness_n_per_m=0.0, backlash_m=0.0, friction_ripple=0.0,
                   viscous_per_k=0.0, coulomb_per_k=0.0, encoder_latency_s=0.0,
                   ati_filter_hz=0.0, brake_holding_force_n=0.0, ati_tool_mass_kg=0.0,
                   cable_weight_n=0.0,
                   cable_stiffness_n_per_m=0.0, amplifier_offset_v=0.0)

    @property
    def ideal(self) -> bool:
        return self == RigImperfections.none()


class TruthPerturbation(BaseModel):
    """How far the default truth lies from the nominal description: each quantity is multiplied
    by (1 + u) with u uniform in ±the stated fraction (COMs: shifted by ±``com_m``), drawn from
    one seeded generator. The amounts are what weighing, CAD and catalogue values leave open on
    a built rig."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    mass: Fraction = 0.08              # bodies weighed with their fasteners, cables, grease
    com_m: NonNeg = 0.01               # COM from CAD, ±10 mm
    inertia: Fraction = 0.15           # inertia tensors from CAD of simplified shapes
    viscous: Fraction = 0.30           # per axis: seals, lubrication, preload
    coulomb: Fraction = 0.30
    rotor_inertia: Fraction = 0.15     # coupling and screw inertia on top of the rotor's


def perturbed_truth(nominal: RobotDescription | None = None, seed: int = DEFAULT_TRUTH_SEED,
                    amount: TruthPerturbation | None = None) -> RobotDescription:
    """A description of 'the real rig': ``nominal`` perturbed by ``amount`` with ``seed``."""
    nominal = nominal or load_description()
    amount = amount or TruthPerturbation()
    rng = np.random.default_rng(seed)
    data = nominal.model_dump()

    def scale(frac: float) -> float:
        return 1.0 + float(rng.uniform(-frac, frac))

    for name in ("slider", "rod", "platform", "sensor"):
        body = data["bodies"][name]
        body["mass_kg"] *= scale(amount.mass)
        body["com_m"] = [c + float(rng.uniform(-amount.com_m, amount.com_m))
                         for c in body["com_m"]]
        s = scale(amount.inertia)          # one factor keeps the tensor a physical body's
        body["inertia_kg_m2"] = [[v * s for v in row] for row in body["inertia_kg_m2"]]
    fr = data["friction"]
    fr["viscous_per_axis_n_s_per_m"] = [v * scale(amount.viscous)
                                        for v in nominal.friction.viscous_axes]
    coulomb = [v * scale(amount.coulomb) for v in nominal.friction.coulomb_axes]
    ratio = [s / c if c > 0 else 1.0 for s, c in zip(nominal.friction.static_axes,
                                                        nominal.friction.coulomb_axes)]
    fr["coulomb_per_axis_n"] = coulomb
    fr["static_per_axis_n"] = [c * r for c, r in zip(coulomb, ratio)]
    rotor = nominal.drive.rotor_inertia_per_axis_kg_m2 or [nominal.drive.rotor_inertia_kg_m2] * 3
    data["drive"]["rotor_inertia_per_axis_kg_m2"] = [r * scale(amount.rotor_inertia)
                                                     for r in rotor]
    data["name"] = f"{nominal.name}-truth-seed{seed}"
    return RobotDescription.model_validate(data)


@lru_cache(maxsize=4)
def default_truth() -> RobotDescription:
    """The default twin's truth: the packaged nominal description, perturbed with the default
    seed and amounts."""
    return perturbed_truth(load_description(), DEFAULT_TRUTH_SEED)


def screw_damping_n_s_per_m(imp: RigImperfections, moving_mass_kg: float) -> float:
    """Damping (N s/m) of the screw spring for its damping ratio with ``moving_mass_kg``."""
    return 2.0 * imp.screw_damping_ratio * math.sqrt(imp.screw_stiffness_n_per_m
                                                     * moving_mass_kg)


def add_twin_arguments(parser) -> None:
    """``--truth FILE`` and ``--ideal-twin`` for commands that build a twin."""
    parser.add_argument("--truth", metavar="FILE",
                        help="the twin's own robot description (default: the nominal one "
                             "perturbed by the documented, seeded amount)")
    parser.add_argument("--ideal-twin", action="store_true",
                        help="an ideal twin: no unmodelled effect, truth = the model (or "
                             "--truth), for comparisons")


def twin_setup(args, model: RobotDescription | None = None
               ) -> tuple[RobotDescription | None, RigImperfections | None]:
    """(truth, imperfections) from ``add_twin_arguments``' options; ``None`` = the defaults.
    ``model`` (a ``--robot`` description) is what the twin is a twin of: its truth is ``model``
    perturbed by the default amount (the model itself with ``--ideal-twin``) unless ``--truth``
    names one."""
    truth = load_description(args.truth) if args.truth else None
    if args.ideal_twin:
        return truth or model or load_description(), RigImperfections.none()
    if truth is None and model is not None:
        truth = perturbed_truth(model, DEFAULT_TRUTH_SEED)
    return truth, None
