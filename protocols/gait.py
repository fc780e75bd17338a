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
    OFFSET and, for type-4 plates, FORCE_PLATFORM:CAL_MATRIX to the pre-calibration channels,
    and expresses the force in the lab frame, whose z is taken as vertical. Plate types 2, 3
    (Kistler, 8 channels) and 4 are read; other types are refused by name. Sampled at
    ANALOG:RATE.

    Units are decided by physics, not by labels: real files label data in N as ``V``, ``nt`` or
    ``Newtons`` and type-4 pre-calibration channels as ``N``, so ANALOG:UNITS is only quoted in
    messages. The generator checks that the stance's vertical peak is plausible against the
    subject's body mass (:func:`check_plausible_peak`): PROCESSING:Bodymass (kg) when the file
    has it (``body_mass_kg``), else the protocol's ``source_body_weight_kg``.

    The plate's unloaded offset is removed (:func:`quiet_baseline`): the median of each
    component over the record's quiet stretches (windows of ``QUIET_WINDOW_S`` whose Fz is
    steady, at the lowest steady level — a foot only adds load), reported as ``offset_n``.
    Plates report the force *on the plate*, negative in z for most lab frames; the sign of all
    three components is then flipped when the record's largest |Fz| is negative, so the loading
    is positive. A file shorter than its header says is refused as truncated (ezc3d would
    silently read the frames present).

Traceability
    Every record carries the sha256 of its source file, the plate index, the offset removed and
    the body mass the file states (``GroundReactionForce`` fields); the stance keeps its window
    in record time (``start_s``) and its contact instants (``contact_s``).

Stance selection (``select_stance``)
    by threshold: the ``occurrence``-th run of consecutive samples with Fz > threshold (a run
    touching the record's first or last sample is incomplete and refused), widened to the true
    contact (back and forward while Fz stays above the contact level, ``CONTACT_LEVEL_N`` or 4σ
    of the quiet noise) and then by ``lead_s`` of unloaded record on both sides, so the replay
    starts before heel strike and ends after toe off: the heel-strike transient (a 0.5 BW spike
    within 10 ms of contact in real records) is replayed whole, and the replay's tapers act on
    the unloaded lead-in. Or an explicit [start_s, end_s] window, taken as given. The selected
    stance's time starts at 0.

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
import hashlib
import io
import math
import struct
from dataclasses import dataclass, replace
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
#: Plate types read (C3D: 2 = six channels in N/N·mm, 3 = Kistler 8 channels, 4 = type 2 with
#: a CAL_MATRIX applied to pre-calibration channels). Others are refused by name.
SUPPORTED_PLATE_TYPES = (2, 3, 4)
#: Quiet-baseline windows (s) and the steadiness they need: Fz standard deviation within a
#: window at most max(QUIET_STD_N, 3 × the steadiest window's).
QUIET_WINDOW_S = 0.05
QUIET_STD_N = 2.0
#: ... and never above this (N): a record whose steadiest window moves more has no quiet one.
QUIET_MAX_STD_N = 10.0
#: A quiet level with samples this far below it (N, or 8σ) was a loaded stretch, not the
#: unloaded plate (a plate reads no less than unloaded, but for noise and ringing).
FLOOR_TOLERANCE_N = 10.0
#: Contact: Fz above this (N, offset removed) or above 4σ of the quiet noise, whichever is larger.
CONTACT_LEVEL_N = 5.0
#: A stance's vertical peak in body weights: walking peaks at 1.0-1.3 BW, running at 2-3 BW; a
#: careful or assisted step still loads ≥ 0.5 BW. Outside, the units are wrong (lbf reads
#: 0.22×, kgf 0.10×, kN 0.001× the force in N) or the body mass is not the subject's.
PLAUSIBLE_PEAK_BW = (0.5, 3.0)
#: Unloaded record kept before contact beyond the replay's taper (s, record time).
LEAD_MARGIN_S = 0.02
# max of sin(2πs) sin(πs) = 2 sin²(πs) cos(πs) on [0, 1]: 4/(3√3) at cos(πs) = 1/√3.
_AP_SHAPE_MAX = 4.0 / (3.0 * math.sqrt(3.0))


@dataclass(frozen=True)
class GroundReactionForce:
    """A force record: ``t`` (s), ``fz`` (N, loading positive), ``fx``/``fy`` (N) or None.

    Traceability (module docstring): ``sha256`` of the source file, ``plate_index`` (C3D),
    ``offset_n`` removed (fx, fy, fz in N, as read: force on the plate; ``offset_measured``
    False when the record has no unloaded stretch and nothing was removed), ``noise_n`` (σ of Fz
    over the quiet stretches, N), ``body_mass_kg`` the file states (PROCESSING:Bodymass),
    ``units`` the force channels' labels as found, ``start_s`` the record time of the first
    sample, ``contact_s`` the contact instants in record time (stances selected by threshold).
    """

    t: np.ndarray
    fz: np.ndarray
    fx: np.ndarray | None
    fy: np.ndarray | None
    source: str
    sha256: str | None = None
    plate_index: int | None = None
    offset_n: tuple[float, float, float] = (0.0, 0.0, 0.0)
    offset_measured: bool = False
    noise_n: float = 0.0
    body_mass_kg: float | None = None
    units: str = ""
    start_s: float = 0.0
    contact_s: tuple[float, float] | None = None

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
        raw = Path(path).read_bytes()
        rows = list(csv.reader(io.StringIO(raw.decode("utf-8"), newline="")))
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
                               values[:, 3].copy() if shear else None, src,
                               sha256=hashlib.sha256(raw).hexdigest())


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


