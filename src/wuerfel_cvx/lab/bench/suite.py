"""Benchmark suites: TOML files in ``benchmarks/`` that expand into grid points.

A suite file has a name, a description, a ``[defaults]`` table and one or more ``[[grid]]``
tables.  Each grid table is the defaults overlaid with its own keys; its points are the
Cartesian product of its lists::

    name = "smoke"
    description = "seconds-long check that every part of the sweep works"

    [defaults]
    duration = 0.3                      # simulated time per grid point (s)
    formulations = ["velocity"]
    solvers = ["CLARABEL", "OSQP", "PIQP"]
    tols = ["default"]
    dts = [0.01]                        # time steps (s)
    table_masses = ["fixed"]            # "fixed" or a heavy-table corner mass (kg)
    extra_rods = [false]
    sleeps = [false]                    # true: islands at rest sleep
    islands = [false]                   # true: one QP per island instead of one joint QP
    friction_models = ["ccp"]           # "ccp" and/or "coulomb" (scenes with friction)
    solve_paths = ["native"]            # "native", "compiled", "declared" (wuerfel_cvx.solve.paths)
    polishing = [true]                  # false: answers as the solvers gave them (no polish)
    reuse_active_sets = [false]         # true: a resting pile skips the solver (reused)
    peers = []                          # peer engines; names unknown here are left out
    reference = "dt/8"                  # "dt/8", "rest", "settled" or "none"
    settle = 0.0                        # with "settled": time (s) given to settle first
    compare_every = 1                   # steps between re-solves by the reference solver
    time_limit = 600.0                  # wall seconds per grid point before it is stopped
    bare_call_floor = false             # true: default-settings points also replay their
                                        # solver calls bare (wuerfel_cvx.lab.bench.floors)

    [[grid]]
    scenes = ["tilted-drop", "stack-3"]

Peer engines (``PYMUNK``, ``MUJOCO``) may appear among the solvers; a peer point has no
formulation, tolerance or friction model of ours, so it is expanded once per scene and dt.
Peers may also be named in ``peers``: a name that is not a peer engine of this
installation is then left out of the suite, and :attr:`Suite.skipped` says so (among the
solvers it would be taken for a solver and give an error row).  The sweep skips the
points of an engine whose package is not installed, naming them.
"""

from __future__ import annotations

import itertools
import math
import tomllib
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

from ...errors import InputError
from ...formulations import DEFAULT_FORMULATION, FRICTION_MODELS
from ...settings import Settings
from ...solve.paths import NATIVE, SOLVE_PATHS
from ...step.sleep import SleepSettings
from ..peers import PEER_ENGINES

REFERENCE_KINDS = ("dt/8", "rest", "settled", "none")
"""``dt/8``: the same scene and formulation at dt/8 with CLARABEL at ``high`` tolerance;
``rest``: the exact solution is the initial state (a scene that starts at rest: every body
supported, in equilibrium); ``settled``: the state after the grid point's ``settle``
seconds, for a scene that starts apart and falls together (the error is how far it moves
after settling); ``none``: no reference."""

REFERENCE_REFINEMENT = 8
"""The reference runs at ``dt / REFERENCE_REFINEMENT``."""

DEFAULT_FRICTION_MODEL = FRICTION_MODELS[0]
"""The friction model of a grid point that names none; left out of its ``point_id``."""

ReferenceKey = tuple[str, str, float, float, str]
"""What identifies a dt/8 reference run: scene, formulation, dt (s), duration (s) and
friction model."""

REFERENCE_SOLVER = "CLARABEL"
REFERENCE_TOL = "high"
"""The tightest CLARABEL setting (see :data:`wuerfel_cvx.solve.registry.TOLERANCE_PRESETS`)."""

_LIST_KEYS = {"scenes": str, "formulations": str, "solvers": str, "tols": str,
              "dts": float, "table_masses": (str, float), "extra_rods": bool,
              "sleeps": bool, "islands": bool, "friction_models": str, "peers": str,
              "solve_paths": str, "polishing": bool,
              "reuse_active_sets": bool}
