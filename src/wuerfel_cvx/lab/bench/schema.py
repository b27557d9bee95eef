"""The benchmark results table: one typed row per grid point, with a schema version.

The table is long-format CSV (one row per scene x formulation x solver x tolerance x dt x
variant).  Every column is declared once here with its type, unit and meaning; writing,
reading, validating and the report all go through :data:`COLUMNS`.  Change the columns and
you must bump :data:`SCHEMA_VERSION`: a sweep refuses to append to a file of another version.
A file of an older version is still read (for the report) when the columns added since then
have a value that says what the older rows meant (:data:`ADDED_COLUMNS`).
"""

from __future__ import annotations

import csv
import hashlib
import io
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import pandas as pd

from ...errors import InputError
from ...formulations import FORMULATIONS

SCHEMA_VERSION = 12

PROVENANCE_FILE = "provenance.json"
"""Beside a results CSV: the physics fingerprint its rows were measured on and the code
versions that wrote them (:func:`wuerfel_cvx.lab.bench.sweep.record_provenance`)."""
"""Version of :data:`COLUMNS`; stored in every row's ``schema_version``."""

FRICTION_FORMULATIONS: frozenset[str] = frozenset(
    name for name, make in FORMULATIONS.items() if make().friction is not None)
"""Formulations that take a friction model (the others, ``seed``, have no friction)."""


def _old_friction_model(frame: pd.DataFrame) -> pd.Series:
    """``friction_model`` of the rows of a file older than version 6.

    Those runs had no friction in any scene, which every friction model treats alike, so
    the value is what a run of the same configuration writes now: ``ccp`` (the default)
    for a formulation that takes friction, empty for ``seed`` and the peers.
    """
    takes_friction = frame["formulation"].isin(sorted(FRICTION_FORMULATIONS))
    return pd.Series(["ccp" if flag else None for flag in takes_friction.fillna(False)],
                     index=frame.index, dtype="string")


STAGE_TIME_COLUMNS = (
    "search_time_per_step", "build_time_per_step", "solve_time_per_step",
    "solver_time_per_step_mean", "polish_time_per_step", "update_time_per_step",
    "record_time_per_step", "outside_steps_time_per_step")
"""The mean time per step (s) of each stage of a run's steps (the metrics' ``<stage>_time_s``,
:data:`wuerfel_cvx.step.simulation.STAGES`), the solver's own and the polish's within the
solve stage, and the rest of the ``simulate()`` call (set-up, the loop): they add up to
``call_wall_time_per_step``."""

ADDED_COLUMNS: dict[int, dict[str, Any]] = {
    4: {"islands": False},
    5: {"max_overlap_depth": None},
    6: {"friction_model": _old_friction_model, "friction_steps": None,
        "max_signorini_violation": None, "max_coulomb_violation": None,
        "max_dissipation_violation": None, "friction_work": None,
        "coulomb_iterations_mean": None, "coulomb_iterations_max": None,
        "coulomb_converged_fraction": None, "coulomb_unconverged_steps": None},
    7: {"solve_path": None, "call_wall_time_per_step": None, "call_over_solver_mean": None},
    8: {"polish": None, "polished_fraction": None, "polish_rejected_steps": None,
        "polish_rejections": None, "max_push_at_distance": None, "max_push_gap_product": None},
    9: dict.fromkeys(STAGE_TIME_COLUMNS),
    10: {"reuse_active_sets": False, "reused_fraction": None},
    11: {"kkt_factor_time": None},
    12: {"bare_call_time_per_step": None, "bare_call_over_solver": None},
}
"""Per schema version, the columns it added and their value in the rows of older files:
a constant, ``None`` (not measured then: missing), or a function of the older frame giving
one value per row.  Version 3 had no ``islands`` column: its runs solved one joint QP;
version 4 did not measure ``max_overlap_depth``; version 5 had no friction, so its
criteria and fixed-point columns are missing and its ``friction_model`` is that of
:func:`_old_friction_model`; version 6 had no ``solve_path`` (its runs solved repeated
structures on a direct path that no longer exists: left empty) and did not time the whole
``simulate`` call; version 7 did not polish (``polish`` false) nor measure pushes at a
distance row by row (``polish`` left empty: the plots take such rows as plain, not as the
unpolished variant of a newer run); version 8 did not split a step's time into stages;
version 9 did not reuse active sets (its runs solved every QP); version 10 did not factor
the last QP's KKT matrix; version 11 did not replay a run's solver calls bare."""

ColumnType = Literal["str", "int", "float", "bool"]


