"""Force-plate description files (YAML, ``schema_version: 1``) and the plate's geometry.

Frames and conventions (used everywhere in ``calibration``):

* Plate frame F: origin at the centre of the working surface, x and y in the surface (x along
  ``size_m[0]``), z normal to it pointing *into* the plate (the direction a load presses).
  This is the AMTI/C3D force-plate convention.
* Transducer origin O: ``origin_m`` in F (z ≥ 0: below the surface), the point about which the
  plate's moments are reported.
* A plate's output is the wrench *applied to the plate* ``w = (Fx, Fy, Fz, Mx, My, Mz)``
  (N, N·m), in F's axes, moments about O. A load pressing the surface has Fz > 0.
* Channels: raw values ``v`` (V, or whatever ``unit`` says), ``w = C v`` with
  ``C = nominal_matrix · diag(scale)`` (6 × N).

Kinds: ``six_channel`` (F = C·V, AMTI-like; 6 channels, a 6×6 matrix), ``kistler8`` (eight
piezo channels fx12, fx34, fy14, fy23, fz1..fz4; the matrix follows from the sensor offsets
a, b, az0 of the Kistler manual when not given), ``linear_n`` (any N ≥ 6 channels and a 6×N
matrix).
"""
from __future__ import annotations

import hashlib
import math
from enum import StrEnum
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, PrivateAttr, model_validator

from calibration import yaml_files
from rt.errors import ConfigurationError

Finite = Annotated[float, Field(allow_inf_nan=False)]
Positive = Annotated[float, Field(gt=0.0, allow_inf_nan=False)]
#: Components of a wrench, in the order of every 6-vector and matrix row here.
WRENCH_AXES = ("Fx", "Fy", "Fz", "Mx", "My", "Mz")
KISTLER_CHANNELS = ("fx12", "fx34", "fy14", "fy23", "fz1", "fz2", "fz3", "fz4")


class PlateKind(StrEnum):
    SIX_CHANNEL = "six_channel"
    KISTLER8 = "kistler8"
    LINEAR_N = "linear_n"


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class Channel(_Model):
    """One analog channel: its label, unit, the factor to the matrix's input unit and the
    DAQ input range (± range, in ``unit``)."""

    label: str = Field(min_length=1)
    unit: str = "V"
    scale: Positive = 1.0
    range: Positive = 10.0


class KistlerGeometry(_Model):
    """Sensor offsets from the Kistler manual (m): a along x, b along y, az0 the depth of the
    sensor plane below the surface (positive)."""

    a_m: Positive
    b_m: Positive
    az0_m: Annotated[float, Field(ge=0.0, allow_inf_nan=False)]


class PlateDescription(_Model):
    """A force plate, as written from its manual or calibration sheet (module docstring)."""

    schema_version: Literal[1]
    name: str = Field(min_length=1)
    manufacturer: str = ""
    model: str = ""
    serial: str = ""
    kind: PlateKind
    channels: list[Channel] = Field(min_length=6, max_length=64)
    size_m: tuple[Positive, Positive]
    origin_m: tuple[Finite, Finite, Annotated[float, Field(ge=0.0, allow_inf_nan=False)]]
    force_range_n: tuple[Positive, Positive, Positive]
    moment_range_nm: tuple[Positive, Positive, Positive]
    sample_rate_hz: Annotated[float, Field(gt=0.0, le=100_000.0)] = 1000.0
    nominal_matrix: list[list[Finite]] | None = None
    kistler: KistlerGeometry | None = None
    _sha256: str = PrivateAttr(default="")

    @model_validator(mode="after")
    def _consistent(self) -> PlateDescription:
        n = len(self.channels)
        if self.kind == PlateKind.SIX_CHANNEL and n != 6:
            raise ValueError(f"channels: a six_channel plate has 6 channels, got {n}")
        if self.kind == PlateKind.KISTLER8:
            if n != 8:
                raise ValueError(f"channels: a kistler8 plate has 8 channels, got {n}")
            if self.kistler is None and self.nominal_matrix is None:
                raise ValueError("kistler: a kistler8 plate needs its sensor offsets "
                                 "(a_m, b_m, az0_m) or a nominal_matrix")
        elif self.nominal_matrix is None:
            raise ValueError(f"nominal_matrix: required for a {self.kind.value} plate "
                             f"(6 rows of {n} values)")
        if self.nominal_matrix is not None:
            rows = self.nominal_matrix
            if len(rows) != 6 or any(len(r) != n for r in rows):
                raise ValueError(f"nominal_matrix: must be 6 rows of {n} values (one per "
                                 f"channel), got {len(rows)} rows of "
                                 f"{sorted({len(r) for r in rows})} values")
            if np.linalg.matrix_rank(np.array(rows)) < 6:
                raise ValueError("nominal_matrix: rank < 6: some wrench component cannot be "
                                 "measured; check the matrix")
        if abs(self.origin_m[0]) > self.size_m[0] / 2 or abs(self.origin_m[1]) > self.size_m[1] / 2:
            raise ValueError("origin_m: the transducer origin lies outside the plate's outline")
        return self

    # ------------------------------------------------------------------ derived
    @property
    def n_channels(self) -> int:
        return len(self.channels)

    @property
    def sha256(self) -> str:
        """sha256 of the file it was read from ("" when built in memory)."""
        return self._sha256

    def matrix_without_scales(self) -> np.ndarray:
        """The 6×N matrix in the channels' scaled unit (as written, or from Kistler geometry)."""
        if self.nominal_matrix is not None:
            return np.array(self.nominal_matrix, dtype=float)
        assert self.kistler is not None
        return kistler_matrix(self.kistler)

    def nominal_C(self) -> np.ndarray:
        """C (6 × N): wrench (N, N·m, about O, axes of F) = C · raw channels."""
        return self.matrix_without_scales() * np.array([c.scale for c in self.channels])

    def full_scale(self) -> np.ndarray:
        """Full scale per wrench axis (N, N·m): the figures %FS refers to."""
        return np.array([*self.force_range_n, *self.moment_range_nm], dtype=float)

    def corners_F(self) -> np.ndarray:
        """The surface corners in F (4 × 3, m), C3D order: +x+y, -x+y, -x-y, +x-y."""
        hx, hy = self.size_m[0] / 2, self.size_m[1] / 2
        return np.array([[hx, hy, 0.0], [-hx, hy, 0.0], [-hx, -hy, 0.0], [hx, -hy, 0.0]])

    def channel_labels(self) -> list[str]:
        return [c.label for c in self.channels]

    def channel_ranges(self) -> np.ndarray:
        return np.array([c.range for c in self.channels], dtype=float)

    def record_entry(self) -> dict:
        """The ``plate`` block of the calibration record."""
        return {"name": self.name, "manufacturer": self.manufacturer, "model": self.model,
                "serial": self.serial, "kind": self.kind.value, "size_m": list(self.size_m),
                "corners_m": self.corners_F().tolist(), "origin_m": list(self.origin_m),
                "force_range_n": list(self.force_range_n),
                "moment_range_nm": list(self.moment_range_nm),
                "channel_labels": self.channel_labels(),
                "sample_rate_hz": self.sample_rate_hz, "description_sha256": self.sha256}