_SCALAR_KEYS = {"duration": float, "reference": str, "settle": float, "compare_every": int,
                "time_limit": float, "bare_call_floor": bool}
_DEFAULTS: dict[str, Any] = {
    "formulations": [DEFAULT_FORMULATION], "solvers": ["CLARABEL"], "tols": ["default"],
    "dts": [0.01], "table_masses": ["fixed"], "extra_rods": [False], "sleeps": [False],
    "islands": [False], "friction_models": [DEFAULT_FRICTION_MODEL], "peers": [],
    "solve_paths": [NATIVE], "polishing": [True], "reuse_active_sets": [False],
    "reference": "dt/8", "settle": 0.0,
    "compare_every": 1, "time_limit": 600.0, "bare_call_floor": False,
}


@dataclass(frozen=True)
class GridPoint:
    """One configuration of a sweep: a scene run for ``duration`` seconds."""

    suite: str
    scene: str
    formulation: str
    """``velocity`` or ``seed``; ``peer`` for a peer engine."""
    solver: str
    """Solver registry name (upper case) or peer engine."""
    tol: str
    """Tolerance preset; ``native`` for a peer engine."""
    dt: float
    """Time step (s)."""
    duration: float
    """Simulated time (s)."""
    table_mass: float | None = None
    """Seed heavy-table corner mass (kg), or ``None`` for fixed tables."""
    extra_rod: bool = False
    sleep: bool = False
    """Islands at rest sleep (see :mod:`wuerfel_cvx.step.sleep`)."""
    reference: str = "dt/8"
    compare_every: int = 1
    """Re-solve every ``compare_every``-th step's QP with the reference solver; 0: never."""
    time_limit: float = 600.0
    """Wall time (s) after which a grid point is stopped and reported as failed."""
    islands: bool = False
    """One QP per island instead of one joint QP (``simulate(..., islands=True)``)."""
    friction_model: str | None = DEFAULT_FRICTION_MODEL
    """``simulate(..., friction_model=...)``: ``ccp`` or ``coulomb``; ``None`` for a peer."""
    solve_path: str = NATIVE
    """How the QPs reach the solver (:class:`~wuerfel_cvx.solve.paths.SolvePath`); ``native``
    for a peer."""
    polish: bool = True
    """``simulate(..., polish=...)``: answers polished on their active set; ``True`` for a
    peer."""
    reuse_active_sets: bool = False
    """``simulate(..., reuse_active_sets=...)``: each QP tried first on its structure's last
    active set, the solver skipped where it holds; ``False`` for a peer."""
    scene_file: str | None = None
    """The scene's TOML file, absolute, when ``scene`` names one: found relative to the suite
    file as the suite was read.  ``scene`` stays as the suite wrote it, in the point's id."""
    settle: float = 0.0
    """With reference ``settled``: the time (s) the scene is given to come to rest; the
    trajectory error is measured from the state at that time on.  0 otherwise."""
    bare_call_floor: bool = False
    """Measure the floor under the call / solver ratio when the point runs the default
    settings (:attr:`runs_defaults`): its solver calls replayed bare
    (:mod:`wuerfel_cvx.lab.bench.floors`).  A measurement, not a setting: not in the id."""

    def settings(self) -> Settings:
        """The run's :class:`~wuerfel_cvx.settings.Settings` (not for a peer point)."""
        return Settings(dt=self.dt, solver=self.solver, formulation=self.formulation,
                        tol=self.tol, solve_path=self.solve_path,
                        friction_model=self.friction_model or DEFAULT_FRICTION_MODEL,
                        table_mass=self.table_mass, extra_rod=self.extra_rod,
                        sleep=SleepSettings() if self.sleep else None, islands=self.islands,
                        polish=self.polish, reuse_active_sets=self.reuse_active_sets)

    @property
    def runs_defaults(self) -> bool:
        """Whether the point is ours and runs the default :class:`Settings` at its dt and solver."""
        if self.engine != "wuerfel_cvx":
            return False
        settings = self.settings()
        return settings == Settings(dt=self.dt, solver=self.solver,
                                    friction_model=settings.friction_model)

    @property
    def scene_input(self) -> str:
        """What to load the scene from: its file if it has one, else its library name."""
        return self.scene_file or self.scene

    @property
    def engine(self) -> str:
        """``wuerfel_cvx`` or the peer engine's package name."""
        return self.solver.lower() if self.solver in PEER_ENGINES else "wuerfel_cvx"

    @property
    def steps(self) -> int:
        """Number of steps: ``round(duration / dt)``, at least 1."""
        return max(1, round(self.duration / self.dt))

    @property
    def point_id(self) -> str:
        """A readable key, unique within the suite."""
        parts = [self.scene, self.formulation, self.solver, self.tol, f"dt={self.dt:g}",
                 f"T={self.duration:g}"]
        if self.table_mass is not None:
            parts.append(f"table_mass={self.table_mass:g}")
        if self.extra_rod:
            parts.append("extra_rod")
        if self.sleep:
            parts.append("sleep")
        if self.islands:
            parts.append("islands")
        if self.friction_model not in (None, DEFAULT_FRICTION_MODEL):
            parts.append(f"friction={self.friction_model}")
        if self.solve_path != NATIVE:
            parts.append(f"path={self.solve_path}")
        if not self.polish:
            parts.append("unpolished")
        if self.reuse_active_sets:
            parts.append("reuse")
        return "|".join(parts)

    @property
    def reference_label(self) -> str:
        """The results' ``reference_kind``: the kind, and for ``settled`` its time."""
        if self.reference == "settled":
            return f"settled {self.settle:g} s"
        return self.reference

    @property
    def reference_key(self) -> ReferenceKey | None:
        """What identifies this point's dt/8 reference run, or ``None`` if it needs none.

        Variants (heavy tables, a sixth rod) and peers are compared with the exact model:
        fixed tables, five rods, and for peers the default formulation with the
        default friction model.  A point's reference uses the point's friction model.
        """
        if self.reference != "dt/8":
            return None
        formulation = DEFAULT_FORMULATION if self.formulation == "peer" else self.formulation
        return (self.scene_input, formulation, self.dt, self.duration,
                self.friction_model or DEFAULT_FRICTION_MODEL)