@dataclass(frozen=True)
class Column:
    """One column of the results table."""

    name: str
    type: ColumnType
    """``str``, ``int``, ``float`` or ``bool``; empty cells are missing values."""
    unit: str
    """SI unit, ``1`` for dimensionless, ``""`` for text and flags."""
    description: str


def _c(name: str, type_: ColumnType, unit: str, description: str) -> Column:
    return Column(name, type_, unit, description)


COLUMNS: tuple[Column, ...] = (
    _c("schema_version", "int", "", "version of this schema"),
    _c("suite", "str", "", "suite name"),
    _c("point_id", "str", "", "unique key of the grid point within the suite"),
    # configuration
    _c("scene", "str", "", "named scene"),
    _c("engine", "str", "", "'wuerfel_cvx', or a peer engine ('pymunk', 'mujoco')"),
    _c("formulation", "str", "", "'velocity', 'seed', or 'peer' for peer engines"),
    _c("solver", "str", "", "solver registry name, or the peer engine in capitals"),
    _c("tol", "str", "", "tolerance preset (low/default/high); 'native' for peers"),
    _c("dt", "float", "s", "time step"),
    _c("duration", "float", "s", "simulated time asked for"),
    _c("steps", "int", "1", "steps asked for: round(duration / dt)"),
    _c("table_mass", "float", "kg", "seed heavy-table corner mass; empty for fixed tables"),
    _c("extra_rod", "bool", "", "redundant sixth rod on every square"),
    _c("sleep", "bool", "", "islands at rest sleep (left out of the QP until touched)"),
    _c("islands", "bool", "", "one QP per island instead of one joint QP per step"),
    _c("solve_path", "str", "", "how the QPs reached the solver: native, compiled or declared"),
    _c("polish", "bool", "", "answers polished on their active set (wuerfel_cvx.solve.kkt)"),
    _c("reuse_active_sets", "bool", "",
       "a QP is first tried on its structure's last active set (the solver skipped if it holds)"),
    _c("n_squares", "int", "1", "number of squares"),
    # environment
    _c("package_version", "str", "", "wuerfel_cvx version"),
    _c("solver_version", "str", "", "version of the solver's (or peer's) Python package"),
    _c("cvxpy_version", "str", "", "cvxpy version"),
    _c("python_version", "str", "", "Python version"),
    _c("cpu", "str", "", "processor model"),
    _c("finished_at", "str", "", "UTC time the row was written (ISO 8601)"),
    # outcome
    _c("status", "str", "", "'ok', 'failed' (a step failed) or 'error' (could not run)"),
    _c("error", "str", "", "the failure or error message; empty when ok"),
    _c("failed_step", "int", "1", "step that failed; empty when none did"),
    _c("steps_completed", "int", "1", "steps completed"),
    _c("success", "bool", "", "the solver claimed success on every step"),
    _c("verified", "bool", "", "the independent KKT residual check held on every step"),
    _c("verified_fraction", "float", "1", "fraction of completed steps that were verified"),
    _c("polished_fraction", "float", "1",
       "fraction of the steps that solved a QP whose answers were all exact: polished, exact "
       "as the solver gave them, or found on the last answer's active set; empty without "
       "polishing"),
    _c("reused_fraction", "float", "1",
       "fraction of the steps that solved a QP whose answers were all found on the last "
       "answer's active set, without the solver; empty without polishing"),
    _c("polish_rejected_steps", "int", "1", "steps with a polish rejected"),
    _c("polish_rejections", "str", "",
       "why polishes were rejected: 'reason: steps', ...; empty when none was"),
    _c("max_push_at_distance", "float", "N s",
       "largest impulse on a QP row whose gap opened over its step (metrics' "
       "push_at_distance_Ns)"),
    _c("max_push_gap_product", "float", "N s m",
       "largest gap times impulse on a QP row (metrics' push_gap_product_Nsm)"),
    # timing
    _c("wall_time_per_step_median", "float", "s", "median wall time of a whole step"),
    _c("call_wall_time_per_step", "float", "s",
       "wall time of the whole simulate() call (set-up, search, solve, metrics, recording) "
       "over the steps completed: what a user waits for"),
    _c("call_over_solver_mean", "float", "1",
       "call_wall_time_per_step over the solver's own mean time per step"),
    _c("search_time_per_step", "float", "s", "mean time per step of the contact search"),
    _c("build_time_per_step", "float", "s",
       "mean time per step building the QPs (islands, rows, further passes' QPs)"),
    _c("solve_time_per_step", "float", "s",
       "mean time per step of the solve calls (solver, adapter, polish, KKT check)"),
    _c("solver_time_per_step_mean", "float", "s",
       "mean of the solver's own time per step (within the solve calls)"),
    _c("polish_time_per_step", "float", "s",
       "mean time per step after the solver returned: polish and KKT check (within the "
       "solve calls)"),
    _c("update_time_per_step", "float", "s",
       "mean time per step advancing the bodies, the physical check, merging islands"),
    _c("record_time_per_step", "float", "s", "mean time per step of the metrics and recording"),
    _c("outside_steps_time_per_step", "float", "s",
       "call_wall_time_per_step minus the mean step: set-up and the loop around the steps"),
    _c("bare_call_time_per_step", "float", "s",
       "the run's solver calls replayed bare (the adapters' update and solve calls alone, "
       "wuerfel_cvx.lab.bench.floors), per step; empty unless the suite asked for it"),
    _c("bare_call_over_solver", "float", "1",
       "bare_call_time_per_step over the solver's own time in the same calls: the floor "
       "under call_over_solver_mean of any Python loop calling this solver"),
    _c("wall_time_per_step_p90", "float", "s", "90th percentile wall time of a step"),
    _c("solver_time_per_step_median", "float", "s", "median of the solver's own time"),
    _c("modelling_time_per_step_median", "float", "s",
       "median of step wall time minus solver time (building, cvxpy, checks, update)"),
    _c("step_over_solver_median", "float", "1",
       "median over steps of (whole step time / solver's own time): the modelling layer's "
       "cost as a multiple of the solver; 1 would be free modelling (over the steps whose "
       "solver ran: not a reused one)"),
    _c("kkt_factor_time", "float", "s",
       "one numeric factorization of the last QP's KKT matrix with every row, OSQP's form, "
       "by QDLDL (median of 3; the floor of an exact second-order step, lab/bench/floors.py); "
       "empty for a peer"),
    _c("wall_time_per_simulated_second", "float", "1",
       "total step wall time divided by the simulated time (s per s)"),
    _c("total_wall_time", "float", "s", "sum of step wall times"),
    # size
    _c("n_variables", "int", "1", "largest QP: variables"),
    _c("n_equalities", "int", "1", "largest QP: equality rows"),
    _c("n_inequalities", "int", "1", "largest QP: inequality rows"),
    _c("n_contacts_max", "int", "1", "most contacts in one step"),
    # accuracy
    _c("max_rod_drift", "float", "1", "largest relative rod-length error"),
    _c("max_penetration", "float", "m", "deepest penetration of a corner into a body"),
    _c("max_overlap_depth", "float", "m",
       "largest separating-axis overlap of two bodies (or a body and a table) after a step: "
       "independent of the edge each corner is matched to"),
    _c("energy_gain", "float", "J", "max over the run of E(t) - E(0); > 0 means energy made"),
    _c("max_step_energy_rise", "float", "J", "largest rise of total energy in one step"),
    _c("reference_kind", "str", "",
       "'dt/8' (same scene and formulation at dt/8, tightest CLARABEL), 'rest' (the exact "
       "solution is the initial state: a scene that starts at rest), 'settled S s' (the state "
       "after S s of settling: a scene that starts apart), or 'none'"),
    _c("trajectory_error", "float", "m",
       "largest corner distance to the reference over the common instants (for 'settled': "
       "from the settling time on)"),
    _c("reference_disagreement", "float", "m/s",
       "largest |x - x_ref| (inf-norm) between this solver's step solution and the "
       "tightest CLARABEL's on the same step QP (m/s for velocity, m/s^2 for seed)"),
    # friction (wuerfel_cvx.step.criteria, after Le Lidec et al. 2023; empty for peers)
    _c("friction_model", "str", "",
       "'ccp' or 'coulomb' for a formulation that takes friction (on a scene without "
       "friction both are the frictionless model); empty for 'seed' and peers"),
    _c("friction_steps", "int", "1",
       "completed steps with a contact with friction, whose criteria were measured; "
       "empty for peers"),
    _c("max_signorini_violation", "float", "N s m",
       "largest |gap| x normal impulse of a contact over the run (an impulse pushing at a "
       "distance); empty without friction steps"),
    _c("max_coulomb_violation", "float", "N s",
       "largest friction impulse beyond mu x normal impulse over the run"),
    _c("max_dissipation_violation", "float", "J",
       "largest lambda_t s + mu lambda_n |s| of a contact over the run: friction not "
       "opposing the slip, or slip inside the cone (0 under maximum dissipation)"),
    _c("friction_work", "float", "J",
       "friction impulses' work summed over the run's steps (<= 0 when friction dissipates)"),
    _c("coulomb_iterations_mean", "float", "1",
       "mean friction problems per step of the Coulomb fixed point; empty without it"),
    _c("coulomb_iterations_max", "int", "1",
       "most friction problems in one step of the Coulomb fixed point; empty without it"),
    _c("coulomb_converged_fraction", "float", "1",
       "fraction of the fixed point's steps that converged within its iteration limit"),
    _c("coulomb_unconverged_steps", "int", "1",
       "steps whose Coulomb fixed point stopped at its iteration limit unconverged"),
)
"""Every column, in file order."""

