"""Peer engines: the same named scenes in pymunk (Chipmunk2D) and MuJoCo.

    >>> from wuerfel_cvx.peers import simulate_peer
    >>> traj = simulate_peer("pymunk", "tilted-drop", dt=0.01, steps=200)

Each square is one rigid body (3 degrees of freedom) with the package's mass and the
4-corner-mass moment of inertia ``m s^2 / 2`` (kg m^2); contacts are frictionless and
inelastic, tables static, ``dt`` and gravity the same as for :func:`wuerfel_cvx.simulate`.
The engine-specific choices (pymunk's collision slop and iterations, MuJoCo's soft
contact defaults) are documented in :mod:`.pymunk_peer` and :mod:`.mujoco_peer`.

The result is a :class:`~wuerfel_cvx.trajectory.Trajectory` in the package's layout
(corner points and velocities, the same ``info`` keys and metric columns), so peers and
the QP simulator can be compared with the same code.  The engines are optional:
``pip install "wuerfel-cvx[peers]"``; they are imported only when used.
"""

from __future__ import annotations

import importlib
from pathlib import Path

from ..errors import InputError
from ..scene import Scene
from ..simulate import resolve_scene
from ..trajectory import Trajectory
from . import mujoco_peer, pymunk_peer
from ._common import PeerWorld, check_run_arguments, package_version, run_peer

PEER_ENGINES: tuple[str, ...] = ("PYMUNK", "MUJOCO")
"""Names of the peer engines (upper case; arguments are case-insensitive)."""

_PACKAGES = {"PYMUNK": pymunk_peer.PACKAGE, "MUJOCO": mujoco_peer.PACKAGE}
INSTALL_HINT = 'pip install "wuerfel-cvx[peers]"'
"""How to install the optional peer engines."""

__all__ = ["INSTALL_HINT", "PEER_ENGINES", "available_peers", "peer_version", "simulate_peer"]


def _engine_name(engine: str) -> str:
    name = str(engine).upper()
    if name not in PEER_ENGINES:
        raise InputError(f"unknown peer engine '{engine}' (known: {', '.join(PEER_ENGINES)})",
                         field="engine")
    return name


def _importable(package: str) -> bool:
    try:
        importlib.import_module(package)
    except (ImportError, OSError):  # OSError: a shared library of the engine is missing
        return False
    return True


def available_peers() -> list[str]:
    """The peer engines whose package can be imported, in :data:`PEER_ENGINES` order."""
    return [name for name in PEER_ENGINES if _importable(_PACKAGES[name])]


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
        ``"PYMUNK"`` or ``"MUJOCO"``, case-insensitive.
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
    if not _importable(package):
        raise InputError(f"peer engine {name} needs the package '{package}': {INSTALL_HINT}",
                         field="engine")
    resolved = resolve_scene(scene)
    check_run_arguments(dt, steps)
    world: PeerWorld
    if name == "PYMUNK":
        world = pymunk_peer.build_world(resolved, float(dt))
    else:
        world = mujoco_peer.build_world(resolved, float(dt))
    return run_peer(name, package, resolved, world, float(dt), int(steps), progress=progress)
