"""Communication graphs: families, Laplacian and spectrum, connectivity errors, [graph] parsing."""

from __future__ import annotations

import tomllib
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from mpcform import Graph, ScenarioError, Template, ValidationError
from mpcform.control.graph import DisconnectedGraphWarning, describe_components
from mpcform.scenario.build import build_controller
from mpcform.scenario.load import scenario_from_dict

ROOT = Path(__file__).resolve().parents[2]
RING = ROOT / "scenarios" / "consensus_ring.toml"


def dense_laplacian(g: Graph) -> np.ndarray:
    a = np.zeros((g.n, g.n))
    a[g.edges[:, 0], g.edges[:, 1]] = a[g.edges[:, 1], g.edges[:, 0]] = 1.0
    return np.diag(a.sum(axis=1)) - a


# ---- families ------------------------------------------------------------------------------
@pytest.mark.parametrize("n", [1, 2, 3, 8, 13])
def test_named_families(n: int) -> None:
    complete, ring, path = Graph.complete(n), Graph.ring(n), Graph.path(n)
    assert complete.m == n * (n - 1) // 2 and path.m == n - 1
    assert ring.m == (n if n > 2 else n - 1)
    for g in (complete, ring, path):
        assert g.is_connected and g.n == n
        assert np.all(g.edges[:, 0] < g.edges[:, 1])
        np.testing.assert_array_equal(g.laplacian.toarray(), dense_laplacian(g))
    if n > 1:
        assert complete.lambda_max == pytest.approx(n)
        assert path.lambda_max == pytest.approx(2.0 + 2.0 * np.cos(np.pi / n))
    if n > 2:
        assert set(ring.degrees.tolist()) == {2}
        assert ring.algebraic_connectivity == pytest.approx(2.0 - 2.0 * np.cos(2.0 * np.pi / n))
        np.testing.assert_array_equal(ring.neighbours(0), [1, n - 1])


def test_k_nearest_is_symmetric_and_recovers_the_ring() -> None:
    ring_template = Template.polygon(8).offsets
    knn = Graph.k_nearest(ring_template, 2)
    np.testing.assert_array_equal(knn.edges, Graph.ring(8).edges)
    rng = np.random.default_rng(4)
    pts = rng.uniform(-5.0, 5.0, (20, 3))
    g = Graph.k_nearest(pts, 3)
    assert np.all(g.degrees >= 3)
    dist = np.linalg.norm(pts[:, None] - pts[None], axis=-1)
    np.fill_diagonal(dist, np.inf)
    nearest = np.argsort(dist, axis=1)[:, :3]
    edges = {tuple(e) for e in g.edges.tolist()}
    for i in range(20):
        for j in nearest[i]:
            assert (min(i, j), max(i, j)) in edges


def test_disk_graph_matches_brute_force() -> None:
    rng = np.random.default_rng(5)
    pts = rng.uniform(0.0, 4.0, (30, 2))
    g = Graph.disk(pts, 1.1)
    dist = np.linalg.norm(pts[:, None] - pts[None], axis=-1)
    i, j = np.nonzero(np.triu(dist <= 1.1, 1))
    assert {tuple(e) for e in g.edges.tolist()} == set(zip(i.tolist(), j.tolist(), strict=True))


def test_explicit_edges_are_normalised() -> None:
    g = Graph.from_edges(4, [[1, 0], [0, 1], [2, 3], [3, 2], [1, 2]])
    assert g.edges.tolist() == [[0, 1], [1, 2], [2, 3]] and g.kind == "explicit"
    assert Graph.from_edges(3, []).m == 0
    with pytest.raises(ValueError):
        g.edges[0, 0] = 5  # frozen


@pytest.mark.parametrize(
    ("edges", "fragment"),
    [
        ([[0, 0]], "self-loop"),
        ([[0, 4]], "outside [0, 3]"),
        ([[-1, 2]], "outside"),
        ([[0, 1.5]], "integer"),
        ([[0, 1, 2]], "pairs"),
        ([[True, 1]], "integer"),
    ],
)
def test_bad_edges_name_the_field(edges: Any, fragment: str) -> None:
    with pytest.raises(ValidationError, match="graph.edges") as err:
        Graph.from_edges(4, edges)
    assert err.value.field == "graph.edges" and fragment in str(err.value)


def test_bad_parameters() -> None:
    pts = Template.polygon(5).offsets
    for k in (0, 5, 2.0, True):
        with pytest.raises(ValidationError) as err:
            Graph.k_nearest(pts, k)  # type: ignore[arg-type]
        assert err.value.field == "graph.k"
    with pytest.raises(ValidationError) as err:
        Graph.disk(pts, 0.0)
    assert err.value.field == "graph.radius"
    with pytest.raises(ValidationError) as err:
        Graph.ring(0)
    assert err.value.field == "graph.n"


# ---- spectrum and connectivity --------------------------------------------------------------
@given(st.integers(1, 12), st.lists(st.tuples(st.integers(0, 11), st.integers(0, 11)), max_size=30))
def test_laplacian_spectrum_counts_components(n: int, pairs: list[tuple[int, int]]) -> None:
    edges = [(i, j) for i, j in pairs if i < n and j < n and i != j]
    g = Graph.from_edges(n, edges)
    lap = g.laplacian.toarray()
    np.testing.assert_allclose(lap, lap.T)
    np.testing.assert_allclose(lap.sum(axis=1), 0.0, atol=1e-12)
    spectrum = g.laplacian_spectrum
    assert spectrum[0] > -1e-9 and g.lambda_max == pytest.approx(spectrum[-1], abs=1e-12)
    assert int((spectrum < 1e-9).sum()) == len(g.components)
    assert sorted(np.concatenate(g.components).tolist()) == list(range(n))
    assert g.is_connected == (len(g.components) == 1)