COLUMN_NAMES: tuple[str, ...] = tuple(column.name for column in COLUMNS)
_BY_NAME = {column.name: column for column in COLUMNS}
_PANDAS_DTYPES = {"str": "string", "int": "Int64", "float": "float64", "bool": "boolean"}


def new_row(**values: Any) -> dict[str, Any]:
    """A complete row: every column present, missing ones ``None``; unknown names raise."""
    unknown = set(values) - set(COLUMN_NAMES)
    if unknown:
        raise KeyError(f"not in the results schema: {sorted(unknown)}")
    row: dict[str, Any] = dict.fromkeys(COLUMN_NAMES)
    row["schema_version"] = SCHEMA_VERSION
    row.update(values)
    return row


def _cell(value: Any, column: Column) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    if column.type == "bool":
        return "true" if bool(value) else "false"
    if column.type == "int":
        return str(int(value))
    if column.type == "float":
        return repr(float(value))
    return str(value)


def format_row(row: dict[str, Any]) -> str:
    """One CSV line (with its newline) in :data:`COLUMNS` order."""
    buffer = io.StringIO()
    csv.writer(buffer, lineterminator="\n").writerow(
        _cell(row.get(column.name), column) for column in COLUMNS)
    return buffer.getvalue()


def header_line() -> str:
    """The CSV header line."""
    return ",".join(COLUMN_NAMES) + "\n"