@dataclass(frozen=True)
class Suite:
    """A named list of grid points."""

    name: str
    description: str
    points: tuple[GridPoint, ...]
    skipped: tuple[str, ...] = ()
    """Why peers named in ``peers`` were left out (one message per engine)."""

    @classmethod
    def from_toml(cls, path: str | Path) -> Suite:
        """Read a suite file; raises :class:`InputError` naming the file and key."""
        path = Path(path)
        try:
            with path.open("rb") as handle:
                data = tomllib.load(handle)
        except FileNotFoundError:
            raise InputError("no such suite file", source=str(path)) from None
        except tomllib.TOMLDecodeError as exc:
            raise InputError(f"not valid TOML ({exc})", source=str(path)) from None
        return cls.from_dict(data, source=str(path), folder=path.parent)

    @classmethod
    def named(cls, name: str) -> Suite:
        """A suite by name (``benchmarks/<name>.toml``) or by path to a TOML file."""
        if name.endswith(".toml") or "/" in name:
            return cls.from_toml(name)
        local = Path("benchmarks") / f"{name}.toml"
        if local.is_file():
            return cls.from_toml(local)
        bundled = resources.files("wuerfel_cvx.suites").joinpath(f"{name}.toml")
        if bundled.is_file():
            with resources.as_file(bundled) as bundled_path:
                return cls.from_toml(bundled_path)
        raise InputError(f"unknown suite (known: {', '.join(suite_names())}; "
                         "or give a .toml path)", source=name)

    @classmethod
    def from_dict(cls, data: dict[str, Any], source: str = "suite",
                  folder: Path | None = None) -> Suite:
        """Build from parsed TOML; checks keys and types.

        Scene files are found relative to ``folder`` (the suite file's; default: the
        working directory); one that is not there is an :class:`InputError`.
        """
        unknown = set(data) - {"name", "description", "defaults", "grid"}
        if unknown:
            raise InputError(f"unknown keys {sorted(unknown)}", source=source)
        name = data.get("name")
        if not isinstance(name, str) or not name:
            raise InputError("needs a non-empty string", source=source, field="name")
        defaults = {**_DEFAULTS, **_checked(data.get("defaults", {}), source, "defaults")}
        grids = data.get("grid")
        if not isinstance(grids, list) or not grids:
            raise InputError("needs at least one [[grid]] table", source=source, field="grid")
        points: list[GridPoint] = []
        skipped: dict[str, str] = {}
        for index, grid in enumerate(grids):
            where = f"grid[{index}]"
            settings = {**defaults, **_checked(grid, source, where)}
            runnable, left_out = _runnable_peers(settings["peers"])
            skipped.update(left_out)
            settings["solvers"] = [*settings["solvers"], *runnable]
            points.extend(_expand(name, settings, source, where, folder or Path.cwd()))
        unique = list(dict.fromkeys(points))
        return cls(name, str(data.get("description", "")), tuple(unique),
                   tuple(skipped.values()))