def _force_units(params: dict, plate_index: int, plate_type: int) -> str:
    """ANALOG:UNITS of the plate's force channels as found ("" when the file does not say),
    quoted in messages only (module docstring: labels are unreliable).

    FORCE_PLATFORM:CHANNEL (1-based analog indices, one column per plate) lists the force
    channels first: 8 of them for a type-3 plate, 3 for the other types.
    """
    channels = np.asarray(params["FORCE_PLATFORM"]["CHANNEL"]["value"])
    if channels.ndim != 2 or plate_index >= channels.shape[1]:
        return ""
    n_force = 8 if plate_type == 3 else 3
    analog = params["ANALOG"]
    units = list(analog["UNITS"]["value"]) if "UNITS" in analog else []
    found = sorted({str(units[c - 1]).strip() for c in channels[:n_force, plate_index]
                    if 0 < c <= len(units)})
    return "/".join(found)


def _plate_types(params: dict) -> np.ndarray:
    fp = params["FORCE_PLATFORM"]
    return np.asarray(fp["TYPE"]["value"]).ravel().astype(int) if "TYPE" in fp \
        else np.zeros(0, dtype=int)


def _body_mass(params: dict) -> float | None:
    """PROCESSING:Bodymass (kg) when the file states a finite positive one."""
    proc = params.get("PROCESSING", {})
    if "Bodymass" not in proc:
        return None
    values = np.asarray(proc["Bodymass"]["value"], dtype=float).ravel()
    if values.size and math.isfinite(values[0]) and values[0] > 0.0:
        return float(values[0])
    return None


def quiet_baseline(fz: np.ndarray, rate_hz: float) -> tuple[np.ndarray, float]:
    """The quiet (unloaded) samples of a plate's record and the σ of their Fz (N).

    Windows of ``QUIET_WINDOW_S``; a window is steady when its Fz standard deviation is at most
    max(``QUIET_STD_N``, 3 × the steadiest window's), never above ``QUIET_MAX_STD_N``; the
    quiet windows are the steady ones whose mean lies within max(5 N, 5σ) of the lowest steady
    mean (an unloaded plate reads its lowest level: a foot only adds load). That level must be the record's floor: when samples
    read more than max(``FLOOR_TOLERANCE_N``, 8σ) below it, the steadiest low stretch was a
    loaded one and the record has no unloaded stretch. Returns a boolean mask of the quiet
    samples (all False when there is none) and their σ (NaN then).
    """
    w = max(3, int(round(QUIET_WINDOW_S * rate_hz)))
    n_win = fz.size // w
    mask = np.zeros(fz.size, dtype=bool)
    if n_win == 0:
        return mask, math.nan
    win = fz[:n_win * w].reshape(n_win, w)
    means, stds = win.mean(axis=1), win.std(axis=1)
    steady = stds <= min(QUIET_MAX_STD_N, max(QUIET_STD_N, 3.0 * float(stds.min())))
    if not steady.any():
        return mask, math.nan
    sigma = float(np.median(stds[steady]))
    level = float(means[steady].min())
    if float(fz.min()) < level - max(FLOOR_TOLERANCE_N, 8.0 * sigma):
        return mask, math.nan
    quiet = steady & (means <= level + max(5.0, 5.0 * sigma))
    mask[:n_win * w] = np.repeat(quiet, w)
    return mask, float(np.std(fz[mask]))