def kistler_matrix(g: KistlerGeometry) -> np.ndarray:
    """Kistler eight-channel outputs → wrench about O (the surface point above the sensor
    centre, at depth az0), from the Kistler manual's formulas:

    Fx = fx12 + fx34; Fy = fy14 + fy23; Fz = fz1 + fz2 + fz3 + fz4;
    Mx = b (fz1 + fz2 - fz3 - fz4); My = a (-fz1 + fz2 + fz3 - fz4);
    Mz = b (-fx12 + fx34) + a (fy14 - fy23).
    Moments are about the sensors' plane; O is the origin of that plane.
    """
    a, b = g.a_m, g.b_m
    return np.array([
        [1, 1, 0, 0, 0, 0, 0, 0],
        [0, 0, 1, 1, 0, 0, 0, 0],
        [0, 0, 0, 0, 1, 1, 1, 1],
        [0, 0, 0, 0, b, b, -b, -b],
        [0, 0, 0, 0, -a, a, a, -a],
        [-b, b, a, -a, 0, 0, 0, 0],
    ], dtype=float)


def load_plate(path: str | Path) -> PlateDescription:
    """Read a plate description; ConfigurationError naming the file, line and field."""
    p = Path(path)
    plate = yaml_files.load(PlateDescription, p)
    plate._sha256 = hashlib.sha256(p.read_bytes()).hexdigest()
    return plate


#: The twin's plate (AMTI-like six-channel), shipped with the package.
TWIN_PLATE_FILE = Path(__file__).resolve().parent / "data" / "twin_plate.yaml"


def cop_F(wrench: np.ndarray, origin_m: np.ndarray | tuple) -> tuple[np.ndarray, np.ndarray]:
    """Centre of pressure on the surface (z = 0 of F) and free moment, from wrenches about O.

    Args:
        wrench: (..., 6) applied wrenches (N, N·m) about O, axes of F.
        origin_m: O in F (m).

    Returns:
        (cop (..., 2) in m, tz (...,) in N·m); NaN where Fz ≤ 0.
    """
    w = np.asarray(wrench, dtype=float)
    ox, oy, oz = (float(v) for v in origin_m)
    fx, fy, fz, mx, my, mz = (w[..., k] for k in range(6))
    with np.errstate(divide="ignore", invalid="ignore"):
        fz_safe = np.where(fz > 0.0, fz, math.nan)
        # M = (p - O) x F with p = (px, py, 0): Mx = (py-oy) Fz + oz Fy, My = -oz Fx - (px-ox) Fz
        px = ox + (-my - oz * fx) / fz_safe
        py = oy + (mx - oz * fy) / fz_safe
    tz = mz - ((px - ox) * fy - (py - oy) * fx)
    return np.stack([px, py], axis=-1), tz


def wrench_at_point(force_F: np.ndarray, point_F: np.ndarray, origin_m, tz: float | np.ndarray = 0.0
                    ) -> np.ndarray:
    """The wrench about O of forces (..., 3) applied at points (..., 3) of F, plus a free
    moment ``tz`` about z (N·m)."""
    f = np.asarray(force_F, dtype=float)
    r = np.asarray(point_F, dtype=float) - np.asarray(origin_m, dtype=float)
    m = np.cross(r, f)
    m[..., 2] += tz
    return np.concatenate([f, m], axis=-1)


def require_file(path: Path, what: str) -> None:
    if not path.is_file():
        raise ConfigurationError(f"{path}: no such {what} file")