def suite_names() -> list[str]:
    """Names of the bundled suites."""
    names = {entry.name.removesuffix(".toml")
             for entry in resources.files("wuerfel_cvx.suites").iterdir()
             if entry.name.endswith(".toml")}
    return sorted(names)


def _checked(table: Any, source: str, where: str) -> dict[str, Any]:
    if not isinstance(table, dict):
        raise InputError("must be a table", source=source, field=where)
    checked: dict[str, Any] = {}
    for key, value in table.items():
        field = f"{where}.{key}"
        if key in _LIST_KEYS:
            if not isinstance(value, list) or not value:
                raise InputError("must be a non-empty list", source=source, field=field)
            for item in value:
                _check_type(item, _LIST_KEYS[key], source, field)
        elif key in _SCALAR_KEYS:
            _check_type(value, _SCALAR_KEYS[key], source, field)
        else:
            raise InputError(f"unknown key (known: {', '.join([*_LIST_KEYS, *_SCALAR_KEYS])})",
                             source=source, field=field)
        checked[key] = value
    return checked


def _runnable_peers(names: list[str]) -> tuple[list[str], dict[str, str]]:
    """The ``peers`` that are peer engines here, and a message for each one left out.

    An engine whose package is not installed stays: the sweep skips its points and says so.
    """
    runnable, left_out = [], {}
    for name in (str(name).upper() for name in names):
        if name in PEER_ENGINES:
            runnable.append(name)
        else:
            left_out[name] = (f"peer {name} left out: not a peer engine of this installation "
                              f"(known: {', '.join(PEER_ENGINES)})")
    return runnable, left_out


def _check_type(value: Any, expected: Any, source: str, field: str) -> None:
    kinds = expected if isinstance(expected, tuple) else (expected,)
    ok = any(_is(value, kind) for kind in kinds)
    if not ok:
        names = " or ".join(kind.__name__ for kind in kinds)
        raise InputError(f"expected {names}, got {value!r}", source=source, field=field)


def _is(value: Any, kind: type) -> bool:
    if kind is float:
        return isinstance(value, int | float) and not isinstance(value, bool)
    if kind is int:
        return isinstance(value, int) and not isinstance(value, bool)
    return isinstance(value, kind)


