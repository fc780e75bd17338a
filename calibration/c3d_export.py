"""The calibration in C3D form (``talus calibrate export``), readable by any C3D software.

* ``OUT.c3d`` — the held-out (validation) trials' raw plate channels (zeroed on each trial's
  unloaded baseline, as the plate's amplifier auto-zero would; ANALOG:SCALE 1, OFFSET 0) at the
  plate's rate, one after the other, and a FORCE_PLATFORM group of TYPE 4 whose CAL_MATRIX is
  the fitted 6×6 matrix, stored in column order (CAL_MATRIX(i, j) = element of row i, column j)
  as the C3D documentation specifies, rows in N/V and N·m/V (POINT:UNITS is ``m``). ORIGIN is
  the vector from the transducer origin to the surface centre in the plate's axes (its z is
  negative, the sign C3D readers expect). Only the linear matrix can be carried by C3D: the
  position-dependent correction stays in the calibration record.
* An eight-channel Kistler plate (``kistler8``) goes out as TYPE 3, the type every C3D reader
  computes from the eight channels and the sensor offsets ORIGIN = (a, b, az0): TYPE 3 carries
  no matrix, so the channels written are the *calibrated* ones — u = K⁺ C v, with C the fitted
  6×8 matrix and K the Kistler formulas' matrix (``calibration.plate.kistler_matrix``) —
  for which K u = C v exactly: a reader reproduces the fitted forces and moments. The wrench is
  first carried to the point of the sensor plane under the surface centre (TYPE 3 puts the
  sensors' centre there), az0 is its depth with C3D's sign (negative, as TYPE 4's ORIGIN z).
* ``REF.csv`` — the ATI reference at the same instants (the plate's samples put on the robot's
  clock), in the C3D file's global frame G, the frame of its CORNERS: origin at the plate's
  surface centre, Z up out of the working surface, X along the plate's x, Y = Z × X. Columns
  ``t,Fx,Fy,Fz,Mx,My,Mz,COPx,COPy`` (s, N, N·m about G's origin, m): the force the load applies
  to the plate, as C3D readers report the plate's force; COP is the load point.

The C3D global frame is the plate's own lab frame (a plate is recalibrated where it is, not where
the robot held it); a lab that wants its capture volume's frame moves CORNERS with its own
registration.
"""
from __future__ import annotations

import csv
import io
import os
import tempfile
from pathlib import Path

import numpy as np

from calibration import dataset
from calibration.campaign import Processed
from calibration.plate import KISTLER_CHANNELS, PlateDescription, PlateKind, kistler_matrix
from calibration.trial import TRIALS_DIR, TrialData, sha256_file
from rt.errors import ConfigurationError, InputError

#: Rotation from the plate frame F (z into the plate) to the C3D global frame G (Z up).
R_GF = np.diag([1.0, -1.0, -1.0])
POINT_RATE_DIVISOR = 10      # analog samples per point frame


def corners_G(p: Processed) -> np.ndarray:
    """CORNERS in G (4 × 3), ordered so that C3D readers recover F's axes:
    x = c1 - c2 direction, y = c1 - c4 direction, z = x × y (into the plate)."""
    return p.plate.corners_F() @ R_GF.T