def append_row(path: Path, row: dict[str, Any]) -> None:
    """Append one row to ``path`` (writing the header first for a new file), durably.

    The line is written with a single ``write`` and flushed to disk, so a killed sweep
    leaves at most one partial last line, which :func:`complete_lines` drops.
    """
    new_file = not path.exists() or path.stat().st_size == 0
    with path.open("a", encoding="utf-8", newline="") as handle:
        handle.write((header_line() if new_file else "") + format_row(row))
        handle.flush()
        os.fsync(handle.fileno())


def complete_lines(path: Path) -> str:
    """The file's text without a trailing partial line (from a sweep killed mid-write)."""
    text = path.read_text(encoding="utf-8")
    if text and not text.endswith("\n"):
        text = text[: text.rfind("\n") + 1]
    return text


def repair(path: Path) -> None:
    """Cut a trailing partial line off ``path`` so that appending starts on a fresh line."""
    if path.exists():
        text = complete_lines(path)
        if len(text.encode("utf-8")) != path.stat().st_size:
            path.write_text(text, encoding="utf-8")


def read_results(path: str | Path, upgrade: bool = True) -> pd.DataFrame:
    """Read a results CSV with the schema's types; raises :class:`InputError` if it differs.

    A trailing partial line (a sweep killed mid-write) is ignored.  With ``upgrade``, a file
    of an older schema version is read as the current one (see :data:`ADDED_COLUMNS`);
    without, only the current version is accepted (a sweep appending to the file).
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("no such results file", source=str(path))
    text = complete_lines(path)
    if not text.strip():
        return pd.DataFrame({c.name: pd.Series(dtype=_PANDAS_DTYPES[c.type]) for c in COLUMNS})
    header = text.split("\n", 1)[0].split(",")
    older = _older_version(tuple(header)) if upgrade else None
    if older is not None:
        version, added = older
        frame = pd.read_csv(io.StringIO(text), dtype="string", keep_default_na=False,
                            na_values=[""])
        claimed = set(frame["schema_version"].dropna())
        if claimed - {str(version)}:
            raise InputError(f"has the columns of schema version {version} but rows of "
                             f"version {sorted(claimed)}", source=str(path),
                             field="schema_version")
        frame = frame.assign(schema_version=str(SCHEMA_VERSION),
                             **{name: _old_value(value, name) for name, value in added.items()})
        return validate(frame[list(COLUMN_NAMES)], source=str(path))
    if tuple(header) != COLUMN_NAMES:
        missing = [name for name in COLUMN_NAMES if name not in header]
        extra = [name for name in header if name not in COLUMN_NAMES]
        raise InputError(f"columns differ from schema version {SCHEMA_VERSION} "
                         f"(missing {missing}, unexpected {extra})", source=str(path))
    frame = pd.read_csv(io.StringIO(text), dtype="string", keep_default_na=False,
                        na_values=[""])
    return validate(frame, source=str(path))


def _old_value(value: Any, name: str) -> Any:
    """An added column's value for ``DataFrame.assign``: a cell, ``None`` or a function."""
    if value is None or callable(value):
        return value
    return _cell(value, _BY_NAME[name])


