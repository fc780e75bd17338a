"""The robot description file: loads into typed objects; bad files are refused by field."""
from __future__ import annotations

import copy
import math
from importlib import resources

import pytest
import yaml

from rt.errors import ConfigurationError
from rt.model.description import description_from_dict, load_description


@pytest.fixture()
def raw() -> dict:
    return yaml.safe_load(resources.files("rt.data").joinpath("robot_nominal.yaml").read_text())


def test_nominal_values_match_design(raw):
    d = description_from_dict(raw)
    assert d.geometry.base_radius_m == 0.30 and d.geometry.platform_radius_m == 0.18
    assert d.geometry.rod_length_m == 0.45 and d.limits.stroke_m == [0.0, 0.40]
    assert (d.bodies.slider.mass_kg, d.bodies.rod.mass_kg, d.bodies.platform.mass_kg,
            d.bodies.sensor.mass_kg) == (2.0, 1.2, 8.0, 0.9)
    # Derived drive figures, by hand: J (2π/lead)² and Kt η 2π / lead.
    assert d.drive.reflected_inertia_kg == pytest.approx(1.3e-4 * (2 * math.pi / 0.005) ** 2)
    assert d.drive.force_per_volt_n == pytest.approx(0.3 * 0.9 * 2 * math.pi / 0.005)
    assert d.encoder.midpoint == 8388608 and d.encoder.m_per_count == 2e-5


def _set(data: dict, path: str, value) -> dict:
    data = copy.deepcopy(data)
    node = data
    keys = path.split(".")
    for k in keys[:-1]:
        node = node[k]
    if value is _DELETE:
        del node[keys[-1]]
    else:
        node[keys[-1]] = value
    return data


_DELETE = object()


@pytest.mark.parametrize("path, value, expected", [
    ("bodies.rod.mass_kg", -1.2, "bodies.rod.mass_kg"),
    ("bodies.platform.inertia_kg_m2", [[1, 0.5, 0], [0, 1, 0], [0, 0, 1]], "symmetric"),
    ("bodies.platform.inertia_kg_m2", [[0.01, 0, 0], [0, 0.01, 0], [0, 0, 1.0]], "I1 + I2"),
    ("schema_version", 7, "unsupported schema_version 7"),
    ("geometry.leg_angles_deg", [90, 200, 330], "120 degrees apart"),
    ("geometry.rod_length_m", 0.05, "rod_length_m must exceed"),
    ("limits.stroke_m", [0.4, 0.0], "low < high"),
    ("drive.screw_efficiency", 1.5, "drive.screw_efficiency"),
    ("friction.viscous_n_s_per_m", float("nan"), "friction.viscous_n_s_per_m"),
    ("encoder.midpoint", 2 ** 24, "does not fit 24 bits"),
    ("geometry.base_radius_m", _DELETE, "geometry.base_radius_m: Field required"),
    ("geometry.extra_key", 1.0, "geometry.extra_key"),
])
def test_bad_field_is_refused_by_name(raw, path, value, expected):
    with pytest.raises(ConfigurationError) as info:
        description_from_dict(_set(raw, path, value), "test.yaml")
    assert expected in str(info.value)
    assert "test.yaml" in str(info.value)


def test_bad_files(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("geometry: [unclosed\n")
    with pytest.raises(ConfigurationError, match="bad.yaml, line 2, column 1: YAML syntax error"):
        load_description(bad)
    bad.write_text("- just\n- a list\n")
    with pytest.raises(ConfigurationError, match="must be a YAML mapping"):
        load_description(bad)
    with pytest.raises(ConfigurationError, match="cannot read"):
        load_description(tmp_path / "missing.yaml")


def test_file_round_trip(tmp_path, raw):
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(_set(raw, "bodies.platform.mass_kg", 9.5)))
    assert load_description(path).bodies.platform.mass_kg == 9.5
