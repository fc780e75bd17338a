"""Ground-reaction-force records for gait replay: reading (C3D, CSV), stance selection, and a
published-shape walking force for tests and the shipped library.

Records
    :class:`GroundReactionForce` holds times (s, from the record's first sample) and forces (N):
    ``fz`` vertical, loading positive (the foot pressing down = the platform pushing up into the
    foot), ``fx``/``fy`` horizontal when the record has them.

CSV (``read_grf_csv``)
    Header ``t,fz`` or ``t,fz,fx,fy`` (s, N), one sample per row, ``#`` comment lines and blank
    lines ignored, times strictly increasing (any sampling; resampled later). Every value must
    be a finite number.

C3D (``read_grf_c3d``, needs ezc3d)
    The force platform ``plate_index`` (0-based, FORCE_PLATFORM order) as ezc3d extracts it:
    ezc3d maps FORCE_PLATFORM:CHANNEL to the analog channels, applies ANALOG:SCALE, GEN_SCALE,
    OFFSET and, for type-4 plates, FORCE_PLATFORM:CAL_MATRIX, and expresses the force in the
    lab frame, whose z is taken as vertical. Sampled at ANALOG:RATE. Plates report the force
    *on the plate*, negative in z for most lab frames; the sign of all three components is
    flipped when the record's largest |Fz| is negative, so the loading is positive. The force
    channels' ANALOG:UNITS must be N (or unset, taken as N); other units are refused. A file
    shorter than its header says is refused as truncated (ezc3d would silently read the frames
    present).

Stance selection (``select_stance``)
    by threshold: the ``occurrence``-th run of consecutive samples with Fz > threshold (a run
    touching the record's first or last sample is incomplete and refused); or an explicit
    [start_s, end_s] window. The selected stance's time starts at 0.

Published shape (``walking_grf_bw``)
    The double-hump vertical force of walking at normal speed, in body weights (BW) against the
    stance fraction s ∈ [0, 1]: 0 at heel strike, first peak 1.15 BW at s = 0.25 (loading
    response), valley 0.75 BW at s = 0.5 (mid-stance), second peak 1.15 BW at s = 0.75 (push
    off), 0 at toe off; stance 0.64 s (0.6-0.7 s at normal walking speed; 0.64 puts the
    landmarks on 2 ms samples). Landmarks joined by cubic smoothsteps (C¹: the landmarks are
    the exact extrema, the slope is continuous, zero at heel strike and toe off).
    Horizontal components: anterior-posterior ±0.20 BW (braking then propulsion),
    medial-lateral 0.05 BW. Source type: textbook values — the typical figures of gait-analysis
    textbooks (e.g. Perry & Burnfield, *Gait Analysis*; Winter, *Biomechanics and Motor Control
    of Human Movement*), not a measured subject; real records have a sharper heel-strike rise.
"""
from __future__ import annotations

import csv
import math
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rt.errors import BackendUnavailableError, ProtocolValidationError

STANDARD_GRAVITY_M_S2 = 9.80665
MIN_SAMPLES = 4
#: Vertical force landmarks of walking: (stance fraction, body weights).
WALKING_FZ_LANDMARKS_BW = ((0.0, 0.0), (0.25, 1.15), (0.5, 0.75), (0.75, 1.15), (1.0, 0.0))
WALKING_AP_PEAK_BW = 0.20
WALKING_ML_PEAK_BW = 0.05
WALKING_STANCE_S = 0.64
# max of sin(2πs) sin(πs) = 2 sin²(πs) cos(πs) on [0, 1]: 4/(3√3) at cos(πs) = 1/√3.
_AP_SHAPE_MAX = 4.0 / (3.0 * math.sqrt(3.0))


@dataclass(frozen=True)
class GroundReactionForce:
    """A force record: ``t`` (s), ``fz`` (N, loading positive), ``fx``/``fy`` (N) or None."""

    t: np.ndarray
    fz: np.ndarray
    fx: np.ndarray | None
    fy: np.ndarray | None
    source: str

    @property
    def has_shear(self) -> bool:
        return self.fx is not None and self.fy is not None

    @property
    def duration_s(self) -> float:
        return float(self.t[-1] - self.t[0])


def _refuse(source: str, reason: str, line: int | None = None) -> ProtocolValidationError:
    where = f"{source}, line {line}" if line is not None else source
    return ProtocolValidationError(f"{where}: {reason}")


# ------------------------------------------------------------------------------ CSV
_CSV_HEADERS = (("t", "fz"), ("t", "fz", "fx", "fy"))


