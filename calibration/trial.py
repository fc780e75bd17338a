"""What one calibration trial records, the interface that runs trials, and the campaign folder.

A campaign folder (``talus calibrate run|demo --out DIR``)::

    DIR/campaign.json      plan, plate file name and sha256, trial list with sha256 of each file
    DIR/plate.yaml         the plate description used (a copy)
    DIR/trials/<id>.npz    one file per trial (:class:`TrialData` fields)
    DIR/twin_truth.json    twin only: the plate's hidden truth, for benchmarks (never read by fit)

Frames: B robot base, S the ATI sensor (on the platform), F the plate (``calibration.plate``).
``ati`` is what the ATI reports: the environment's wrench on the platform at S, in S's axes
(N, N·m), so the load the tool applies to the plate is ``-ati``. ``p_BS`` / ``R_BS`` give S in
B per sample (from the encoders through forward kinematics). ``T_BF`` is the plate's pose in B
as registered for the trial's site, with its standard uncertainties.
"""
from __future__ import annotations

import abc
import hashlib
import json
import os
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np

from rt.errors import ConfigurationError, InputError

CAMPAIGN_FILE = "campaign.json"
TRIALS_DIR = "trials"
CAMPAIGN_KIND = "talus.calibration_campaign"


@dataclass
class TrialData:
    """One trial's recording (module docstring). Robot-side arrays share ``t_robot`` (s, robot
    clock); plate-side arrays share ``t_plate`` (s, the plate DAQ's clock)."""

    trial_id: str
    t_robot: np.ndarray        # (n,)
    ati: np.ndarray            # (n, 6) N, N·m: environment on the platform, at S, axes of S
    p_BS: np.ndarray           # (n, 3) m
    R_BS: np.ndarray           # (n, 9) row-major
    force_ref: np.ndarray      # (n,) N commanded along the platform's z
    t_plate: np.ndarray        # (m,)
    channels: np.ndarray       # (m, N) raw plate channels
    T_BF: np.ndarray           # (4, 4) registered plate pose
    sigma_translation_m: float
    sigma_rotation_rad: float
    tool_length_m: float

    def save(self, path: Path) -> str:
        """Write atomically to ``path`` (.npz); returns the file's sha256."""
        arrays = {f.name: np.asarray(getattr(self, f.name)) for f in fields(self)}
        fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp.npz")
        os.close(fd)
        try:
            np.savez_compressed(tmp, **arrays)  # type: ignore[arg-type]
            digest = sha256_file(Path(tmp))
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
        return digest

    @classmethod
    def load(cls, path: Path) -> TrialData:
        try:
            with np.load(path, allow_pickle=False) as z:
                kw: dict[str, Any] = {}
                for f in fields(cls):
                    if f.name not in z:
                        raise ConfigurationError(f"{path}: not a trial file (no {f.name!r})")
                    value = z[f.name]
                    kw[f.name] = value.item() if value.ndim == 0 else value
        except (OSError, ValueError) as exc:
            raise ConfigurationError(f"{path}: cannot read the trial: {exc}") from None
        kw["trial_id"] = str(kw["trial_id"])
        data = cls(**kw)
        data.check(str(path))
        return data

    def check(self, where: str) -> None:
        n, m = len(self.t_robot), len(self.t_plate)
        for name, arr, rows in (("ati", self.ati, n), ("p_BS", self.p_BS, n),
                                ("R_BS", self.R_BS, n), ("force_ref", self.force_ref, n),
                                ("channels", self.channels, m)):
            if arr.shape[0] != rows:
                raise ConfigurationError(f"{where}: {name} has {arr.shape[0]} rows, expected "
                                         f"{rows}")
        if n < 10 or m < 10:
            raise ConfigurationError(f"{where}: trial too short ({n} robot, {m} plate samples)")
        if np.any(np.diff(self.t_robot) <= 0) or np.any(np.diff(self.t_plate) <= 0):
            raise ConfigurationError(f"{where}: time stamps are not increasing")
        for name, arr in (("plate channels", self.channels), ("ATI readings", self.ati),
                          ("sensor poses", self.p_BS)):
            if not np.isfinite(arr).all():
                raise ConfigurationError(f"{where}: {name} hold NaN or infinite values")