def _expand(suite: str, s: dict[str, Any], source: str, where: str,
            folder: Path) -> list[GridPoint]:
    if "scenes" not in s:
        raise InputError("needs 'scenes'", source=source, field=where)
    files = {scene: _scene_file(scene, folder, source, f"{where}.scenes")
             for scene in s["scenes"]}
    duration = s.get("duration")
    if duration is None or not (math.isfinite(duration) and duration > 0):
        raise InputError("needs a positive 'duration' (s)", source=source, field=where)
    if s["reference"] not in REFERENCE_KINDS:
        raise InputError(f"must be one of {', '.join(REFERENCE_KINDS)}", source=source,
                         field=f"{where}.reference")
    _check_settle(s["reference"], float(s["settle"]), float(duration), source, where)
    if not s["time_limit"] > 0:
        raise InputError("must be positive (s)", source=source, field=f"{where}.time_limit")
    if s["compare_every"] < 0:
        raise InputError("must be >= 0", source=source, field=f"{where}.compare_every")
    for dt in s["dts"]:
        if not (math.isfinite(dt) and dt > 0):
            raise InputError(f"time steps must be positive, got {dt}", source=source,
                             field=f"{where}.dts")
    masses = [_table_mass(m, source, f"{where}.table_masses") for m in s["table_masses"]]
    models = [_friction_model(m, source, f"{where}.friction_models")
              for m in s["friction_models"]]
    for path in s["solve_paths"]:
        if path not in SOLVE_PATHS:
            raise InputError(f"unknown solve path {path!r} (known: {', '.join(SOLVE_PATHS)})",
                             source=source, field=f"{where}.solve_paths")
    points: dict[str, GridPoint] = {}  # a peer's point once, whatever our settings
    for (scene, formulation, solver, tol, dt, mass, rod, sleep, islands, model,
         path, polish, reuse) in itertools.product(
             s["scenes"], s["formulations"], s["solvers"], s["tols"], s["dts"], masses,
             s["extra_rods"], s["sleeps"], s["islands"], models, s["solve_paths"],
             s["polishing"], s["reuse_active_sets"]):
        solver = solver.upper()
        friction_model: str | None = model
        if solver in PEER_ENGINES:
            formulation, tol, mass, rod, sleep, islands, friction_model, path, polish, reuse = (
                "peer", "native", None, False, False, False, None, NATIVE, True, False)
        point = GridPoint(suite, scene, formulation, solver, str(tol), float(dt),
                          float(duration), mass, bool(rod), bool(sleep), s["reference"],
                          s["compare_every"], float(s["time_limit"]), islands=bool(islands),
                          friction_model=friction_model, solve_path=path,
                          polish=bool(polish), reuse_active_sets=bool(reuse),
                          scene_file=files[scene],
                          settle=float(s["settle"]),
                          bare_call_floor=bool(s["bare_call_floor"]))
        points.setdefault(point.point_id, point)
    return list(points.values())


def _check_settle(reference: str, settle: float, duration: float, source: str,
                  where: str) -> None:
    """A ``settled`` reference needs a settling time inside the run; no other kind takes one."""
    field = f"{where}.settle"
    if reference == "settled":
        if not (math.isfinite(settle) and 0 < settle < duration):
            raise InputError(f"reference 'settled' needs 0 < settle < duration ({duration:g} s), "
                             f"got {settle:g}", source=source, field=field)
    elif settle != 0:
        raise InputError(f"only with reference 'settled' (this block's is '{reference}')",
                         source=source, field=field)


def _scene_file(scene: str, folder: Path, source: str, field: str) -> str | None:
    """The absolute path of a scene given as a file (relative to ``folder``); else ``None``.

    A file that is not there is an :class:`InputError` now, before any point runs.
    """
    if not (scene.endswith(".toml") or "/" in scene or "\\" in scene):
        return None  # a library name (an unknown one becomes its points' error rows)
    path = (folder / Path(scene).expanduser()).resolve()
    if not path.is_file():
        raise InputError(f"scene file {scene!r} not found (looked for {path})",
                         source=source, field=field)
    return str(path)


def _friction_model(value: str, source: str, field: str) -> str:
    key = value.strip().lower()
    if key not in FRICTION_MODELS:
        raise InputError(f"unknown friction model {value!r} (known: {', '.join(FRICTION_MODELS)})",
                         source=source, field=field)
    return key


def _table_mass(value: str | float, source: str, field: str) -> float | None:
    if isinstance(value, str):
        if value != "fixed":
            raise InputError(f"'fixed' or a mass in kg, got {value!r}", source=source,
                             field=field)
        return None
    if not (math.isfinite(value) and value > 0):
        raise InputError(f"table mass must be positive, got {value}", source=source,
                         field=field)
    return float(value)