def test_two_clusters_disk_graph_is_a_clear_error() -> None:
    pts = np.r_[Template.polygon(4).offsets, Template.polygon(4).offsets + 10.0]
    g = Graph.disk(pts, 2.0)
    assert [c.tolist() for c in g.components] == [[0, 1, 2, 3], [4, 5, 6, 7]]
    with pytest.raises(ValidationError) as err:
        g.check_connected()
    msg = str(err.value)
    assert err.value.field == "graph.radius"
    assert "disconnected: 2 components {0, 1, 2, 3}, {4, 5, 6, 7}" in msg
    assert "raise the radius" in msg and "allow_disconnected" in msg
    with pytest.warns(DisconnectedGraphWarning, match="running anyway"):
        g.check_connected(allow_disconnected=True)
    with pytest.raises(ValidationError) as err:
        Graph.from_edges(3, [[0, 1]]).check_connected()
    assert err.value.field == "graph.edges" and "{2}" in str(err.value)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        Graph.ring(5).check_connected()  # connected: neither error nor warning


def test_describe_components_truncates() -> None:
    text = describe_components((np.arange(20), np.array([20])), limit=3)
    assert text == "{0, 1, 2, ... (20 drones)}, {20}"


# ---- the [graph] scenario table ---------------------------------------------------------------
def ring_dict(graph: dict[str, Any] | None) -> dict[str, Any]:
    data = tomllib.loads(RING.read_text())
    if graph is None:
        del data["graph"]
    else:
        data["graph"] = graph
    return data


@pytest.mark.parametrize(
    ("graph", "edges"),
    [
        ({"kind": "ring"}, Graph.ring(8).edges),
        ({"kind": "path"}, Graph.path(8).edges),
        ({"kind": "complete"}, Graph.complete(8).edges),
        ({"kind": "k_nearest", "k": 2}, Graph.ring(8).edges),
        ({"kind": "disk", "radius": 0.8}, Graph.ring(8).edges),  # neighbours are 0.765 m apart
        ({"kind": "disk", "radius": 0.8, "on": "initial"}, Graph.ring(8).edges),
        (
            {"kind": "explicit", "edges": [[0, 1], [1, 2], [2, 3], [3, 4], [4, 5], [5, 6], [6, 7]]},
            Graph.path(8).edges,
        ),
    ],
)
def test_graph_table_kinds(graph: dict[str, Any], edges: np.ndarray) -> None:
    s = scenario_from_dict(ring_dict(graph))
    assert s.graph is not None
    np.testing.assert_array_equal(s.graph.edges, edges)
    assert s.network.delay_steps == 0 and s.network.loss_probability == 0.0
    assert s.allow_disconnected is False


@pytest.mark.parametrize(
    ("graph", "field", "fragment"),
    [
        ({"kind": "star"}, "graph.kind", "expected one of"),
        ({"kind": "ring", "radius": 1.0}, "graph.radius", "does not apply"),
        ({"kind": "disk"}, "graph.radius", "missing"),
        ({"kind": "k_nearest", "k": 8}, "graph.k", "[1, n - 1 = 7]"),
        ({"kind": "explicit", "edges": [[0, 8]]}, "graph.edges", "outside [0, 7]"),
        ({"kind": "explicit", "edges": [0, 1]}, "graph.edges", "pairs"),
        ({"kind": "ring", "loss_probability": 1.0}, "graph.loss_probability", "[0, 1)"),
        ({"kind": "ring", "delay_steps": -1}, "graph.delay_steps", ">= 0"),
        ({"kind": "ring", "relative_positions": "guessed"}, "graph.relative_positions", "one of"),
        ({"kind": "ring", "delay": 2}, "graph.delay", "did you mean 'delay_steps'"),
    ],
)
def test_graph_table_errors_name_the_key(graph: dict[str, Any], field: str, fragment: str) -> None:
    with pytest.raises(ScenarioError) as err:
        scenario_from_dict(ring_dict(graph))
    assert err.value.field == field and fragment in str(err.value)


def test_disconnected_scenario_graph_errors_when_the_controller_is_built() -> None:
    s = scenario_from_dict(ring_dict({"kind": "disk", "radius": 0.5}))  # no pair that close
    with pytest.raises(ScenarioError) as err:
        build_controller(s)
    assert err.value.field == "graph.radius" and "8 components" in str(err.value)
    assert build_controller(s, "tracking").name == "tracking"  # other controllers ignore [graph]
    allowed = scenario_from_dict(ring_dict({"kind": "disk", "radius": 0.5, "allow_disconnected": True}))
    with pytest.warns(DisconnectedGraphWarning):
        assert build_controller(allowed).name == "consensus"


def test_consensus_without_graph_table_is_an_error() -> None:
    s = scenario_from_dict(ring_dict(None))
    assert s.graph is None
    with pytest.raises(ScenarioError, match=r"missing table \[graph\]") as err:
        build_controller(s)
    assert err.value.field == "graph"
