"""One identity for a contact across steps, and where this step's contacts were last step.

A contact is named by its point and its edge: the indices of the point and of the edge's two
corners in the all-points array (:meth:`~wuerfel_cvx.step.model.Model.all_points`), one int64 row
``(point, edge_i, edge_j)`` of a :data:`ContactIds` array
(:meth:`~wuerfel_cvx.step.contacts.Contacts.ids`).  The same contact found again in the next state
has the same ids, whatever its place in the list.  The ids are plain integers, not packed
into one word, so a scene may have any number of points.

Two things are carried from step to step by it, through one matcher (:class:`ContactIndex`):

* the warm starts (:mod:`wuerfel_cvx.solve.warm_start`): a QP row is named by ``(block, contact)``,
  its block of rows (``velocity``'s rate rows, then its approach rows) and its contact's ids,
  so a row's last multiplier is found as its contact's place in the last QP;
* the Coulomb fixed point's friction impulses
  (:class:`~wuerfel_cvx.friction.coulomb.FrictionMemory`,
  from one step to the next, and from one pass's contacts to the next pass's).

Matching.  :meth:`ContactIndex.of` puts one set of ids in a hash table (open addressing,
linear probing, a power-of-two size at least twice the count); :meth:`ContactIndex.find`
looks another set's ids up, comparing whole ids, so the answer is exact whatever the hash:
each id's place in the indexed set, or -1.  Time O(n + m) for n indexed and m looked-up ids
(sorting would be O((n + m) log(n + m)), and lexicographic sorting of three columns is
several sorts); each is one compiled loop (:func:`~wuerfel_cvx._numba.compiled`), so a small
scene pays a call, not a dozen NumPy operations.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .._numba import compiled
from ..scenes.geometry import FloatArray
from .model import IntArray

ContactIds = IntArray
"""Contacts' ids ``(n, 3)`` int64: each row a contact's ``(point, edge_i, edge_j)``."""


@compiled
def _slot(ids: IntArray, row: int, mask: int) -> int:
    """Row ``row`` of ``ids``: its first slot in a table of ``mask + 1`` slots (a power of 2).

    Each column is folded to 32 bits, mixed in, and the result multiplied by an odd 31-bit
    constant (a product below 2**63: no overflow) and shifted onto itself.
    """
    hashed = 0
    for column in range(ids.shape[1]):
        value = ids[row, column]
        hashed = ((hashed ^ value ^ (value >> 32)) & 0xFFFFFFFF) * 0x7FEB352D
        hashed ^= hashed >> 29
    return hashed & mask


@compiled
def _table(ids: IntArray, size: int) -> IntArray:
    """A table of ``size`` (a power of 2) slots holding each row's place, -1 where empty."""
    table = np.full(size, -1, dtype=np.int64)
    for row in range(ids.shape[0]):
        slot = _slot(ids, row, size - 1)
        while table[slot] >= 0:
            slot = (slot + 1) & (size - 1)
        table[slot] = row
    return table


@compiled
def _lookup(table: IntArray, ids: IntArray, wanted: IntArray) -> IntArray:
    """Each ``wanted`` row's place in ``ids`` (indexed in ``table``), -1 where it is not."""
    mask = table.shape[0] - 1
    found = np.full(wanted.shape[0], -1, dtype=np.int64)
    for row in range(wanted.shape[0]):
        slot = _slot(wanted, row, mask)
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


@compiled
def carry_rows(place: IntArray, values: FloatArray, indexed: int, blocks: int,
               out: FloatArray) -> int:
    """Rows of values moved to the contacts found at ``place``, in place; the rows moved.

    ``values`` holds blocks of rows, one row per indexed contact (row ``b * indexed + j``:
    block ``b``, contact ``j``); ``out`` the same blocks for the ``m = len(place)`` contacts
    looked up.  For each of the first ``blocks`` blocks and each contact ``k`` found
    (``place[k] >= 0``), ``out[b * m + k] = values[b * indexed + place[k]]``; other rows
    keep their value.
    """
    count = place.shape[0]
    moved = 0
    for k in range(count):
        if place[k] >= 0:
            for block in range(blocks):
                out[block * count + k] = values[block * indexed + place[k]]
            moved += blocks
    return moved


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
        size = 1 << max(1, int(2 * held.shape[0] - 1).bit_length())  # >= 2 n
        return cls(held, _table(held, size))

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
        return _lookup(self._table, self.ids, wanted)

    def carry(self, values: FloatArray, ids: NDArray[np.integer]) -> FloatArray:
        """``values`` (one per indexed contact) moved to the contacts ``ids``, 0 for a new one."""
        place = self.find(ids)
        carried = np.zeros(place.shape[0])
        carry_rows(place, np.asarray(values, dtype=np.float64), len(self), 1, carried)
        return carried
