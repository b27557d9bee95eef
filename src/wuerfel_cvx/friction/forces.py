"""Friction coefficients of bodies and of their contacts.

Each square, box and table carries a Coulomb coefficient ``friction`` (1, >= 0, default 0;
the TOML key of the same name).  A contact between bodies ``a`` and ``b`` takes Box2D's
mixing rule ``sqrt(mu_a mu_b)``: a frictionless body makes every contact it has
frictionless, and two equal coefficients mix to themselves.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..scenes.geometry import FloatArray
from ..scenes.scene import Scene

if TYPE_CHECKING:
    from ..step.contacts import Contacts


def body_friction(scene: Scene) -> FloatArray:
    """Coefficient of every body ``(n_bodies,)``: the moving bodies, then the tables."""
    bodies = [*scene.bodies, *scene.tables]
    return np.array([body.friction for body in bodies], dtype=np.float64)


def contact_friction(friction: FloatArray, contacts: Contacts) -> FloatArray:
    """Coefficient of each contact ``(len(contacts),)``: ``sqrt(mu_point mu_edge)``.

    ``friction`` is :func:`body_friction`'s array (:attr:`Model.friction
    <wuerfel_cvx.step.model.Model.friction>`) for the model the contacts index.
    """
    return np.asarray(np.sqrt(friction[contacts.point_body] * friction[contacts.edge_body]),
                      dtype=np.float64)


def is_frictionless(scene: Scene) -> bool:
    """Whether no body of ``scene`` has friction (the seed's model)."""
    return not np.any(body_friction(scene))


@dataclass(frozen=True)
class ContactForces:
    """A step's contact impulses and slips, one entry per contact, whatever the model.

    The friction models' common answer, from which the physical criteria are measured
    (:mod:`wuerfel_cvx.step.criteria`).
    """

    coefficient: FloatArray
    """Friction coefficient ``mu`` (1)."""
    normal: FloatArray
    """Normal impulse ``lambda_n`` (N s), >= 0 up to the solver's tolerance."""
    friction: FloatArray
    """Friction impulse ``lambda_t`` (N s) along the contact's tangent (the edge's
    direction, :func:`~wuerfel_cvx.formulations.cone.slip_rows`)."""
    slip: FloatArray
    """Slip ``s`` (m/s) after the step: the contact point's velocity along the tangent
    relative to the edge."""
