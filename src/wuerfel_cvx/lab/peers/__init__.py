"""Peer engines: the same named scenes in pymunk (Chipmunk2D), MuJoCo, Box2D v3 and 2.3.

    >>> from wuerfel_cvx.lab.peers import simulate_peer
    >>> traj = simulate_peer("pymunk", "tilted-drop", dt=0.01, steps=200)

Each square is one rigid body (3 degrees of freedom) with the package's mass and the
4-corner-mass moment of inertia ``m s^2 / 2`` (kg m^2); contacts are inelastic, with each
contact's friction coefficient ``sqrt(mu_a mu_b)`` from the scene's ``friction`` keys
(frictionless without them), tables static, ``dt`` and gravity the same as for
:func:`wuerfel_cvx.simulate`.  How each engine is made to mix friction that way, and the
engine-specific choices (pymunk's collision slop and iterations, MuJoCo's soft contact
defaults, Box2D's sub-steps, iterations and sleep) are documented in
:mod:`.pymunk_peer`, :mod:`.mujoco_peer`, :mod:`.box2d_peer` (Box2D v3.1 through
``box2d-python``, Python >= 3.12) and :mod:`.pybox2d_peer` (Box2D 2.3 through ``box2d``).

The result is a :class:`~wuerfel_cvx.trajectory.Trajectory` in the package's layout
(corner points and velocities, the same ``info`` keys and metric columns), so peers and
the QP simulator can be compared with the same code.  The engines are optional:
``pip install "wuerfel-cvx[peers]"``; they are imported only when used.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from pathlib import Path

from ...errors import InputError
from ...scenes.scene import Scene
from ...simulate import resolve_scene
from ...trajectory import Trajectory
from . import box2d_peer, mujoco_peer, pybox2d_peer, pymunk_peer
from ._common import PeerWorld, check_run_arguments, package_version, run_peer

PEER_ENGINES: tuple[str, ...] = ("PYMUNK", "MUJOCO", "BOX2D", "PYBOX2D")
"""Names of the peer engines (upper case; arguments are case-insensitive)."""

_PACKAGES = {"PYMUNK": pymunk_peer.PACKAGE, "MUJOCO": mujoco_peer.PACKAGE,
             "BOX2D": box2d_peer.PACKAGE, "PYBOX2D": pybox2d_peer.PACKAGE}
"""The distribution of each engine (its version goes to ``info["versions"]``)."""
PEER_MODULES = {"PYMUNK": "pymunk", "MUJOCO": "mujoco", "BOX2D": box2d_peer.MODULE,
                "PYBOX2D": pybox2d_peer.MODULE}
"""The module each engine's distribution installs (imported to tell it is available)."""
_BUILDERS: dict[str, Callable[[Scene, float], PeerWorld]] = {
    "PYMUNK": pymunk_peer.build_world, "MUJOCO": mujoco_peer.build_world,
    "BOX2D": box2d_peer.build_world, "PYBOX2D": pybox2d_peer.build_world,
}
"""How each engine builds its world of a scene at a time step (s)."""
INSTALL_HINT = 'pip install "wuerfel-cvx[peers]"'
"""How to install the optional peer engines."""

__all__ = ["INSTALL_HINT", "PEER_ENGINES", "PEER_MODULES", "available_peers", "peer_version",
           "simulate_peer"]


def _engine_name(engine: str) -> str:
    name = str(engine).upper()
    if name not in PEER_ENGINES:
        raise InputError(f"unknown peer engine '{engine}' (known: {', '.join(PEER_ENGINES)})",
                         field="engine")
    return name


def _importable(module: str) -> bool:
    try:
        importlib.import_module(module)
    except (ImportError, OSError):  # OSError: a shared library of the engine is missing
        return False
    return True


def available_peers() -> list[str]:
    """The peer engines whose package can be imported, in :data:`PEER_ENGINES` order."""
    return [name for name in PEER_ENGINES if _importable(PEER_MODULES[name])]


def peer_version(engine: str) -> str:
    """Installed version of an engine's package, or ``"not installed"``.

    Raises :class:`InputError` for an unknown engine name.
    """
    return package_version(_PACKAGES[_engine_name(engine)])


def simulate_peer(engine: str, scene: Scene | str | Path, dt: float, steps: int, *,
                  progress: bool = False) -> Trajectory:
    """Simulate a scene in a peer engine for ``steps`` steps of ``dt`` seconds.

    Parameters
    ----------
    engine:
        One of :data:`PEER_ENGINES`, case-insensitive.
    scene:
        A :class:`Scene`, a library name such as ``"stack-10"``, or a TOML path.
    dt:
        Time step (s), positive.
    steps:
        Number of steps, non-negative.
    progress:
        Show a progress bar.

    Returns
    -------
    Trajectory
        Corners ``(steps + 1, 4 n, 2)`` (m) and their velocities (m/s) in the layout of
        :func:`wuerfel_cvx.simulate`, with ``info["formulation"] == "peer"`` and one
        metrics row per step (timings of the engine's step call; no residuals).

    Raises
    ------
    InputError
        For an unknown engine, a missing engine package, or a bad argument.
    StepFailure
        When the engine returns a non-finite state; its ``trajectory`` holds the steps
        before it.

    """
    name = _engine_name(engine)
    package = _PACKAGES[name]
    if not _importable(PEER_MODULES[name]):
        hint = INSTALL_HINT + (" (Python >= 3.12)" if name == "BOX2D" else "")
        raise InputError(f"peer engine {name} needs the package '{package}': {hint}",
                         field="engine")
    resolved = resolve_scene(scene)
    check_run_arguments(dt, steps)
    world: PeerWorld = _BUILDERS[name](resolved, float(dt))
    return run_peer(name, package, resolved, world, float(dt), int(steps), progress=progress)
