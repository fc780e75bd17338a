"""Labels of protocol and limit fields in clinical words and units (translatable).

The schema's field names carry their SI/clinical unit (``amplitude_n``, ``hold_s``); a field
this table does not know is shown by its name with the unit suffix spelled out, so a new
schema field is never hidden from the form.
"""
from __future__ import annotations

from app.i18n import tr

#: Unit suffixes of field names → the unit shown.
_UNITS = (("_deg_s2", "°/s²"), ("_deg_s3", "°/s³"), ("_deg_s", "°/s"), ("_deg", "°"),
          ("_n_m_s_rad", "N·m·s/rad"), ("_n_m_rad", "N·m/rad"), ("_n", "N"), ("_hz", "Hz"),
          ("_kg", "kg"), ("_m", "m"), ("_s", "s"))


def _labels() -> dict[str, str]:
    return {
        "name": tr("Name"), "description": tr("Description"),
        "pose": tr("Platform position"), "z_m": tr("Height (m)"),
        "roll_deg": tr("Roll tilt (°)"),
        "pitch_deg": tr("Pitch tilt (°)"),
        "mean_n": tr("Mean force (N)"), "amplitude_n": tr("Force amplitude (N)"),
        "frequency_hz": tr("Frequency (Hz)"), "cycles": tr("Cycles"),
        "ramp_in_s": tr("Ramp in (s)"), "ramp_out_s": tr("Ramp out (s)"),
        "ramp_s": tr("Ramp (s)"),
        "limits": tr("Limits of this protocol"),
        "roll_min_deg": tr("Minimum roll (°)"),
        "roll_max_deg": tr("Maximum roll (°)"),
        "pitch_min_deg": tr("Minimum pitch (°, dorsiflexion)"),
        "pitch_max_deg": tr("Maximum pitch (°, plantarflexion)"),
        "max_force_n": tr("Maximum force (N)"),
        "max_angular_speed_deg_s": tr("Maximum angular speed (°/s)"),
        "sequence": tr("Movements"), "amplitude_deg": tr("Range per direction (°)"),
        "dorsiflexion": tr("Dorsiflexion (°)"), "plantarflexion": tr("Plantarflexion (°)"),
        "inversion": tr("Inversion (°)"), "eversion": tr("Eversion (°)"),
        "speed_deg_s": tr("Speed (°/s)"), "repetitions": tr("Repetitions"),
        "hold_s": tr("Hold at each end (s)"), "profile": tr("Motion profile"),
        "max_acceleration_deg_s2": tr("Maximum acceleration (°/s²)"),
        "max_jerk_deg_s3": tr("Maximum jerk (°/s³)"),
        "source": tr("Gait record file"), "file": tr("Trajectory file"),
        "percent_body_weight": tr("Load (% body weight)"), "time_scale": tr("Time scale"),
        "plate_index": tr("Force plate"), "include_shear": tr("Include shear forces"),
        "source_body_weight_kg": tr("Body mass in the record (kg)"),
        "holds": tr("Holds"), "rest_s": tr("Rest (s)"), "rest_between_s": tr("Rest between (s)"),
        "target_force_n": tr("Target force (N)"), "duration_s": tr("Duration (s)"),
        "assistance_gain": tr("Assistance gain"), "threshold_n": tr("Threshold (N)"),
        "guide_period_s": tr("Guide period (s)"), "admittance": tr("Admittance"),
        "stiffness_n_m_rad": tr("Stiffness (N·m/rad)"),
        "damping_n_m_s_rad": tr("Damping (N·m·s/rad)"),
        "interpolation": tr("Interpolation"), "sample_rate_hz": tr("Sample rate (Hz)"),
        "stance": tr("Stance"), "transition_speed_deg_s": tr("Transition speed (°/s)"),
        "max_speed_deg_s": tr("Maximum speed (°/s)"), "axes": tr("Axes"),
        "rom_deg": tr("Range (°)"), "start_s": tr("Start (s)"), "end_s": tr("End (s)"),
        "centre": tr("Turn about"),
        "ankle_displacement_limit_mm": tr("Ankle comfort limit (mm)"),
    }


def field_label(name: str) -> str:
    """The label of schema field ``name``."""
    known = _labels().get(name)
    if known is not None:
        return known
    for suffix, unit in _UNITS:
        if name.endswith(suffix):
            return f"{name[: -len(suffix)].replace('_', ' ').capitalize()} ({unit})"
    return name.replace("_", " ").capitalize()
