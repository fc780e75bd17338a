"""The calibration in C3D form (``talus calibrate export``), readable by any C3D software.

* ``OUT.c3d`` — the held-out (validation) trials' raw plate channels (zeroed on each trial's
  unloaded baseline, as the plate's amplifier auto-zero would; ANALOG:SCALE 1, OFFSET 0) at the
  plate's rate, one after the other, and a FORCE_PLATFORM group of TYPE 4 whose CAL_MATRIX is
  the fitted 6×6 matrix, stored in column order (CAL_MATRIX(i, j) = element of row i, column j)
  as the C3D documentation specifies, rows in N/V and N·m/V (POINT:UNITS is ``m``). ORIGIN is
  the vector from the transducer origin to the surface centre in the plate's axes (its z is
  negative, the sign C3D readers expect). Only the linear matrix can be carried by C3D: the
  position-dependent correction stays in the calibration record.
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
    import ezc3d

    if p.plate.n_channels != 6:
        raise InputError(f"{p.plate.name}: a {p.plate.kind.value} plate has "
                         f"{p.plate.n_channels} channels; C3D TYPE-4 carries a 6×6 matrix "
                         "(TYPE-3 export of eight-channel plates is not implemented)")
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

    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = np.array([fs / POINT_RATE_DIVISOR])
    c["parameters"]["POINT"]["UNITS"]["value"] = ["m"]
    c["data"]["points"] = np.zeros((4, 0, n // POINT_RATE_DIVISOR))
    c["parameters"]["ANALOG"]["RATE"]["value"] = np.array([fs])
    c["parameters"]["ANALOG"]["LABELS"]["value"] = p.plate.channel_labels()
    c["parameters"]["ANALOG"]["UNITS"]["value"] = [ch.unit for ch in p.plate.channels]
    c["data"]["analogs"] = v_all.T[None, :, :]
    c.add_parameter("ANALOG", "SCALE", np.ones(6))
    c.add_parameter("ANALOG", "OFFSET", np.zeros(6))
    c.add_parameter("ANALOG", "GEN_SCALE", np.array([1.0]))
    _int_parameter(c, "FORCE_PLATFORM", "USED", [1], [1])
    _int_parameter(c, "FORCE_PLATFORM", "TYPE", [4], [1])
    c.add_parameter("FORCE_PLATFORM", "UNITS", ["N"])
    _int_parameter(c, "FORCE_PLATFORM", "ZERO", [1, 1], [2])
    c.add_parameter("FORCE_PLATFORM", "CORNERS", corners_G(p).T[:, :, None])
    c.add_parameter("FORCE_PLATFORM", "ORIGIN", (-origin)[:, None])
    _int_parameter(c, "FORCE_PLATFORM", "CHANNEL", list(range(1, 7)), [6, 1])
    c.add_parameter("FORCE_PLATFORM", "CAL_MATRIX", p.linear.C[:, :, None])
    c.add_parameter("MANUFACTURER", "COMPANY", ["talus"])
    c.add_parameter("MANUFACTURER", "SOFTWARE", ["talus calibrate export"])
    _write_atomic(c3d_path, lambda tmp: c.write(str(tmp)))
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