@dataclass(frozen=True)
class LiveSamples:
    """A block of a running trial's samples as the robot's side measures them, published
    while the trial runs (live plots; the trial's file, written at its end, is the record).

    ``t_robot`` is on the campaign's robot clock exactly as the trial's file will have it
    (:attr:`TrialData.t_robot`: from the ATI's first reading, the trial's offset added);
    ``force_ref`` the commanded force along the platform's z (N, :attr:`TrialData.force_ref`);
    ``ati_load`` the load the reference sensor measures along S's z (N: ``-ati[:, 2]``, the
    push the tool applies)."""

    trial_id: str
    t_robot: np.ndarray       # (k,) s
    force_ref: np.ndarray     # (k,) N
    ati_load: np.ndarray      # (k,) N


#: Receives a running trial's samples block by block, on the thread that runs the trial; it
#: must return quickly (a GUI posts them to its own thread) and must not raise.
SampleSink = Callable[[LiveSamples], None]


class TrialRunner(abc.ABC):
    """Runs one trial: the robot presses ``profile_n`` (N, every ``dt`` s, along the platform's z)
    at a site with the platform at ``pose`` (z m, roll, pitch rad), and returns the recording.

    Implementations: :class:`calibration.twin_runner.TwinTrialRunner` (the robot twin with the
    twin plate, in process), :class:`calibration.twin_runner.DirectTrialRunner` (no robot: the
    commanded load fed to the twin plate; fast, for tests of the fit). The RT-process runner
    (the campaign sent as sessions over ZeroMQ) implements the same interface.
    """

    #: Robot time spent in trials so far (s), for the campaign's length figure.
    robot_time_s: float = 0.0
    #: Where the running trial's samples go while it runs (:class:`LiveSamples`; None:
    #: nowhere). Every runner publishes them: those that record in this process every sample,
    #: the RT process's runner its telemetry's (≈ 60 per second).
    samples: SampleSink | None = None

    def publish(self, trial_id: str, t_robot: np.ndarray, force_ref: np.ndarray,
                ati_fz: np.ndarray) -> None:
        """Hand a block of samples (``ati_fz``: the ATI's S-axis z, N) to :attr:`samples`."""
        sink = self.samples
        if sink is not None and len(t_robot):
            sink(LiveSamples(trial_id, np.array(t_robot, float), np.array(force_ref, float),
                             -np.asarray(ati_fz, float)))

    @abc.abstractmethod
    def run(self, trial_id: str, site_xy_m: tuple[float, float], pose: tuple[float, float, float],
            profile_n: np.ndarray, dt: float, tilt_rad: np.ndarray | None = None) -> TrialData:
        """Run one trial; raises a TalusError when the robot could not complete it.
        ``tilt_rad`` ((n, 2) roll, pitch in rad on the profile's samples) tilts the platform
        under load about ``pose`` (shear pushes); None holds the pose."""

    def close(self) -> None:
        """Release what the runner holds."""


def sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def write_json_atomic(path: Path, data: Any, force: bool = False) -> None:
    """Write JSON to ``path`` through a temporary file; refuses an existing file unless
    ``force`` (nothing a command did not create is overwritten)."""
    if path.exists() and not force:
        raise InputError(f"{path} exists; choose another name or pass --force")
    fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            json.dump(data, f, indent=1, allow_nan=False)
            f.write("\n")
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def read_json_of_kind(path: Path, kind: str, what: str) -> dict:
    """A JSON object whose ``kind`` is ``kind``; ConfigurationError naming ``what`` otherwise."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise ConfigurationError(f"{path}: unreadable {what}: {exc}") from None
    if not isinstance(data, dict) or data.get("kind") != kind:
        raise ConfigurationError(f"{path}: not a {what}")
    return data


def read_campaign(folder: Path) -> dict:
    """The campaign's index, checked: every listed trial file present and unchanged."""
    index_path = folder / CAMPAIGN_FILE
    if not index_path.is_file():
        raise ConfigurationError(f"{folder}: not a campaign folder (no {CAMPAIGN_FILE})")
    index = read_json_of_kind(index_path, CAMPAIGN_KIND, "talus calibration campaign")
    for entry in index.get("trials", []):
        path = folder / TRIALS_DIR / f"{entry['id']}.npz"
        if not path.is_file():
            raise ConfigurationError(f"{folder}: trial {entry['id']} is missing ({path}); "
                                     "run the campaign again into a new folder")
        if sha256_file(path) != entry["sha256"]:
            raise ConfigurationError(f"{path}: changed since it was recorded (sha256 differs)")
    return index
