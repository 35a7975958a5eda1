"""Templates: centring, named shapes (count, centring, spacing) and input validation."""

import numpy as np
import pytest

from mpcform.errors import MPCFormError, ValidationError
from mpcform.formation.template import Template


def assert_centred(tpl: Template) -> None:
    np.testing.assert_allclose(tpl.offsets.mean(axis=0), 0.0, atol=1e-12)


def test_validation_error_is_an_mpcform_value_error():
    assert issubclass(ValidationError, MPCFormError)
    assert issubclass(ValidationError, ValueError)
    err = ValidationError("template.offsets", "bad")
    assert err.field == "template.offsets" and "template.offsets" in str(err)


def test_centred_returns_the_shift():
    points = np.array([[1.0, 2.0], [3.0, 2.0], [2.0, 5.0]])
    tpl, shift = Template.centred(points)
    np.testing.assert_allclose(shift, [2.0, 3.0])
    np.testing.assert_allclose(tpl.offsets + shift, points)
    assert_centred(tpl)


@pytest.mark.parametrize(
    ("points", "expected"),
    [
        (
            np.array([[1.0 + 1.0j, 0.0], [-1.0, 0.0]]),
            "template.offsets: expected real numbers of shape (n, n)",
        ),
        ([[1.0, 0.0], [1.0, 0.0], [-2.0, 0.0]], "template.offsets: offsets 0 and 1 coincide at [1, 0]"),
        (
            [[5e-10, 0.0], [-5e-10, 0.0], [1.0, 0.0], [-1.0, 0.0]],
            "template.offsets: offsets 0 and 1 coincide",
        ),
        ([[0.0, 0.0], [0.0, 0.0]], "template.offsets: all 2 offsets are zero"),
        ([[0.0, np.nan], [1.0, 0.0]], "template.offsets: expected finite numbers"),
        ([["0", "1"], ["1", "0"]], "template.offsets: expected numbers of shape (n, n)"),
    ],
)
def test_centred_takes_real_finite_distinct_points(points, expected):
    """The same rules as a scenario's offsets (mpcform.scenario.placement.check_distinct)."""
    with pytest.raises(ValidationError) as info:
        Template.centred(points)
    assert str(info.value).startswith(expected), str(info.value)


def test_centred_and_the_scenario_loader_refuse_coincident_points_alike():
    from mpcform.errors import ScenarioError
    from mpcform.scenario.placement import check_distinct

    points = np.array([[5e-10, 0.0], [-5e-10, 0.0], [1.0, 0.0], [-1.0, 0.0]])  # 1e-9 m apart
    with pytest.raises(ValidationError) as api:
        Template.centred(points)
    with pytest.raises(ScenarioError) as toml:
        check_distinct(points, "template.offsets")
    assert str(api.value) == str(toml.value) and "coincide" in str(api.value)
    Template.centred([[2e-9, 0.0], [-2e-9, 0.0], [1.0, 0.0], [-1.0, 0.0]])  # 4e-9 m apart: distinct


def test_offsets_are_read_only():
    tpl = Template.polygon(4)
    with pytest.raises(ValueError):
        tpl.offsets[0, 0] = 1.0


@pytest.mark.parametrize(
    ("offsets", "match"),
    [
        ([[1.0, 0.0], [0.0, 1.0]], "centred"),  # mean (0.5, 0.5)
        ([[1.0, 0.0], [-1.0, np.nan]], "template.offsets"),
        ([1.0, -1.0], "template.offsets"),  # 1-D
        (np.zeros((0, 2)), "template.offsets"),
        (np.zeros((2, 4)), "template.offsets"),  # 4 columns
        (np.zeros((2, 1)), "template.offsets"),
        ("abc", "template.offsets"),
    ],
)
def test_bad_offsets_are_rejected(offsets, match):
    with pytest.raises(ValidationError, match=match):
        Template(offsets)