def read_grf_csv(path: str | Path) -> GroundReactionForce:
    """Read a ``t,fz[,fx,fy]`` CSV strictly (module docstring); raises ProtocolValidationError."""
    src = str(path)
    try:
        with open(path, newline="", encoding="utf-8") as f:
            rows = list(csv.reader(f))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise _refuse(src, f"cannot read the file ({exc})") from None
    numbered = [(i + 1, r) for i, r in enumerate(rows)
                if r and any(c.strip() for c in r) and not r[0].lstrip().startswith("#")]
    if not numbered:
        raise _refuse(src, "the file is empty (no header, no samples)")
    line, first = numbered[0]
    header = tuple(c.strip().lower() for c in first)
    if header not in _CSV_HEADERS:
        raise _refuse(src, f"the header must be 't,fz' or 't,fz,fx,fy' (s, N); got "
                      f"{','.join(c.strip() for c in first)!r}", line)
    data = numbered[1:]
    if len(data) < MIN_SAMPLES:
        raise _refuse(src, f"at least {MIN_SAMPLES} samples are needed (got {len(data)})")
    values = np.empty((len(data), len(header)))
    for k, (line, row) in enumerate(data):
        if len(row) != len(header):
            raise _refuse(src, f"expected {len(header)} columns ({','.join(header)}), got "
                          f"{len(row)}", line)
        for j, (text, name) in enumerate(zip(row, header)):
            try:
                v = float(text)
            except ValueError:
                raise _refuse(src, f"column {name!r}: {text.strip()!r} is not a number",
                              line) from None
            if not math.isfinite(v):
                raise _refuse(src, f"column {name!r}: {text.strip()} is not a finite number "
                              "(gaps must be filled before replay)", line)
            values[k, j] = v
        if k > 0 and not values[k, 0] > values[k - 1, 0]:
            raise _refuse(src, f"time {float(values[k, 0])!r} s is not after the previous "
                          f"sample's {float(values[k - 1, 0])!r} s: times must increase strictly",
                          line)
    t = values[:, 0] - values[0, 0]
    shear = len(header) == 4
    return GroundReactionForce(t, values[:, 1].copy(), values[:, 2].copy() if shear else None,
                               values[:, 3].copy() if shear else None, src)


def write_grf_csv(path: str | Path, grf: GroundReactionForce, comments: tuple[str, ...] = ()
                  ) -> None:
    """Write a record in the CSV format ``read_grf_csv`` reads (µs and 0.1 mN resolution)."""
    with open(path, "w", encoding="utf-8", newline="") as f:
        for c in comments:
            f.write(f"# {c}\n")
        if grf.fx is not None and grf.fy is not None:
            f.write("t,fz,fx,fy\n")
            for t, fz, fx, fy in zip(grf.t, grf.fz, grf.fx, grf.fy):
                f.write(f"{t:.6f},{fz:.4f},{fx:.4f},{fy:.4f}\n")
        else:
            f.write("t,fz\n")
            for t, fz in zip(grf.t, grf.fz):
                f.write(f"{t:.6f},{fz:.4f}\n")


# ------------------------------------------------------------------------------ C3D
_C3D_MAGIC = 0x50


def _header_frames(head: bytes) -> int | None:
    """Frame count the C3D header declares (None when it cannot say: > 65535 frames)."""
    param_block = head[0]
    if param_block != 2:
        return None  # non-standard layout: leave the check to ezc3d
    # Word order follows the processor type (parameter section byte 4: 84 Intel, 85 DEC, 86 MIPS).
    proc = head[512 + 3] if len(head) >= 516 else 84
    fmt = ">HH" if proc == 86 else "<HH"
    first, last = struct.unpack_from(fmt, head, 6)
    if last == 0xFFFF:
        return None
    return last - first + 1


def _force_unit(params: object, plate_index: int) -> str:
    """ANALOG:UNITS of the plate's force channels ("" when the file does not say).

    ezc3d reports every plate's force unit as "N" whatever the channels hold, so the units are
    read here: FORCE_PLATFORM:CHANNEL (1-based analog indices, one column per plate) lists the
    force channels first — 8 of them for a type-3 plate, 3 for the other types.
    """
    fp = params["FORCE_PLATFORM"]  # type: ignore[index]
    channels = np.asarray(fp["CHANNEL"]["value"])
    types = np.asarray(fp["TYPE"]["value"]).ravel()
    if channels.ndim != 2 or plate_index >= channels.shape[1]:
        return ""
    n_force = 8 if plate_index < types.size and int(types[plate_index]) == 3 else 3
    analog = params["ANALOG"]  # type: ignore[index]
    units = list(analog["UNITS"]["value"]) if "UNITS" in analog else []
    found = {str(units[c - 1]).strip() for c in channels[:n_force, plate_index]
             if 0 < c <= len(units)}
    if len(found) > 1:
        return "/".join(sorted(found))
    return found.pop() if found else ""


