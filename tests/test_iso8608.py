"""ISO 8608 road profiles: the classes' table, the synthesised PSD against it, seeding, the
geometry to the road-wheel angle, the bump, and bad --road input."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.signal import welch

from sashil.engine.resolve import default_config
from sashil.errors import ConfigError
from sashil.roads.iso8608 import CLASSES, N_BAND, iso8608_height, spatial_psd
from sashil.roads.option import RoadParts, parse_road

#: ISO 8608 Table 1: Gd(n0) geometric mean of each class [10^-6 m^3]
TABLE = {"A": 16, "B": 64, "C": 256, "D": 1024, "E": 4096, "F": 16384, "G": 65536, "H": 262144}


def test_classes_are_the_standards_table():
    assert {k: round(v * 1e6) for k, v in CLASSES.items()} == TABLE
    assert spatial_psd("C", 0.1) == pytest.approx(256e-6)
    assert spatial_psd("C", 1.0) == pytest.approx(2.56e-6)  # waviness 2: a decade down, 100x


@pytest.mark.parametrize("road_class", list("ABCDEFGH"))
def test_synthesised_psd_matches_the_table(road_class):
    speed, rate = 10.0, 200.0
    h = iso8608_height(road_class, speed, 400.0, rate, seed=3)
    f, g = welch(h, fs=rate, nperseg=8192)
    n, gd = f / speed, g * speed  # temporal one-sided PSD -> spatial
    for lo, hi in [(0.05, 0.2), (0.2, 0.8), (0.8, 2.0)]:
        band = (n >= lo) & (n < hi)
        ratio = np.mean(gd[band] / spatial_psd(road_class, n[band]))
        assert ratio == pytest.approx(1.0, abs=0.15), (lo, hi, ratio)
    # the variance is the integral of Gd over the standard's band: Gd(n0)·n0²·(1/n1 − 1/n2)
    expected = CLASSES[road_class] * 0.1**2 * (1.0 / N_BAND[0] - 1.0 / N_BAND[1])
    assert np.var(h) == pytest.approx(expected, rel=0.02)


def test_the_road_is_seeded():
    a = iso8608_height("C", 10.0, 60.0, 1000.0, seed=1)
    assert np.array_equal(a, iso8608_height("C", 10.0, 60.0, 1000.0, seed=1))
    assert not np.array_equal(a, iso8608_height("C", 10.0, 60.0, 1000.0, seed=2))


def test_road_option_maps_height_to_the_wheel_angle_through_the_lever():
    config = default_config()
    config["road"]["period_s"] = 20.0
    road, text = parse_road("iso8608:c:5", RoadParts.read(config))
    assert text.startswith("ISO 8608 class C at 5 m/s")
    h = iso8608_height("C", 5.0, 20.0, 1000.0, seed=0)
    # after the fade-in, theta1 = h / lever_m; its rate the derivative of the angle
    t = 3.0
    i = int(t * 1000)
    assert road(t)[0] == pytest.approx(h[i] / 0.5)
    slope = (road(t + 1e-3)[0] - road(t - 1e-3)[0]) / 2e-3
    assert road(t)[1] == pytest.approx(slope, rel=0.05, abs=1e-3)
    assert road(0.0)[:2] == (0.0, 0.0)  # faded in from rest


def test_bump():
    road, text = parse_road("bump:2", RoadParts.read(default_config()))
    assert road(0.5) == (0.0, 0.0, 0.0)
    assert road(1.25)[0] == pytest.approx(math.radians(2.0))  # the top, half-way through 0.5 s from 1 s
    assert "bump 2 deg" in text


@pytest.mark.parametrize(
    "spec, words",
    [
        ("iso8608:Z", "expected an ISO 8608 road class A-H, got 'Z'"),
        ("iso8608:", "expected an ISO 8608 road class A-H"),
        ("iso8608:C:0", "expected a speed in (0, 100] m/s, got 0"),
        ("iso8608:C:-3", "expected a speed in (0, 100] m/s"),
        ("iso8608:C:fast", "expected a speed in m/s after the class"),
        ("bump:0", "expected a bump height"),
    ],
)
def test_bad_road_is_one_line_naming_the_option(spec, words):
    with pytest.raises(ConfigError) as err:
        parse_road(spec, RoadParts.read(default_config()))
    assert str(err.value).startswith(f"--road {spec}: ") and words in str(err.value)