def export(folder: Path, p: Processed, c3d_path: Path, csv_path: Path, force: bool = False
           ) -> list[dict]:
    """Write the C3D and the reference CSV; returns the record's ``exports`` entries."""
    _check_exportable(p.plate, p.linear.C)
    for path in (c3d_path, csv_path):
        if path.exists() and not force:
            raise InputError(f"{path} exists; choose another name or pass --force")
        if not path.parent.is_dir():
            raise InputError(f"{path.parent}: no such folder")
    entries = [e for e in p.index["trials"] if e["held_out"]]
    if not entries:
        raise ConfigurationError(f"{folder}: no held-out trial to export")
    origin = np.array(p.plate.origin_m)
    fs = p.plate.sample_rate_hz
    channels, ref_rows = [], []
    t_next = 0.0
    for e in entries:
        d = TrialData.load(folder / TRIALS_DIR / f"{e['id']}.npz")
        v = dataset.zeroed_channels(d)
        t_robot = p.clock.to_robot(d.t_plate)  # type: ignore[attr-defined]
        inside = (t_robot >= d.t_robot[0]) & (t_robot <= d.t_robot[-1])
        v, t_robot = v[inside], t_robot[inside]
        w, pt = dataset.reference_in_plate(d, origin)
        w_s = np.column_stack([np.interp(t_robot, d.t_robot, w[:, k]) for k in range(6)])
        p_s = np.column_stack([np.interp(t_robot, d.t_robot, pt[:, k]) for k in range(3)])
        # Moments about the surface centre c = 0: M_c = M_O + O × F.
        f_F = w_s[:, :3]
        m_c = w_s[:, 3:] + np.cross(origin, f_F)
        cop = p_s.copy()
        cop[:, 2] = 0.0
        channels.append(v)
        ref_rows.append(np.column_stack([t_next + np.arange(len(v)) / fs, f_F @ R_GF.T,
                                         m_c @ R_GF.T, (cop @ R_GF.T)[:, :2]]))
        t_next += len(v) / fs
    v_all = np.vstack(channels)
    ref = np.vstack(ref_rows)
    n = (len(v_all) // POINT_RATE_DIVISOR) * POINT_RATE_DIVISOR
    v_all, ref = v_all[:n], ref[:n]

    write_c3d(c3d_path, p.plate, p.linear.C, v_all, corners_G(p))
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(["t", "Fx", "Fy", "Fz", "Mx", "My", "Mz", "COPx", "COPy"])
    for row in ref:
        writer.writerow([f"{row[0]:.6f}", *(f"{x:.6g}" for x in row[1:])])
    _write_atomic(csv_path, lambda tmp: tmp.write_text(buf.getvalue(), encoding="utf-8"))
    return [{"kind": "c3d", "path": str(c3d_path), "sha256": sha256_file(c3d_path),
             "frame": "G: plate surface centre, Z up, X along the plate's x",
             "trials": [e["id"] for e in entries]},
            {"kind": "reference_csv", "path": str(csv_path), "sha256": sha256_file(csv_path)}]


def _check_exportable(plate: PlateDescription, C: np.ndarray) -> None:
    if plate.kind == PlateKind.KISTLER8:
        if plate.kistler is None:
            raise InputError(f"{plate.name}: C3D TYPE 3 needs the Kistler sensor offsets "
                             "(the plate file's kistler: a_m, b_m, az0_m)")
        if C.shape != (6, 8):
            raise InputError(f"{plate.name}: a kistler8 calibration is a 6×8 matrix, got "
                             f"{C.shape[0]}×{C.shape[1]}")
    elif plate.n_channels != 6 or C.shape != (6, 6):
        raise InputError(f"{plate.name}: a {plate.kind.value} plate has {plate.n_channels} "
                         "channels; C3D TYPE-4 carries a 6×6 matrix (TYPE 3 is for kistler8 "
                         "plates)")


def kistler_channels(plate: PlateDescription, C: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The calibrated Kistler channels (n, 8) in N for raw channels ``v`` (n, 8): u = K⁺ w,
    w = C v carried from the transducer origin O to the sensor plane's point under the surface
    centre P = (0, 0, O_z) (module docstring); K u = w exactly (K has full row rank)."""
    assert plate.kistler is not None
    origin = np.array(plate.origin_m)
    w = v @ C.T
    p_point = np.array([0.0, 0.0, origin[2]])
    w[:, 3:] += np.cross(origin - p_point, w[:, :3])          # M_P = M_O + (O − P) × F
    K = kistler_matrix(plate.kistler)
    return np.asarray(w @ np.linalg.pinv(K).T)


def write_c3d(path: Path, plate: PlateDescription, C: np.ndarray, v: np.ndarray,
              corners: np.ndarray) -> None:
    """A C3D of the raw channels ``v`` (n, N; n a multiple of ``POINT_RATE_DIVISOR``) with one
    force platform: TYPE 4 with ``C`` as CAL_MATRIX for a six-channel plate, TYPE 3 with the
    calibrated channels for a Kistler plate (module docstring). ``corners`` in G (4 × 3)."""
    import ezc3d

    _check_exportable(plate, C)
    n = len(v)
    fs = plate.sample_rate_hz
    origin = np.array(plate.origin_m)
    kistler = plate.kind == PlateKind.KISTLER8
    analogs = kistler_channels(plate, C, v) if kistler else v
    m = analogs.shape[1]
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = np.array([fs / POINT_RATE_DIVISOR])
    c["parameters"]["POINT"]["UNITS"]["value"] = ["m"]
    c["data"]["points"] = np.zeros((4, 0, n // POINT_RATE_DIVISOR))
    c["parameters"]["ANALOG"]["RATE"]["value"] = np.array([fs])
    c["parameters"]["ANALOG"]["LABELS"]["value"] = list(KISTLER_CHANNELS) if kistler \
        else plate.channel_labels()
    c["parameters"]["ANALOG"]["UNITS"]["value"] = ["N"] * m if kistler \
        else [ch.unit for ch in plate.channels]
    c["data"]["analogs"] = analogs.T[None, :, :]
    c.add_parameter("ANALOG", "SCALE", np.ones(m))
    c.add_parameter("ANALOG", "OFFSET", np.zeros(m))
    c.add_parameter("ANALOG", "GEN_SCALE", np.array([1.0]))
    _int_parameter(c, "FORCE_PLATFORM", "USED", [1], [1])
    _int_parameter(c, "FORCE_PLATFORM", "TYPE", [3 if kistler else 4], [1])
    c.add_parameter("FORCE_PLATFORM", "UNITS", ["N"])
    _int_parameter(c, "FORCE_PLATFORM", "ZERO", [1, 1], [2])
    c.add_parameter("FORCE_PLATFORM", "CORNERS", corners.T[:, :, None])
    if kistler:
        assert plate.kistler is not None
        c.add_parameter("FORCE_PLATFORM", "ORIGIN",
                        np.array([plate.kistler.a_m, plate.kistler.b_m, -origin[2]])[:, None])
    else:
        c.add_parameter("FORCE_PLATFORM", "ORIGIN", (-origin)[:, None])
        c.add_parameter("FORCE_PLATFORM", "CAL_MATRIX", C[:, :, None])
    _int_parameter(c, "FORCE_PLATFORM", "CHANNEL", list(range(1, m + 1)), [m, 1])
    c.add_parameter("MANUFACTURER", "COMPANY", ["talus"])
    c.add_parameter("MANUFACTURER", "SOFTWARE", ["talus calibrate export"])
    _write_atomic(path, lambda tmp: c.write(str(tmp)))


def _int_parameter(c, group: str, name: str, values: list[int], dims: list[int]) -> None:
    """An INT parameter (ezc3d's ``add_parameter`` stores numbers as FLOAT, and readers
    require FORCE_PLATFORM:USED, TYPE and CHANNEL to be INT)."""
    from ezc3d import ezc3d as swig

    param = swig.Parameter(name, "")
    param.set(swig.VecInt([int(v) for v in values]), swig.VecUInt([int(d) for d in dims]))
    c.parameters.add_parameter(group, param)


def _write_atomic(path: Path, write) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=path.suffix)
    os.close(fd)
    try:
        write(Path(tmp))
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