def read_grf_c3d(path: str | Path, plate_index: int) -> GroundReactionForce:
    """Read force platform ``plate_index`` of a C3D file (module docstring).

    Raises:
        ProtocolValidationError: not a C3D file, truncated, unreadable, no such plate, unit not
            N, non-finite samples.
        BackendUnavailableError: ezc3d is not installed.
    """
    src = str(path)
    try:
        with open(path, "rb") as f:
            head = f.read(1024)
    except OSError as exc:
        raise _refuse(src, f"cannot read the file ({exc.strerror})") from None
    if len(head) < 512:
        raise _refuse(src, f"not a C3D file: {len(head)} bytes, shorter than the 512-byte C3D "
                      "header")
    if head[1] != _C3D_MAGIC:
        raise _refuse(src, f"not a C3D file: byte 2 is 0x{head[1]:02X} where a C3D header "
                      f"has 0x{_C3D_MAGIC:02X}")
    try:
        import ezc3d  # noqa: PLC0415 - optional dependency, imported only when a C3D is read
    except ImportError as exc:
        raise BackendUnavailableError(f"{src}: reading C3D files needs ezc3d "
                                      f"(pip install 'ezc3d>=1.5,<2'): {exc}") from None
    try:
        c3d = ezc3d.c3d(src, extract_forceplat_data=True)
    except Exception as exc:  # ezc3d raises OSError/RuntimeError/IndexError on bad files
        raise _refuse(src, f"ezc3d cannot read it as C3D: {exc}") from None
    params = c3d["parameters"]
    if "FORCE_PLATFORM" not in params or "USED" not in params["FORCE_PLATFORM"]:
        raise _refuse(src, "the file has no FORCE_PLATFORM parameters: no force plate to read")
    used = np.asarray(params["FORCE_PLATFORM"]["USED"]["value"]).ravel()
    n_used = int(used[0]) if used.size else 0
    platforms = c3d["data"]["platform"]
    if n_used == 0 or not platforms:
        raise _refuse(src, "the file has no force platform (FORCE_PLATFORM:USED = 0)")
    if not 0 <= plate_index < len(platforms):
        raise _refuse(src, f"plate_index {plate_index}: the file has {len(platforms)} force "
                      f"platform(s) (FORCE_PLATFORM:USED = {n_used}); valid indices 0.."
                      f"{len(platforms) - 1}")
    rate_values = np.asarray(params["ANALOG"]["RATE"]["value"]).ravel()
    rate = float(rate_values[0]) if rate_values.size else 0.0
    if not (math.isfinite(rate) and rate > 0.0):
        raise _refuse(src, f"ANALOG:RATE must be > 0 Hz (got {rate})")
    pf = platforms[plate_index]
    unit = _force_unit(params, plate_index)
    if unit not in ("N", ""):
        raise _refuse(src, f"force platform {plate_index}: force unit {unit!r} is not supported "
                      "(ANALOG:UNITS of its force channels must be 'N')")
    force = np.asarray(pf["force"], dtype=float)
    n = force.shape[1]
    declared = _header_frames(head)
    points = c3d["header"]["points"]
    read_frames = int(points["last_frame"]) - int(points["first_frame"]) + 1
    if declared is not None and read_frames < declared:
        raise _refuse(src, f"the file is truncated: its header declares {declared} frames but "
                      f"only {read_frames} could be read")
    if n < MIN_SAMPLES:
        raise _refuse(src, f"force platform {plate_index}: {n} samples, at least {MIN_SAMPLES} "
                      "needed")
    bad = np.argwhere(~np.isfinite(force))
    if bad.size:
        axis, k = bad[0]
        raise _refuse(src, f"force platform {plate_index}: F{'xyz'[axis]} is not a finite number "
                      f"at analog sample {k} (t = {k / rate:.4f} s); gaps must be filled before "
                      "replay")
    fx, fy, fz = force
    if -fz.min() > fz.max():  # force on the plate: flip so the loading is positive
        fx, fy, fz = -fx, -fy, -fz
    t = np.arange(n) / rate
    return GroundReactionForce(t, fz.copy(), fx.copy(), fy.copy(), src)


def read_grf(path: str | Path, plate_index: int | None = None) -> GroundReactionForce:
    """Read a C3D (``plate_index`` required) or CSV record, by the file's suffix."""
    p = Path(path)
    if p.suffix.lower() == ".c3d":
        if plate_index is None:
            raise _refuse(str(p), "a C3D source needs plate_index")
        return read_grf_c3d(p, plate_index)
    if p.suffix.lower() == ".csv":
        return read_grf_csv(p)
    raise _refuse(str(p), "a gait record must be a .c3d or .csv file")


