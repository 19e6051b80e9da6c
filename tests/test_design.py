import math

import numpy as np
import pytest

from glsynth.core import design
from glsynth.core.design import StandardDesign, cross_sections, is_straight, table3_row

EPS = 1e-9


@pytest.mark.parametrize("height, row", [
    (5.0, 0), (5.0 + EPS, 0), (5.5 - EPS, 0), (5.5, 0), (5.5 + EPS, 0), (7.0, 0), (7.0 + EPS, 1),
    (8.5, 1), (8.5 + EPS, 2), (10.0, 2), (10.0 + EPS, 3), (12.0, 3), (12.0 + EPS, 4), (14.0, 4),
])
def test_table3_rows_at_and_around_every_boundary(height, row):
    assert table3_row(height) == row


@pytest.mark.parametrize("height", [5.0 - EPS, 14.0 + EPS, -1.0, math.inf, math.nan])
def test_heights_outside_table4_are_rejected(height):
    with pytest.raises(ValueError, match="height_m"):
        table3_row(height)


@pytest.mark.parametrize("radius, straight", [
    (math.inf, True), (5000.0 + 1e-6, True), (1e9, True), (5000.0, False), (4999.0, False),
    (500.0, False), (1e-3, False),
])
def test_straight_means_radius_above_5000(radius, straight):
    assert is_straight(radius) is straight


@pytest.mark.parametrize("radius", [0.0, -10.0, math.nan])
def test_bad_radius_is_rejected(radius):
    with pytest.raises(ValueError, match="radius_m"):
        is_straight(radius)


@pytest.mark.parametrize("height, radius, column, beam", [
    (6.0, math.inf, (60, 60), None), (6.0, 1000.0, (60, 70), None),
    (8.0, math.inf, (70, 70), None), (8.0, 1000.0, (70, 80), None),
    (9.0, math.inf, (80, 80), None), (9.0, 1000.0, (80, 90), None),
    (11.0, math.inf, (70, 70), (80, 60)), (11.0, 1000.0, (70, 85), (80, 60)),
    (13.0, math.inf, (80, 80), (80, 60)), (13.0, 5000.0, (80, 95), (80, 60)),
])
def test_table3_values(height, radius, column, beam):
    choice = cross_sections(height, radius)
    assert choice.column_cm == column
    assert choice.intermediate_beam_cm == beam
    assert choice.straight == (radius > design.STRAIGHT_RADIUS_M)


def test_standard_span_layout():
    d = StandardDesign()
    assert d.length_m == 24.0
    assert d.column_rows_s == (3.0, 9.0, 15.0, 21.0)
    assert np.allclose(np.diff((0.0, *d.column_rows_s, 24.0)), (3, 6, 6, 6, 3))


def test_design_rejects_bad_values_with_field_and_fix():
    with pytest.raises(ValueError, match=r"design\.slab_thickness_m = -0\.3.*\(0\.0, 100\.0\]"):
        StandardDesign(slab_thickness_m=-0.3)
    with pytest.raises(ValueError, match="column_spacing_m"):
        StandardDesign(column_spacing_m=12.0, deck_width_m=11.0)
