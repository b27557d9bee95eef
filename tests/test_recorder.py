"""The recorder's metrics frame, built column by column, is the frame pandas infers from the rows.

:func:`~wuerfel_cvx.step.recorder.typed_metrics` types each column itself;
:func:`~wuerfel_cvx.step.recorder.inferred_metrics` is pandas' own inference from the list of
row dicts (the reference, and the fallback).  Their frames must agree in columns, dtypes and
every value, for the kinds of values the rows of a run, an asleep step, the Coulomb fixed
point and a peer engine hold, and for the kinds the typed path leaves to the reference.
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np
import pandas as pd
import pytest

from wuerfel_cvx.scenes.geometry import FloatArray
from wuerfel_cvx.scenes.scene import Scene
from wuerfel_cvx.step.metrics import STATE_COLUMNS, state_metrics
from wuerfel_cvx.step.model import Model, State
from wuerfel_cvx.step.recorder import (
    METRIC_COLUMNS,
    inferred_metrics,
    typed_metrics,
)
from wuerfel_cvx.step.simulation import Simulation
from wuerfel_cvx.step.sleep import SleepSettings
from wuerfel_cvx.trajectory import NULLABLE_COLUMNS

pytestmark = pytest.mark.unit

ROWS = 6
_KINDS: dict[str, list[Any]] = {
    "float": [0.5, -1.25, np.nan, 3.0, 1e300, -0.0],
    "numpy float": [np.float64(0.5), 2.5, np.float64(np.nan), 3.0, 1e-300, 7.0],
    "int": [0, 1, -5, 2**40, 3, 4],
    "numpy int": [np.int64(2), 1, np.int64(-3), 0, 9, 2],
    "bool": [True, False, True, True, np.bool_(False), False],
    "str": ["optimal", "asleep", "polished (gap)", "", "OSQP+CLARABEL", "x"],
    "NA": [pd.NA] * ROWS,
    "int or NA": [pd.NA, 3, 0, pd.NA, 7, 1],
    "bool or NA": [True, pd.NA, False, pd.NA, True, True],
    "float or NA": [0.5, pd.NA, np.nan, 2.0, pd.NA, 1.0],
    # left to the reference: pandas' inference is not a NumPy array of one type
    "int and float": [1, 2.5, 3, 4, 5, 6],
    "bool and float": [True, 0.5, False, True, 1.0, 0.0],
    "None": [None, 1.0, 2.0, None, 3.0, 4.0],
    "str or None": ["a", None, "b", "c", "d", "e"],
    "uint64": [2**63, 1, 2, 3, 4, 5],
    "float32": [np.float32(1.5)] * ROWS,
}


def _model() -> Model:
    return Model.from_scene(Scene.named("tilted-drop"))


def _frames(rows: list[dict[str, Any]], dtypes: dict[str, str]
            ) -> tuple[pd.DataFrame | None, pd.DataFrame]:
    return _typed(rows, dtypes), _inferred(rows, dtypes)


def _states(rows: int) -> tuple[FloatArray, FloatArray]:
    state = State.initial(Scene.named("tilted-drop"))
    rng = np.random.default_rng(3)
    points = state.points + rng.normal(size=(rows + 1, *state.points.shape))
    return points, rng.normal(size=points.shape)


def _typed(rows: list[dict[str, Any]], dtypes: dict[str, str]) -> pd.DataFrame | None:
    points, velocities = _states(len(rows))
    return typed_metrics(rows, state_metrics(_model(), points[1:], velocities[1:]), dtypes)


def _inferred(rows: list[dict[str, Any]], dtypes: dict[str, str]) -> pd.DataFrame:
    points, velocities = _states(len(rows))
    return inferred_metrics(rows, state_metrics(_model(), points[1:], velocities[1:]), dtypes)


def _assert_identical(typed: pd.DataFrame, inferred: pd.DataFrame) -> None:
    assert list(typed.columns) == list(METRIC_COLUMNS) == list(inferred.columns)
    assert [repr(dtype) for dtype in typed.dtypes] == [repr(dtype) for dtype in inferred.dtypes]
    pd.testing.assert_frame_equal(typed, inferred, check_exact=True)


def _rows(kind: str) -> list[dict[str, Any]]:
    """Rows whose every column (but the state's) holds the values of ``kind``."""
    return [{name: _KINDS[kind][index] for name in METRIC_COLUMNS if name not in STATE_COLUMNS}
            for index in range(ROWS)]


@pytest.mark.filterwarnings("ignore:invalid value encountered in cast:RuntimeWarning")
@pytest.mark.parametrize("kind", list(_KINDS))
@pytest.mark.parametrize("cast", [None, "Int64", "boolean", "Float64"])
def test_each_kind_of_column_is_typed_as_pandas_infers_it(kind: str, cast: str | None) -> None:
    dtypes = {} if cast is None else {"iterations": cast}
    try:
        expected = _inferred(_rows(kind), dtypes)
    except (TypeError, ValueError) as refused:  # a cast pandas refuses: refused alike,
        try:  # or left to the reference, which refuses it
            assert _typed(_rows(kind), dtypes) is None
        except type(refused):
            pass
        return
    typed = _typed(_rows(kind), dtypes)
    if typed is not None:  # None: left to the reference, which built ``expected``
        _assert_identical(typed, expected)


@pytest.mark.parametrize("kind", ["float", "int", "bool", "str", "NA", "int or NA"])
def test_the_common_kinds_take_the_typed_path(kind: str) -> None:
    typed, inferred = _frames(_rows(kind), {})
    if kind in ("NA", "int or NA"):  # a column of objects: pandas' own
        assert typed is None
    else:
        assert typed is not None
        _assert_identical(typed, inferred)


def test_rows_without_some_columns_hold_nan_there() -> None:
    rows = [{"step": step, "solver": "PEER", "verified": pd.NA} for step in (1, 2, 3)]
    typed, inferred = _frames(rows, {"verified": "boolean", **NULLABLE_COLUMNS})
    assert typed is not None
    _assert_identical(typed, inferred)
    assert typed["time_s"].isna().all() and typed["coulomb_iterations"].isna().all()


def test_a_numpy_cast_is_left_to_the_reference() -> None:
    rows = _rows("int")
    typed, inferred = _frames(rows, {"iterations": "float64"})
    assert typed is None and inferred["iterations"].dtype == np.float64


@pytest.mark.integration
@pytest.mark.parametrize(("scene", "options"), [
    ("tilted-drop", {}), ("card-house", {"friction_model": "coulomb"}),
    ("stack-10", {"sleep": SleepSettings(speed=1.0, time=0.0)})])  # every step asleep
def test_a_run_records_the_frame_pandas_would_infer(scene: str, options: dict[str, Any]
                                                    ) -> None:
    simulation = Simulation(Scene.named(scene), **options)
    for _ in range(25):
        simulation.step()
    run = simulation.trajectory()
    inferred = inferred_metrics(simulation.recorder.rows,
                                state_metrics(simulation.model, run.points[1:],
                                              run.velocities[1:]), dict(NULLABLE_COLUMNS))
    _assert_identical(run.metrics, inferred)


def test_every_pair_of_kinds_in_one_frame_agrees() -> None:
    typed_kinds = ["float", "int", "bool", "str", "int or NA"]
    for first, second in itertools.combinations(typed_kinds, 2):
        rows = [{**row, "step": other["step"]} for row, other in
                zip(_rows(first), _rows(second), strict=True)]
        typed, inferred = _frames(rows, {"step": "Int64"} if "NA" in second else {})
        if typed is not None:
            _assert_identical(typed, inferred)