def _older_version(header: tuple[str, ...]) -> tuple[int, dict[str, Any]] | None:
    """The older schema version with the columns ``header``, and what was added since.

    The columns added since, with their value in the older rows; ``None`` if ``header`` is
    not the columns of an older version.
    """
    added: dict[str, Any] = {}
    for version in sorted(ADDED_COLUMNS, reverse=True):
        added.update(ADDED_COLUMNS[version])
        if header == tuple(name for name in COLUMN_NAMES if name not in added):
            return version - 1, added
    return None


def validate(frame: pd.DataFrame, source: str = "results") -> pd.DataFrame:
    """Convert every column to its schema type; raises :class:`InputError` naming the cell."""
    typed: dict[str, pd.Series] = {}
    for column in COLUMNS:
        if column.name not in frame.columns:
            raise InputError("missing column", source=source, field=column.name)
        raw = frame[column.name]
        typed[column.name] = _convert(raw, column, source)
    result = pd.DataFrame(typed)
    versions = result["schema_version"].dropna().unique()
    if len(versions) and (len(versions) > 1 or int(versions[0]) != SCHEMA_VERSION):
        raise InputError(f"schema version {list(versions)} is not {SCHEMA_VERSION}",
                         source=source, field="schema_version")
    return result


def _convert(raw: pd.Series, column: Column, source: str) -> pd.Series:
    text = raw.astype("string")
    if column.type == "str":
        return text
    if column.type == "bool":
        lowered = text.str.lower()
        bad = lowered.notna() & ~lowered.isin(["true", "false"])
        _raise_bad(bad, text, column, source)
        return lowered.map({"true": True, "false": False}, na_action="ignore").astype("boolean")
    numbers = pd.to_numeric(text, errors="coerce")
    bad = text.notna() & numbers.isna() & ~text.str.lower().isin(["nan", "inf", "-inf"])
    _raise_bad(bad, text, column, source)
    if column.type == "int":
        fractional = numbers.notna() & (numbers != numbers.round())
        _raise_bad(fractional, text, column, source)
        return numbers.astype("Int64")
    return numbers.astype("float64")


def _raise_bad(bad: pd.Series, text: pd.Series, column: Column, source: str) -> None:
    if bool(bad.any()):
        index = int(bad.to_numpy().nonzero()[0][0])
        raise InputError(f"row {index + 1}: '{text.iloc[index]}' is not {column.type}",
                         source=source, field=column.name)


def describe() -> str:
    """The schema as a Markdown table (for the report and the docs)."""
    lines = [f"Schema version {SCHEMA_VERSION}.", "", "| column | type | unit | meaning |",
             "|---|---|---|---|"]
    lines += [f"| `{c.name}` | {c.type} | {c.unit} | {c.description} |" for c in COLUMNS]
    return "\n".join(lines)


SERIES_COLUMNS: tuple[str, ...] = (
    "step", "time_s", "rod_drift", "penetration_m", "total_energy_J", "step_time_s",
    "solver_time_s", "verified",
)
"""Columns of a grid point's per-step series file (units as in the simulation metrics)."""

CLOCK_COLUMNS: frozenset[str] = frozenset({
    "finished_at", "wall_time_per_step_median", "wall_time_per_step_p90",
    "solver_time_per_step_median", "modelling_time_per_step_median",
    "step_over_solver_median", "wall_time_per_simulated_second", "total_wall_time",
    "call_wall_time_per_step", "call_over_solver_mean", "step_time_s", "solver_time_s",
    "bare_call_time_per_step", "bare_call_over_solver", "kkt_factor_time",
    *STAGE_TIME_COLUMNS})
"""The results and series columns read off a clock.  They differ from run to run; the
others are physics, the same bits on every run of a deterministic solver."""


def series_file_name(point_id: str) -> str:
    """File name of a grid point's per-step series, in ``<results dir>/series/``."""
    readable = "".join(ch if ch.isalnum() or ch in "-._" else "_" for ch in point_id)[:80]
    digest = hashlib.sha1(point_id.encode("utf-8")).hexdigest()[:10]
    return f"{readable}-{digest}.csv"
