"""The compiled row assembly (numba) equals the NumPy row assembly bit for bit.

:func:`wuerfel_cvx.formulations.qp.point_rows` and
:func:`wuerfel_cvx.formulations.rigid.body_rows` run their NumPy paths with
``_numba.enabled`` false (the reference) and the kernels of :mod:`wuerfel_cvx.row_kernel`
with it true; both must give the same canonical CSR matrices (shape, index arrays and their
dtypes, values) on the rows of library states and random states, and the same built QPs.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from kernel_paths import both
from test_contacts_fast import (
    LIBRARY,
    assert_same_matrix,
    library_states,
    random_model,
    random_points,
)
from wuerfel_cvx import row_kernel
from wuerfel_cvx.contacts import find_contacts
from wuerfel_cvx.formulations import get_formulation
from wuerfel_cvx.formulations.qp import point_rows
from wuerfel_cvx.formulations.rigid import body_rows
from wuerfel_cvx.formulations.rows import (
    held_table_blocks,
    n_unknown_points,
    rod_blocks,
    rod_rows,
    seed_side_blocks,
    side_blocks,
    side_rows,
)
from wuerfel_cvx.formulations.velocity import VelocityFormulation
from wuerfel_cvx.model import Model, State

pytestmark = [pytest.mark.integration,
              pytest.mark.skipif(not row_kernel.AVAILABLE, reason="numba is not installed")]


def assert_same_rows(monkeypatch: pytest.MonkeyPatch, model: Model, state: State) -> int:
    """Every block kind's rows and the rigid body rows agree; the number of contacts."""
    reach = VelocityFormulation().body_reach(model, state, 0.01)
    contacts = find_contacts(model, state.points, reach)
    all_points = model.all_points(state.points)
    n_unknown = n_unknown_points(model)
    block_sets = [side_blocks(all_points, contacts, model),
                  seed_side_blocks(all_points, contacts, model),
                  rod_blocks(model, state.points)[0], held_table_blocks(model)]
    for blocks in block_sets:
        rows = len(blocks[0][0]) if blocks else 0
        reference, compiled = both(monkeypatch, lambda b=blocks, r=rows: point_rows(
            r, n_unknown, b))
        assert_same_matrix(compiled, reference)
    reference, compiled = both(monkeypatch, lambda: side_rows(all_points, contacts, model))
    assert_same_matrix(compiled, reference)
    reference, compiled = both(monkeypatch, lambda: rod_rows(model, state.points))
    assert_same_matrix(compiled[0], reference[0])
    assert compiled[1].tobytes() == reference[1].tobytes()
    if model.table_mass is None:
        corner_rows = point_rows(len(contacts), n_unknown, block_sets[0])
        reference, compiled = both(monkeypatch, lambda: body_rows(corner_rows, state.points))
        assert_same_matrix(compiled, reference)
    return len(contacts)


@pytest.mark.parametrize("name", sorted(LIBRARY))
def test_library_states_give_the_same_rows(monkeypatch: pytest.MonkeyPatch, name: str) -> None:
    model, states = library_states(name)
    found = 0
    for state in states:
        found += assert_same_rows(monkeypatch, model, state)
        found += assert_same_rows(monkeypatch, Model.from_scene(model.scene, table_mass=1e3),
                                  state)
    assert found > 0


@pytest.mark.parametrize("seed", range(16))
def test_random_states_give_the_same_rows(monkeypatch: pytest.MonkeyPatch, seed: int) -> None:
    rng = np.random.default_rng(3000 + seed)
    n_squares = int(rng.integers(2, 50))
    model = random_model(n_squares, rng, table_mass=1e3 if seed % 4 == 0 else None,
                         n_tables=seed % 3)
    points = random_points(n_squares, rng, float(rng.choice([1.0, 3.0])))
    assert assert_same_rows(monkeypatch, model, State(points, rng.normal(size=points.shape))) > 0


def test_a_point_twice_in_a_row_is_summed_as_the_numpy_path_sums_it(
        monkeypatch: pytest.MonkeyPatch) -> None:
    rng = np.random.default_rng(7)
    index = rng.integers(-1, 4, size=(30, 3))
    index[:5, 1] = index[:5, 0] = 2  # duplicates: the kernel hands these back to scipy
    blocks = [(index[:, b], rng.normal(size=(30, 2))) for b in range(3)]
    reference, compiled = both(monkeypatch, lambda: point_rows(30, 4, blocks))
    assert_same_matrix(compiled, reference)
    assert isinstance(compiled, sp.csr_array)


@pytest.mark.parametrize("formulation", ["velocity", "velocity-baumgarte", "rigid", "seed"])
def test_built_qps_are_bit_identical(monkeypatch: pytest.MonkeyPatch, formulation: str) -> None:
    model, states = library_states("stack-10")
    chosen = get_formulation(formulation)
    state = states[-1]
    contacts = find_contacts(model, state.points, chosen.body_reach(model, state, 0.01))
    reference, compiled = both(monkeypatch, lambda: chosen.build(model, state, contacts, 0.01))
    assert_same_matrix(compiled.ineq_matrix, reference.ineq_matrix)
    assert_same_matrix(compiled.eq_matrix, reference.eq_matrix)
    assert np.array_equal(compiled.ineq_rhs, reference.ineq_rhs)
    assert np.array_equal(compiled.target, reference.target)
