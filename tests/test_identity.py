"""One contact identity across steps (:mod:`wuerfel_cvx.step.contacts`).

The matcher, exact at any index, and the two uses it carries: the warm starts and the
Coulomb friction memory.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from wuerfel_cvx import Scene
from wuerfel_cvx.formulations import StepQP, get_formulation, step_qp
from wuerfel_cvx.friction.coulomb import CoulombStep, FrictionMemory
from wuerfel_cvx.friction.forces import ContactForces
from wuerfel_cvx.solve.warm_start import WarmStarts
from wuerfel_cvx.step.contacts import ContactIndex
from wuerfel_cvx.step.model import Model, State

pytestmark = pytest.mark.unit

BEYOND_16_BITS = 1 << 18
"""An offset of point indices past what 16-bit packed ids held (2**16 points, 16 384 boxes)."""


def sorted_places(indexed: np.ndarray, wanted: np.ndarray) -> np.ndarray:
    """The oracle: each ``wanted`` row's place in ``indexed`` by sorting both, -1 if absent."""
    both = np.concatenate([indexed, wanted])
    order = np.lexsort(both.T[::-1])  # stable: an indexed row precedes an equal wanted one
    ordered = both[order]
    pair = (np.all(ordered[1:] == ordered[:-1], axis=1) & (order[:-1] < len(indexed))
            & (order[1:] >= len(indexed)))
    places = np.full(len(wanted), -1, dtype=np.int64)
    places[order[1:][pair] - len(indexed)] = order[:-1][pair]
    return places


@pytest.mark.parametrize("high", [1 << 8, 1 << 17, 1 << 40])
def test_the_matcher_finds_every_id_and_only_those_at_any_index(high: int) -> None:
    rng = np.random.default_rng(high)
    ids = np.unique(rng.integers(0, high, size=(3000, 3)), axis=0)
    ids = ids[rng.permutation(len(ids))]
    kept, gone = ids[:2000], ids[2000:]
    wanted = np.concatenate([kept[rng.permutation(len(kept))][:1500], gone[:300]])
    wanted = wanted[rng.permutation(len(wanted))]
    index = ContactIndex.of(kept)
    places = index.find(wanted)
    np.testing.assert_array_equal(places, sorted_places(kept, wanted))
    found = places >= 0
    assert np.count_nonzero(found) == 1500
    np.testing.assert_array_equal(kept[places[found]], wanted[found])


def test_the_matcher_tells_ids_apart_that_differ_in_one_column_only() -> None:
    base = np.array([[70_000, 280_001, 280_000]], dtype=np.int64)
    near = np.concatenate([base + shift for shift in np.eye(3, dtype=np.int64)])
    index = ContactIndex.of(np.concatenate([near, base]))
    np.testing.assert_array_equal(index.find(np.concatenate([base, near[::-1]])), [3, 2, 1, 0])


def test_the_matcher_on_empty_sets() -> None:
    none = np.zeros((0, 3), dtype=np.int64)
    some = np.array([[1, 2, 3]])
    assert ContactIndex.of(none).find(some).tolist() == [-1]
    assert ContactIndex.of(some).find(none).shape == (0,)
    np.testing.assert_array_equal(ContactIndex.empty().carry(np.zeros(0), some), [0.0])
    with pytest.raises(ValueError, match="ids must be"):
        ContactIndex.of(some).find(np.array([[1, 2]]))


def _far_numbered(qp: StepQP, order: np.ndarray) -> StepQP:
    """``qp``'s contacts in ``order``, numbered past 16-bit point indices; its rows to match."""
    c = qp.contacts
    contacts = dataclasses.replace(
        c.selected(order), point=c.point[order] + BEYOND_16_BITS,
        edge_i=c.edge_i[order] + BEYOND_16_BITS, edge_j=c.edge_j[order] + BEYOND_16_BITS)
    return dataclasses.replace(qp, ineq_matrix=qp.ineq_matrix[order],
                               ineq_rhs=qp.ineq_rhs[order], contacts=contacts)


def test_one_identity_carries_warm_starts_and_friction_impulses_past_16_bits() -> None:
    """A QP's row multipliers and contact friction impulses are found by the contacts' ids.

    Kept at one step, they are found at the next by the same contacts' ids, though every
    index is past 2**16 and the contacts come in another order.
    """
    scene = Scene.named("stack-3")
    qp = step_qp(get_formulation("rigid"), Model.from_scene(scene), State.initial(scene), 0.01)
    count = len(qp.contacts)
    assert count > 0 and qp.n_inequalities == count and qp.cones is None
    last = _far_numbered(qp, np.arange(count))
    assert int(last.contacts.point.min()) >= 1 << 16
    order = np.arange(count)[::-1].copy()
    now = _far_numbered(qp, order)
    values = np.arange(1.0, count + 1)

    warm = WarmStarts()
    warm.remember("PROXQP", last, np.ones(qp.n_variables), np.zeros(qp.n_equalities), values,
                  1.0)
    guess = warm.guess("PROXQP", now, 1.0)
    assert guess is not None and guess.matched_rows == count
    np.testing.assert_array_equal(guess.ineq_dual, values[order])

    zero = np.zeros(count)
    memory = FrictionMemory(n_boxes=BEYOND_16_BITS)
    memory.remember([(CoulombStep(last, [], [], True, ContactForces(zero, zero, values, zero)),
                      None)])
    np.testing.assert_array_equal(memory.initial(now.contacts, None), values[order])
