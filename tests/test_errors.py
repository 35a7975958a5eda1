"""The exception tree (``mpcform.errors``): every error of the package is an MPCFormError, input
errors are also ValueErrors, and each carries its context (field, solver) in its message."""

from __future__ import annotations

import ast
import importlib
import pickle
from pathlib import Path

import pytest

from mpcform.errors import MPCFormError, ScenarioError, SolverError, ValidationError

PACKAGE = Path(__file__).resolve().parents[1] / "mpcform"


def test_the_tree() -> None:
    assert issubclass(ValidationError, MPCFormError) and issubclass(ValidationError, ValueError)
    assert issubclass(ScenarioError, ValidationError) and issubclass(ScenarioError, ValueError)
    assert issubclass(SolverError, MPCFormError) and not issubclass(SolverError, ValueError)
    assert issubclass(MPCFormError, Exception) and not issubclass(MPCFormError, ValueError)


def test_validation_error_names_the_field() -> None:
    err = ValidationError("controller.horizon", "expected an integer >= 1, got 0")
    assert err.field == "controller.horizon"
    assert str(err) == "controller.horizon: expected an integer >= 1, got 0"
    assert err.args == ("controller.horizon: expected an integer >= 1, got 0",)


def test_scenario_error_is_caught_as_a_validation_error() -> None:
    with pytest.raises(ValidationError) as info:
        raise ScenarioError("scenario.toml", "cannot parse line 3")
    assert info.value.field == "scenario.toml" and str(info.value) == "scenario.toml: cannot parse line 3"


def test_solver_error_names_the_solver() -> None:
    err = SolverError("qpsolvers:nope", "not installed")
    assert err.solver == "qpsolvers:nope"
    assert str(err) == "solver 'qpsolvers:nope': not installed"


@pytest.mark.parametrize(
    "err",
    [ValidationError("f", "m"), ScenarioError("f", "m"), SolverError("s", "m"), MPCFormError("plain")],
)
def test_one_except_catches_them_all(err: MPCFormError) -> None:
    with pytest.raises(MPCFormError):
        raise err


def _public_exception_classes() -> list[tuple[str, str]]:
    """(module, class) of every public class in the package deriving from an exception."""
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        module = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
                bases = [b.id if isinstance(b, ast.Name) else getattr(b, "attr", "") for b in node.bases]
                if any(b.endswith(("Error", "Exception")) for b in bases):
                    found.append((module, node.name))
    return found


def test_every_public_error_of_the_package_is_an_mpcform_error() -> None:
    classes = _public_exception_classes()
    assert ("mpcform.errors", "SolverError") in classes and len(classes) >= 5
    for module, name in classes:
        cls = getattr(importlib.import_module(module), name)
        assert issubclass(cls, MPCFormError), f"{module}.{name} is not an MPCFormError"


@pytest.mark.parametrize("err", [ValidationError("dt", "bad"), SolverError("osqp", "bad")])
def test_errors_survive_pickling(err: MPCFormError) -> None:
    back = pickle.loads(pickle.dumps(err))
    assert type(back) is type(err) and str(back) == str(err) and back.args == err.args


def test_the_base_error_survives_pickling() -> None:
    back = pickle.loads(pickle.dumps(MPCFormError("plain")))
    assert type(back) is MPCFormError and str(back) == "plain"


def test_a_large_bad_value_is_echoed_cut_short() -> None:
    """A list of 1000 zeros given for template.radius is named in one short line, not 6000 characters."""
    from mpcform.errors import shown
    from mpcform.scenario.load import scenario_from_dict

    assert shown([0.0] * 1000) == "[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, ...]" and shown(0.25) == "0.25"
    assert len(shown("x" * 10_000)) <= 62 and shown(float("inf")) == "inf"
    doc = {
        "version": 1,
        "name": "x",
        "dim": 2,
        "template": {"shape": "polygon", "n": 3, "radius": [0.0] * 1000},
    }
    with pytest.raises(ScenarioError) as info:
        scenario_from_dict(doc)
    assert "template.radius" in str(info.value) and len(str(info.value)) < 200