# ------------------------------------------------------------------------------ stance
def select_stance(grf: GroundReactionForce, *, threshold_n: float | None = None,
                  occurrence: int = 0, start_s: float | None = None,
                  end_s: float | None = None) -> GroundReactionForce:
    """The stance to replay (module docstring), its time starting at 0.

    Give either ``threshold_n`` (N; with ``occurrence``, 0 = first) or ``start_s`` and ``end_s``
    (s from the record's first sample).
    """
    src, t, fz = grf.source, grf.t, grf.fz
    if threshold_n is not None:
        above = fz > threshold_n
        edges = np.diff(np.concatenate(([0], above.astype(np.int8), [0])))
        starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
        if starts.size == 0:
            raise _refuse(src, f"empty stance: no sample of Fz exceeds the threshold "
                          f"{threshold_n:g} N (the record peaks at {fz.max():.1f} N)")
        if occurrence >= starts.size:
            raise _refuse(src, f"stance occurrence {occurrence}: the record has only "
                          f"{starts.size} stance(s) above {threshold_n:g} N")
        i0, i1 = int(starts[occurrence]), int(ends[occurrence])
        if i0 == 0 or i1 == fz.size - 1:
            which = "start" if i0 == 0 else "end"
            raise _refuse(src, f"the stance at t = {t[i0]:.3f} .. {t[i1]:.3f} s touches the "
                          f"{which} of the record: it is incomplete (select it explicitly with "
                          "stance.select: explicit if it is what you want)")
    elif start_s is not None and end_s is not None:
        if start_s < t[0] or end_s > t[-1]:
            raise _refuse(src, f"the stance window {start_s:g} .. {end_s:g} s is outside the "
                          f"record ({t[0]:g} .. {t[-1]:g} s)")
        idx = np.flatnonzero((t >= start_s) & (t <= end_s))
        if idx.size == 0:
            raise _refuse(src, f"empty stance: no sample between {start_s:g} and {end_s:g} s")
        i0, i1 = int(idx[0]), int(idx[-1])
    else:
        raise ValueError("give threshold_n, or start_s and end_s")
    if i1 - i0 + 1 < MIN_SAMPLES:
        raise _refuse(src, f"the stance at t = {t[i0]:.3f} .. {t[i1]:.3f} s has "
                      f"{i1 - i0 + 1} samples; at least {MIN_SAMPLES} are needed")
    sl = slice(i0, i1 + 1)
    return GroundReactionForce(t[sl] - t[i0], fz[sl].copy(),
                               None if grf.fx is None else grf.fx[sl].copy(),
                               None if grf.fy is None else grf.fy[sl].copy(), src)


# ------------------------------------------------------------------------------ published shape
def _smoothstep_through(s: np.ndarray, landmarks: tuple[tuple[float, float], ...]) -> np.ndarray:
    xs = np.array([p[0] for p in landmarks])
    ys = np.array([p[1] for p in landmarks])
    s = np.clip(s, xs[0], xs[-1])
    i = np.clip(np.searchsorted(xs, s, side="right") - 1, 0, xs.size - 2)
    u = (s - xs[i]) / (xs[i + 1] - xs[i])
    return ys[i] + (ys[i + 1] - ys[i]) * u * u * (3.0 - 2.0 * u)


def walking_grf_bw(s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Published-shape walking force (module docstring) at stance fractions ``s``, in BW.

    Returns (fz, fx, fy): vertical, anterior-posterior (negative = braking), medial-lateral.
    Zero outside [0, 1].
    """
    s = np.asarray(s, dtype=float)
    inside = (s >= 0.0) & (s <= 1.0)
    fz = np.where(inside, _smoothstep_through(s, WALKING_FZ_LANDMARKS_BW), 0.0)
    sin1 = np.sin(math.pi * np.clip(s, 0.0, 1.0))
    fx = np.where(inside, -WALKING_AP_PEAK_BW / _AP_SHAPE_MAX
                  * np.sin(2.0 * math.pi * np.clip(s, 0.0, 1.0)) * sin1, 0.0)
    fy = np.where(inside, WALKING_ML_PEAK_BW * sin1 * sin1, 0.0)
    return fz, fx, fy


def walking_grf(body_weight_kg: float = 70.0, stance_s: float = WALKING_STANCE_S,
                rate_hz: float = 500.0, pad_s: float = 0.1) -> GroundReactionForce:
    """One published-shape stance (N) for a subject of ``body_weight_kg``, sampled at
    ``rate_hz``, with ``pad_s`` of unloaded samples before heel strike and after toe off."""
    n = int(round((stance_s + 2.0 * pad_s) * rate_hz)) + 1
    t = np.arange(n) / rate_hz
    fz, fx, fy = walking_grf_bw((t - pad_s) / stance_s)
    w = body_weight_kg * STANDARD_GRAVITY_M_S2
    return GroundReactionForce(t, fz * w, fx * w, fy * w, "<published walking shape>")