def read_grf_c3d(path: str | Path, plate_index: int) -> GroundReactionForce:
    """Read force platform ``plate_index`` of a C3D file, its unloaded offset removed (module
    docstring).

    Raises:
        ProtocolValidationError: not a C3D file, truncated, unreadable, no such plate, a plate
            type other than 2, 3, 4, non-finite samples, no unloaded stretch to take the offset
            from.
        BackendUnavailableError: ezc3d is not installed.
    """
    src = str(path)
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise _refuse(src, f"cannot read the file ({exc.strerror})") from None
    head = data[:1024]
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
        # Parameters first: the plate's type decides whether ezc3d can extract its forces.
        params = ezc3d.c3d(src, extract_forceplat_data=False)["parameters"]
    except Exception as exc:  # ezc3d raises OSError/RuntimeError/IndexError on bad files
        raise _refuse(src, f"ezc3d cannot read it as C3D: {exc}") from None
    if "FORCE_PLATFORM" not in params or "USED" not in params["FORCE_PLATFORM"]:
        raise _refuse(src, "the file has no FORCE_PLATFORM parameters: no force plate to read")
    used = np.asarray(params["FORCE_PLATFORM"]["USED"]["value"]).ravel()
    n_used = int(used[0]) if used.size else 0
    types = _plate_types(params)
    if n_used == 0 or types.size == 0:
        raise _refuse(src, "the file has no force platform (FORCE_PLATFORM:USED = 0)")
    n_plates = min(n_used, types.size)
    if not 0 <= plate_index < n_plates:
        raise _refuse(src, f"plate_index {plate_index}: the file has {n_plates} force "
                      f"platform(s) (FORCE_PLATFORM:USED = {n_used}); valid indices 0.."
                      f"{n_plates - 1}")
    plate_type = int(types[plate_index])
    if plate_type not in SUPPORTED_PLATE_TYPES:
        raise _refuse(src, f"force platform {plate_index} is of type {plate_type}: type "
                      f"{plate_type} is not supported (types "
                      f"{', '.join(map(str, SUPPORTED_PLATE_TYPES))} are)")
    others = sorted({int(x) for x in types[:n_plates]} - set(SUPPORTED_PLATE_TYPES))
    rate_values = np.asarray(params["ANALOG"]["RATE"]["value"]).ravel()
    rate = float(rate_values[0]) if rate_values.size else 0.0
    if not (math.isfinite(rate) and rate > 0.0):
        raise _refuse(src, f"ANALOG:RATE must be > 0 Hz (got {rate})")
    try:
        c3d = ezc3d.c3d(src, extract_forceplat_data=True)
        force = np.asarray(c3d["data"]["platform"][plate_index]["force"], dtype=float)
    except Exception as exc:  # ezc3d's extraction fails on the types it does not model
        why = f" (the file also has plates of type {others}, which ezc3d cannot model)" \
            if others else ""
        raise _refuse(src, f"ezc3d cannot extract force platform {plate_index}{why}: "
                      f"{exc}") from None
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
    quiet, noise = quiet_baseline(force[2] if -force[2].min() <= force[2].max()
                                  else -force[2], rate)
    # No unloaded stretch (a record that starts loaded): the offset cannot be measured and is
    # left in, said so in the record (``offset_measured``) and in the replay's traceability.
    offset = np.median(force[:, quiet], axis=1) if quiet.any() else np.zeros(3)
    force = force - offset[:, None]
    fx, fy, fz = force
    if -fz.min() > fz.max():  # force on the plate: flip so the loading is positive
        fx, fy, fz = -fx, -fy, -fz
    t = np.arange(n) / rate
    return GroundReactionForce(t, fz.copy(), fx.copy(), fy.copy(), src,
                               sha256=hashlib.sha256(data).hexdigest(), plate_index=plate_index,
                               offset_n=(float(offset[0]), float(offset[1]), float(offset[2])),
                               offset_measured=bool(quiet.any()),
                               noise_n=0.0 if math.isnan(noise) else noise,
                               body_mass_kg=_body_mass(params),
                               units=_force_units(params, plate_index, plate_type))


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
                  end_s: float | None = None, lead_s: float = 0.0) -> GroundReactionForce:
    """The stance to replay (module docstring), its time starting at 0.

    Give either ``threshold_n`` (N; with ``occurrence``, 0 = first; ``lead_s``: unloaded record
    kept before contact and after toe off, s) or ``start_s`` and ``end_s`` (s from the record's
    first sample).
    """
    src, t, fz = grf.source, grf.t, grf.fz
    contact: tuple[float, float] | None = None
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
        # The true contact: Fz above the noise, not only above the threshold.
        level = max(CONTACT_LEVEL_N, 4.0 * grf.noise_n)
        while i0 > 0 and fz[i0 - 1] > level:
            i0 -= 1
        while i1 < fz.size - 1 and fz[i1 + 1] > level:
            i1 += 1
        contact = (float(t[i0] + grf.start_s), float(t[i1] + grf.start_s))
        j0 = int(np.searchsorted(t, t[i0] - lead_s - 1e-12))
        j1 = int(np.searchsorted(t, t[i1] + lead_s + 1e-12, side="right")) - 1
        if lead_s > 0.0 and (t[i0] - t[0] < lead_s or t[-1] - t[i1] < lead_s):
            before, after = t[i0] - t[0], t[-1] - t[i1]
            raise _refuse(src, f"the stance at t = {t[i0]:.3f} .. {t[i1]:.3f} s has "
                          f"{min(before, after) * 1e3:.0f} ms of unloaded record "
                          f"{'before contact' if before < after else 'after toe off'}; the "
                          f"replay starts {lead_s * 1e3:.0f} ms before contact and ends as "
                          "long after toe off (ramp_s): shorten ramp_s or select the stance "
                          "explicitly")
        busy = fz[j0:i0] > threshold_n
        busy_after = fz[i1 + 1:j1 + 1] > threshold_n
        if busy.any() or busy_after.any():
            raise _refuse(src, f"the stance at t = {t[i0]:.3f} .. {t[i1]:.3f} s is within "
                          f"{lead_s * 1e3:.0f} ms of another one: no unloaded lead-in for the "
                          "replay (shorten ramp_s or select the stance explicitly)")
        i0, i1 = j0, j1
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
    return replace(grf, t=t[sl] - t[i0], fz=fz[sl].copy(),
                   fx=None if grf.fx is None else grf.fx[sl].copy(),
                   fy=None if grf.fy is None else grf.fy[sl].copy(),
                   start_s=float(t[i0] + grf.start_s), contact_s=contact)


def check_plausible_peak(stance: GroundReactionForce, body_mass_kg: float, mass_from: str,
                         plate: str) -> float:
    """The stance's vertical peak in body weights; refuses it outside ``PLAUSIBLE_PEAK_BW``
    naming the measured peak, the expected range and the unit labels found (module docstring).
    """
    weight = body_mass_kg * STANDARD_GRAVITY_M_S2
    peak = float(stance.fz.max())
    ratio = peak / weight
    lo, hi = PLAUSIBLE_PEAK_BW
    if not lo <= ratio <= hi:
        labels = f" (its force channels are labelled {stance.units!r})" if stance.units else ""
        raise _refuse(stance.source, f"{plate}the stance peaks at {peak:.4g} N = {ratio:.3g} body "
                      f"weights of the {body_mass_kg:g} kg subject ({mass_from}); a stance "
                      f"peaks at {lo:g}-{hi:g} BW, {lo * weight:.0f}-{hi * weight:.0f} N: the "
                      f"data are not in N{labels} or the body mass is not the subject's")
    return ratio


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
