"""One identity for a contact across steps, and where this step's contacts were last step.

A contact is named by its point and its edge: the indices of the point and of the edge's two
corners in the all-points array (:meth:`~wuerfel_cvx.model.Model.all_points`), one int64 row
``(point, edge_i, edge_j)`` of a :data:`ContactIds` array
(:meth:`~wuerfel_cvx.contacts.Contacts.ids`).  The same contact found again in the next state
has the same ids, whatever its place in the list.  The ids are plain integers, not packed
into one word, so a scene may have any number of points.

Two things are carried from step to step by it, through one matcher (:class:`ContactIndex`):

* the warm starts (:mod:`wuerfel_cvx.warm_start`): a QP row is named by ``(block, contact)``,
  its block of rows (``velocity``'s rate rows, then its approach rows) and its contact's ids,
  so a row's last multiplier is found as its contact's place in the last QP;
* the Coulomb fixed point's friction impulses (:class:`~wuerfel_cvx.coulomb.FrictionMemory`,
  from one step to the next, and from one pass's contacts to the next pass's).

Matching.  :meth:`ContactIndex.of` puts one set of ids in a hash table (open addressing,
linear probing, a power-of-two size at least twice the count): each id's slot is a hash of
its columns (products with odd constants, added, then mixed and its high bits taken, all in
wrapping 64-bit arithmetic); :meth:`ContactIndex.find` looks another set's ids up, comparing
whole ids, so the answer is exact whatever the hash: each id's place in the indexed set, or
-1.  Time O(n + m) for n indexed and m looked-up ids, where sorting would be O((n + m) log);
the hashes are NumPy array operations and the probing two compiled loops
(:func:`~wuerfel_cvx._numba.compiled`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ._numba import compiled
from .geometry import FloatArray
from .model import IntArray

ContactIds = IntArray
"""Contacts' ids ``(n, 3)`` int64: each row a contact's ``(point, edge_i, edge_j)``."""

_COLUMN_FACTORS = (0x9E3779B97F4A7C15, 0xC2B2AE3D27D4EB4F, 0x165667B19E3779F9)
"""Odd 64-bit constants, one per id column, whose products with the column are added."""
_MIX_FACTOR = 0xBF58476D1CE4E5B9
"""The odd constant whose product's high bits are the slot (multiplicative hashing)."""


def _slots(ids: IntArray, bits: int) -> IntArray:
    """Each id's first slot in a table of ``2**bits`` slots (``1 <= bits <= 63``)."""
    words = ids.astype(np.uint64)
    hashed = np.zeros(ids.shape[0], dtype=np.uint64)
    for column in range(ids.shape[1]):
        factor = np.uint64(_COLUMN_FACTORS[column % len(_COLUMN_FACTORS)])
        hashed += words[:, column] * factor  # wraps modulo 2**64, as meant
    hashed ^= hashed >> np.uint64(29)
    hashed *= np.uint64(_MIX_FACTOR)
    return (hashed >> np.uint64(64 - bits)).astype(np.int64)


@compiled
def _table(slots: IntArray, size: int) -> IntArray:
    """A table of ``size`` (a power of two) slots holding each row's place, -1 where empty."""
    table = np.full(size, -1, dtype=np.int64)
    for row in range(slots.shape[0]):
        slot = slots[row]
        while table[slot] >= 0:
            slot = (slot + 1) & (size - 1)
        table[slot] = row
    return table


@compiled
def _lookup(table: IntArray, ids: IntArray, wanted: IntArray, slots: IntArray) -> IntArray:
    """Each ``wanted`` row's place in ``ids`` (indexed in ``table``), -1 where it is not."""
    mask = table.shape[0] - 1
    found = np.full(wanted.shape[0], -1, dtype=np.int64)
    for row in range(wanted.shape[0]):
        slot = slots[row]
        while table[slot] >= 0:
            held = table[slot]
            same = True
            for column in range(ids.shape[1]):
                if ids[held, column] != wanted[row, column]:
                    same = False
                    break
            if same:
                found[row] = held
                break
            slot = (slot + 1) & mask
    return found


@dataclass(frozen=True)
class ContactIndex:
    """A set of contacts' ids, indexed to find other contacts' places in it by their ids."""

    ids: ContactIds
    """The indexed ids ``(n, k)`` int64, in their order (distinct, as one state's are)."""
    _table: IntArray
    """The hash table: per slot the place in :attr:`ids` of the id it holds, -1 if none."""

    @classmethod
    def of(cls, ids: NDArray[np.integer]) -> ContactIndex:
        """``ids`` ``(n, k)`` indexed, each row one contact's ids (a repeated row: its first)."""
        held = np.ascontiguousarray(ids, dtype=np.int64)
        if held.ndim != 2:
            raise ValueError(f"ids must be (n, k), got shape {held.shape}")
        bits = max(1, int(2 * held.shape[0] - 1).bit_length())  # 2**bits >= 2 n
        return cls(held, _table(_slots(held, bits), 1 << bits))

    @classmethod
    def empty(cls) -> ContactIndex:
        """No contacts."""
        return cls.of(np.zeros((0, 3), dtype=np.int64))

    def __len__(self) -> int:
        return int(self.ids.shape[0])

    def find(self, ids: NDArray[np.integer]) -> IntArray:
        """Each row of ``ids`` ``(m, k)``: its place in :attr:`ids`, -1 if it is not there."""
        wanted = np.ascontiguousarray(ids, dtype=np.int64)
        if wanted.ndim != 2 or wanted.shape[1] != self.ids.shape[1]:
            raise ValueError(f"ids must be (m, {self.ids.shape[1]}), got shape {wanted.shape}")
        bits = self._table.shape[0].bit_length() - 1
        return _lookup(self._table, self.ids, wanted, _slots(wanted, bits))

    def carry(self, values: FloatArray, ids: NDArray[np.integer]) -> FloatArray:
        """``values`` (one per indexed contact) moved to the contacts ``ids``, 0 for a new one."""
        place = self.find(ids)
        found = place >= 0
        carried = np.zeros(place.shape[0])
        carried[found] = values[place[found]]
        return carried