@pytest.mark.parametrize(
    ("build", "match"),
    [
        (lambda: Template.polygon(0), "template.n"),
        (lambda: Template.polygon(3, radius=0.0), "template.radius"),
        (lambda: Template.polygon(3, dim=4), "template.dim"),
        (lambda: Template.line(2.5), "template.n"),
        (lambda: Template.line(3, spacing=-1.0), "template.spacing"),
        (lambda: Template.grid(0, 2), "template.rows"),
        (lambda: Template.grid(2, True), "template.cols"),
        (lambda: Template.grid(2, 2, layers=2), "template.layers"),
        (lambda: Template.sphere(1), "template.n"),
        (lambda: Template.sphere(5, radius=np.nan), "template.radius"),
    ],
)
def test_bad_shape_parameters_are_rejected(build, match):
    with pytest.raises(ValidationError, match=match):
        build()


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("n", [2, 3, 5, 8])
def test_polygon(n, dim):
    tpl = Template.polygon(n, radius=1.5, dim=dim)
    assert (tpl.n, tpl.dim) == (n, dim)
    assert_centred(tpl)
    np.testing.assert_allclose(np.linalg.norm(tpl.offsets, axis=1), 1.5, atol=1e-12)
    if dim == 3:
        np.testing.assert_array_equal(tpl.offsets[:, 2], 0.0)
    # a regular n-gon's side is the chord 2 R sin(pi / n)
    assert tpl.min_distance() == pytest.approx(2 * 1.5 * np.sin(np.pi / n), rel=1e-12)


def test_polygon_phase_and_ring_alias():
    tpl = Template.ring(4, radius=2.0, phase=np.pi / 4)
    np.testing.assert_allclose(tpl.offsets[0], [np.sqrt(2.0), np.sqrt(2.0)], atol=1e-12)
    np.testing.assert_array_equal(tpl.offsets, Template.polygon(4, 2.0, phase=np.pi / 4).offsets)


def test_single_drone_templates_sit_at_the_origin():
    for tpl in (Template.polygon(1), Template.line(1), Template.grid(1, 1, dim=3)):
        np.testing.assert_array_equal(tpl.offsets, 0.0)
        assert tpl.n == 1 and tpl.min_distance() == np.inf


@pytest.mark.parametrize("dim", [2, 3])
def test_line(dim):
    tpl = Template.line(5, spacing=0.7, dim=dim)
    assert (tpl.n, tpl.dim) == (5, dim)
    assert_centred(tpl)
    np.testing.assert_allclose(tpl.offsets[:, 0], 0.7 * np.arange(-2, 3))
    np.testing.assert_array_equal(tpl.offsets[:, 1:], 0.0)
    assert tpl.min_distance() == pytest.approx(0.7)


@pytest.mark.parametrize(
    ("rows", "cols", "layers", "dim"), [(2, 3, 1, 2), (4, 4, 1, 2), (2, 3, 1, 3), (2, 3, 4, 3)]
)
def test_grid(rows, cols, layers, dim):
    tpl = Template.grid(rows, cols, spacing=0.5, dim=dim, layers=layers)
    assert (tpl.n, tpl.dim) == (rows * cols * layers, dim)
    assert_centred(tpl)
    assert tpl.min_distance() == pytest.approx(0.5)
    # every point is on the lattice: integer multiples of the spacing after a half-cell shift
    extents = np.array([rows, cols, layers][:dim])
    cells = tpl.offsets / 0.5 + (extents - 1) / 2
    np.testing.assert_allclose(cells, np.round(cells), atol=1e-12)
    assert len({tuple(c) for c in np.round(cells).astype(int)}) == tpl.n
    if dim == 3 and layers == 1:
        np.testing.assert_array_equal(tpl.offsets[:, 2], 0.0)


@pytest.mark.parametrize("n", [4, 10, 30, 100])
def test_sphere(n):
    radius = 2.0
    tpl = Template.sphere(n, radius=radius)
    assert (tpl.n, tpl.dim) == (n, 3)
    assert_centred(tpl)
    # The points are a translated sphere of `radius`: disjoint caps of chord radius d/2 each
    # cover pi d^2 / 4 of the 4 pi R^2 surface, so d <= 4 R / sqrt(n). Spread evenly, d is of
    # the order of the equal-area spacing sqrt(4 pi / n) R.
    spacing = np.sqrt(4 * np.pi / n) * radius
    assert 0.5 * spacing <= tpl.min_distance() <= 4 * radius / np.sqrt(n)
    assert np.ptp(tpl.offsets[:, 2]) == pytest.approx(2 * radius * (1 - 1 / n))
