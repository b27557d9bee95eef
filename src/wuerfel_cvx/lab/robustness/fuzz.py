"""Fuzzing the scene loader: mutated scene files must load or fail with one clear error.

:func:`generate_inputs` draws mutations of valid scene files, reproducibly from a seed:

- *structured* ones edit the parsed scene (wrong types, missing and unknown keys, huge,
  tiny, infinite and NaN numbers, negative sizes and masses, big integers, dates,
  unicode, nested lists, many squares or boxes, a square's ``size`` on a box and back,
  negative, NaN, huge and non-numeric ``friction``) and write it back with :mod:`tomli_w`;
- *textual* ones edit the file's bytes (number tokens TOML allows such as ``inf``,
  ``nan``, ``1e309`` and 30-digit integers, deep nesting, flipped and inserted bytes,
  invalid UTF-8, truncation, duplicated lines, megabytes of comments).

:func:`check_input` puts one file through :meth:`Scene.from_toml` and, when it loads,
one step of :func:`~wuerfel_cvx.simulate`.  The outcomes that keep the package's
promise are: the scene loads and steps to a finite state (*accepted*), the loader
raises :class:`InputError` whose one-line message starts with the file's path
(*rejected*), or the step raises :class:`StepFailure` naming step, solver and status
(*step failure*).  Anything else is a *crash*: another exception, an error message
that does not name the file or spans lines, or a non-finite state.  Files are only
ever parsed by :mod:`tomllib`; nothing is executed or unpickled.
"""

from __future__ import annotations

import copy
import datetime
import math
import random
import re
import tempfile
import time
import warnings
from collections import Counter
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
import tomli_w

from ...errors import InputError, StepFailure
from ...scenes.scene import Scene

Outcome = Literal["accepted", "rejected", "step_failure", "crash"]

#: How many step failures a :class:`FuzzResult` keeps as examples.
MAX_EXAMPLES = 10

#: Solvers that re-run a file whose first step failed (with CLARABEL), as a cross-check.
CROSS_CHECK = ("OSQP", "PIQP")

#: Library scenes whose files seed the structured mutations (small: one step is cheap).
SEED_SCENES = ("tilted-drop", "stack-3", "overlap-recovery", "wall-contact", "rain-4",
               "plank-drop", "domino-row", "friction-ramps")

#: Numbers a field may be replaced by: boundaries of :data:`wuerfel_cvx.scenes.scene.LIMITS`,
#: the extremes of doubles, signs, and TOML integers beyond 64 bits.
EXTREME_NUMBERS: tuple[float | int, ...] = (
    0, 0.0, -0.0, -1, -1.0, 1, 1e-6, 1e6, 1.0000001e6, 9.99e-7, 1e-308, 5e-324, -1e-308,
    1e308, -1e308, 1.7976931348623157e308, math.inf, -math.inf, math.nan,
    2**63 - 1, -(2**63), 10**30, -(10**400), 123456789,
)

#: Values of the wrong kind for a number, vector, table or flag.
ODD_VALUES: tuple[Any, ...] = (
    "1.0", "", "ü", "\U0001f4a5", "\u202e" + "evil", "x" * 10_000, True, False, [], {},
    [1.0], [1.0, 2.0, 3.0], [[0.0, 1.0]], ["0", "1"], [True, False], {"x": 1.0},
    datetime.date(1979, 5, 27), datetime.time(7, 32), datetime.datetime(1979, 5, 27, 7, 32),
    [math.nan, 0.0], [0.0, math.inf], [1e308, 1e308], [10**30, 0],
)

#: Tokens a number in the text may be replaced by (all valid TOML, some out of range).
NUMBER_TOKENS = ("inf", "-inf", "+inf", "nan", "-nan", "1e309", "-1e309", "1e-400",
                 "0x7FFFFFFFFFFFFFFF", "99999999999999999999999999999", "1_000.5", "0o17",
                 "0b101", "1979-05-27", "\"3\"", "true", "[1, 2]", "{ a = 1 }")

#: Values for a ``friction`` key: near its range's ends (0 and 100), and the extreme numbers.
FRICTION_VALUES: tuple[Any, ...] = (0.3, 100.0, 100.0000001, -0.1, "0.5", [0.5], *EXTREME_NUMBERS)

#: Unicode that a scene's strings and keys may be given.
UNICODE_TEXT = ("Würfel", "立方体", "\U0001f9ca", "\u0000", "\u202e", "a\tb", "\ud7ff",
                "e\u0301", "\ufeff")


@dataclass(frozen=True)
class FuzzInput:
    """One generated scene file."""

    index: int
    """Position in the generated sequence (0-based)."""
    label: str
    """What was done to which seed file, e.g. ``stack-3: set squares[1].mass = inf``."""
    data: bytes
    """The file's content."""


@dataclass(frozen=True)
class Crash:
    """An input that broke the promise, with what happened."""

    index: int
    label: str
    error: str
    """Exception type and first line of its message, or the broken promise."""
    saved: str | None = None
    """Where the input was saved, if a directory was given."""


@dataclass
class FuzzResult:
    """Counts of one fuzz run (every input ends in exactly one outcome)."""

    tried: int = 0
    accepted: int = 0
    """Loaded, and one step ran to a finite state."""
    rejected: int = 0
    """:class:`InputError` naming the file, in one line."""
    step_failures: int = 0
    """Loaded, but the first step raised :class:`StepFailure` (step, solver, status)."""
    crashes: list[Crash] = field(default_factory=list)
    rejection_reasons: Counter[str] = field(default_factory=Counter)
    """How often each kind of rejection occurred (its message up to the first detail)."""
    step_failure_statuses: Counter[str] = field(default_factory=Counter)
    """How often each solver status ended a loaded scene's first step."""
    step_failure_examples: list[tuple[int, str, str]] = field(default_factory=list)
    """The first few step failures: input index, mutation, message and what the
    :data:`CROSS_CHECK` solvers make of the same file."""
    seconds: float = 0.0
    """Wall time of the run (s)."""

    def count(self, outcome: Outcome) -> int:
        """How many inputs ended in ``outcome``."""
        if outcome == "crash":
            return len(self.crashes)
        return int(getattr(self, {"step_failure": "step_failures"}.get(outcome, outcome)))


# ---------------------------------------------------------------------- checking
def check_input(path: Path, *, step: bool = True,
                solver: str = "CLARABEL") -> tuple[Outcome, str]:
    """Load ``path`` and (if ``step``) simulate one step; the outcome and a description."""
    from ...simulate import simulate  # the loader's tests need no solver import

    try:
        scene = Scene.from_toml(path)
    except InputError as error:
        return _judge_input_error(error, str(path))
    except (KeyboardInterrupt, SystemExit):
        raise
    except BaseException as exc:  # noqa: BLE001 - any other exception is the finding
        return "crash", _describe(exc)
    if not step:
        return "accepted", f"{scene.n_boxes} bodies (not stepped)"
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", RuntimeWarning)  # overflow in the geometry
            trajectory = simulate(scene, dt=0.01, steps=1, solver=solver)
    except InputError as error:
        return _judge_input_error(error, str(path))
    except StepFailure as failure:
        if f"step {failure.step}" in str(failure) and failure.solver and failure.status:
            return "step_failure", str(failure).splitlines()[0]
        return "crash", f"unclear StepFailure: {failure!r}"
    except (KeyboardInterrupt, SystemExit):
        raise
    except BaseException as exc:  # noqa: BLE001
        return "crash", _describe(exc)
    if not (np.all(np.isfinite(trajectory.points)) and
            np.all(np.isfinite(trajectory.velocities))):
        return "crash", "a loaded scene stepped to a non-finite state"
    return "accepted", f"{scene.n_boxes} bodies"


def _judge_input_error(error: InputError, source: str) -> tuple[Outcome, str]:
    text = str(error)
    if "\n" in text or not text.startswith(source):
        return "crash", f"unclear InputError (not one line naming the file): {text[:200]!r}"
    return "rejected", error.reason


def _describe(exc: BaseException) -> str:
    first = str(exc).splitlines()[0] if str(exc) else ""
    return f"{type(exc).__name__}: {first[:200]}"


def rejection_kind(reason: str) -> str:
    """A rejection's reason without its values and quoted keys, for counting kinds."""
    reason = re.sub(r"'[^']*'|\"[^\"]*\"", "'…'", reason)
    for stop in (" (", ", got", " by ", ": "):
        reason = reason.split(stop, 1)[0]
    return reason.strip()


# ---------------------------------------------------------------------- running
def run_fuzz(n_inputs: int, seed: int, *, step: bool = True, crash_dir: Path | None = None,
             seeds: Sequence[tuple[str, bytes]] | None = None,
             progress: Callable[[int], None] | None = None) -> FuzzResult:
    """Generate ``n_inputs`` mutated scene files from ``seed`` and check each.

    With ``step`` (default) every scene that loads is simulated for one step too.

    Crashing inputs are saved to ``crash_dir`` (if given) as ``crash-<index>.toml``.
    ``seeds`` are ``(name, file content)`` pairs to mutate (default: :func:`seed_files`).
    """
    started = time.perf_counter()
    result = FuzzResult()
    with tempfile.TemporaryDirectory(prefix="wuerfel-fuzz-") as scratch:
        path = Path(scratch) / "fuzzed-scene.toml"
        for item in generate_inputs(n_inputs, seed, seeds=seeds):
            path.write_bytes(item.data)
            outcome, detail = check_input(path, step=step)
            result.tried += 1
            if outcome == "accepted":
                result.accepted += 1
            elif outcome == "rejected":
                result.rejected += 1
                result.rejection_reasons[rejection_kind(detail)] += 1
            elif outcome == "step_failure":
                result.step_failures += 1
                status = re.search(r"status '([^']*)'", detail)
                result.step_failure_statuses[status.group(1) if status else detail] += 1
                if len(result.step_failure_examples) < MAX_EXAMPLES:
                    result.step_failure_examples.append(
                        (item.index, item.label, f"{detail}; {_cross_check(path)}"))
            else:
                saved = None
                if crash_dir is not None:
                    crash_dir.mkdir(parents=True, exist_ok=True)
                    target = crash_dir / f"crash-{item.index}.toml"
                    target.write_bytes(item.data)
                    saved = str(target)
                result.crashes.append(Crash(item.index, item.label, detail, saved))
            if progress is not None:
                progress(result.tried)
    result.seconds = time.perf_counter() - started
    return result


def _cross_check(path: Path) -> str:
    """What the other solvers make of a file whose first step failed."""
    from ...solve.registry import available_solvers

    found = []
    for solver in (name for name in CROSS_CHECK if name in available_solvers()):
        outcome, detail = check_input(path, solver=solver)
        status = re.search(r"status '([^']*)'", detail)
        found.append(f"{solver} {status.group(1) if status else outcome}")
    return "other solvers: " + ", ".join(found)


def seed_files() -> list[tuple[str, bytes]]:
    """``(name, TOML text)`` of the library scenes in :data:`SEED_SCENES`."""
    return [(name, tomli_w.dumps(Scene.named(name).to_dict()).encode())
            for name in SEED_SCENES]


# ---------------------------------------------------------------------- generating
def generate_inputs(n_inputs: int, seed: int, *,
                    seeds: Sequence[tuple[str, bytes]] | None = None) -> Iterator[FuzzInput]:
    """``n_inputs`` mutated scene files, the same for the same ``seed`` and seed files."""
    rng = random.Random(seed)
    bases = list(seeds) if seeds is not None else seed_files()
    for index in range(n_inputs):
        name, text = rng.choice(bases)
        mutate = rng.choice(_TEXT_MUTATIONS) if rng.random() < 0.35 else _mutate_structure
        label, data = mutate(rng, text)
        yield FuzzInput(index, f"{name}: {label}", data)


def _mutate_structure(rng: random.Random, text: bytes) -> tuple[str, bytes]:
    """One to three edits of the parsed scene, written back as TOML."""
    import tomllib

    data: dict[str, Any] = tomllib.loads(text.decode("utf-8"))
    labels = []
    for _ in range(rng.choice((1, 1, 1, 2, 3))):
        edit = rng.choice(_STRUCTURE_EDITS)
        labels.append(edit(rng, data))
    return "; ".join(labels), tomli_w.dumps(data).encode("utf-8")


def _slots(data: dict[str, Any]) -> list[tuple[str, dict[str, Any], str]]:
    """Every ``(dotted path, containing table, key)`` of the scene's values."""
    slots = [(key, data, key) for key in data]
    for group in ("squares", "boxes", "tables"):
        entries = data.get(group)
        if isinstance(entries, list):
            for i, entry in enumerate(entries):
                if isinstance(entry, dict):
                    slots += [(f"{group}[{i}].{key}", entry, key) for key in entry]
    return slots


def _set_value(rng: random.Random, data: dict[str, Any]) -> str:
    where, table, key = rng.choice(_slots(data))
    value: Any
    if isinstance(table[key], list) and table[key] and rng.random() < 0.6:
        position = rng.randrange(len(table[key]))
        value = rng.choice(EXTREME_NUMBERS + ODD_VALUES[:6])
        table[key][position] = copy.deepcopy(value)
        return f"set {where}[{position}] = {value!r:.40}"
    value = rng.choice(EXTREME_NUMBERS + ODD_VALUES)
    table[key] = copy.deepcopy(value)
    return f"set {where} = {value!r:.40}"


def _negate(rng: random.Random, data: dict[str, Any]) -> str:
    numbers = [(w, t, k) for w, t, k in _slots(data)
               if isinstance(t[k], int | float) and not isinstance(t[k], bool)]
    if not numbers:
        return _set_value(rng, data)
    where, table, key = rng.choice(numbers)
    table[key] = -table[key] * rng.choice((1, 10, 10**300))  # ints stay exact integers
    return f"negate and scale {where}"


def _delete_key(rng: random.Random, data: dict[str, Any]) -> str:
    where, table, key = rng.choice(_slots(data))
    del table[key]
    return f"delete {where}"


def _add_key(rng: random.Random, data: dict[str, Any]) -> str:
    where, table, _ = rng.choice(_slots(data))
    key = rng.choice(("friction", "Mass", "center ", "centre", "") + UNICODE_TEXT)
    table[key] = rng.choice(EXTREME_NUMBERS + ODD_VALUES)
    return f"add key {key!r} beside {where}"


def _set_friction(rng: random.Random, data: dict[str, Any]) -> str:
    """Set (or add) one square's, box's or table's ``friction`` to a :data:`FRICTION_VALUES`."""
    if not (slots := [slot for slot in _slots(data) if "[" in slot[0]]):  # no entry's key
        return _set_value(rng, data)
    where, table, _ = rng.choice(slots)
    table["friction"] = copy.deepcopy(value := rng.choice(FRICTION_VALUES))
    return f"set {where.rsplit('.', 1)[0]}.friction = {value!r:.40}"


def _unicode_name(rng: random.Random, data: dict[str, Any]) -> str:
    data["name"] = "".join(rng.choice(UNICODE_TEXT) for _ in range(rng.randint(1, 50)))
    return "unicode name"


def _nest(rng: random.Random, data: dict[str, Any]) -> str:
    where, table, key = rng.choice(_slots(data))
    depth = rng.randint(1, 40)
    value = table[key]
    for _ in range(depth):
        value = [value] if rng.random() < 0.7 else {"x": value}
    table[key] = value
    return f"nest {where} {depth} deep"


def _many_squares(rng: random.Random, data: dict[str, Any]) -> str:
    count = rng.choice((40, 40, 400))  # 400: a large scene (large-pyramid has 5050)
    spread = rng.choice((1.0, 3.0))  # 1.0: touching or overlapping unit squares
    group = rng.choice(("squares", "boxes"))
    bodies = []
    for i in range(count):
        side = 1.0 if spread > 1.0 else rng.choice((1.0, 1.2))
        bodies.append({"center": [spread * (i % 40), 5.0 + spread * (i // 40)],
                       "size": side if group == "squares" else [side, side / 2]})
    data[group] = bodies
    return f"{count} {group} at spacing {spread}"


def _swap_size_kind(rng: random.Random, data: dict[str, Any]) -> str:
    """A square's ``size`` written as a box's pair, or a box's pair as a scalar."""
    entries = [(group, i, entry) for group in ("squares", "boxes")
               for i, entry in enumerate(_listed(data.get(group)))
               if isinstance(entry, dict) and "size" in entry]
    if not entries:
        return _set_value(rng, data)
    group, index, entry = rng.choice(entries)
    size = entry["size"]
    entry["size"] = size[0] if isinstance(size, list) and size else [size, size]
    return f"swap the kind of {group}[{index}].size"


def _listed(value: object) -> list[Any]:
    """``value`` if it is a list (an earlier edit may have made a group anything), else []."""
    return value if isinstance(value, list) else []


def _empty_groups(rng: random.Random, data: dict[str, Any]) -> str:
    group = rng.choice(("squares", "boxes", "tables"))
    data[group] = rng.choice(([], [{}], [[]], {}, [{"center": []}]))
    return f"replace {group} by {data[group]!r}"


_STRUCTURE_EDITS: tuple[Callable[[random.Random, dict[str, Any]], str], ...] = (
    _set_value, _set_value, _set_value, _negate, _delete_key, _add_key, _unicode_name,
    _nest, _many_squares, _empty_groups, _swap_size_kind, _set_friction,
)


# textual mutations ------------------------------------------------------------
def _replace_number(rng: random.Random, text: bytes) -> tuple[str, bytes]:
    numbers = list(re.finditer(rb"-?\d+(\.\d+)?(e-?\d+)?", text))
    if not numbers:
        return _flip_bytes(rng, text)
    match = rng.choice(numbers)
    token = rng.choice(NUMBER_TOKENS).encode()
    return (f"number {match.group().decode()} -> {token.decode()}",
            text[:match.start()] + token + text[match.end():])


def _deep_nesting(rng: random.Random, text: bytes) -> tuple[str, bytes]:
    depth = rng.choice((10, 100, 990, 2000, 20_000))
    if rng.random() < 0.5:
        value = b"[" * depth + b"1.0" + b"]" * depth
    else:
        value = b"{ a = " * depth + b"1.0" + b" }" * depth
    key = rng.choice((b"gravity", b"deep"))
    return f"{key.decode()} nested {depth} deep", key + b" = " + value + b"\n" + text


def _flip_bytes(rng: random.Random, text: bytes) -> tuple[str, bytes]:
    data = bytearray(text)
    count = rng.randint(1, 8)
    for _ in range(count):
        data[rng.randrange(len(data))] = rng.randrange(256)
    return f"{count} random bytes", bytes(data)


def _insert_bytes(rng: random.Random, text: bytes) -> tuple[str, bytes]:
    chunk = rng.choice((b"\xff\xfe", b"\xc3", b"\x00", b"\r", b"\"", b"'''", b"[[", b"]]",
                        b"=", b"\n[[squares]]\n", b"\n[[boxes]]\n", b"\\u0000", "ü".encode(),
                        "\U0001f9ca".encode()))
    position = rng.randrange(len(text) + 1)
    return f"insert {chunk!r} at {position}", text[:position] + chunk + text[position:]


def _truncate(rng: random.Random, text: bytes) -> tuple[str, bytes]:
    cut = rng.randrange(len(text) + 1)
    return f"truncate at {cut}", text[:cut]


def _duplicate_line(rng: random.Random, text: bytes) -> tuple[str, bytes]:
    lines = text.splitlines(keepends=True)
    index = rng.randrange(len(lines))
    return f"duplicate line {index + 1}", b"".join(lines[:index + 1] + lines[index:])


def _huge_file(rng: random.Random, text: bytes) -> tuple[str, bytes]:
    megabytes = rng.choice((1, 4))
    line = b"# " + b"padding " * 12 + b"\n"
    return f"{megabytes} MB of comments", line * (megabytes * 2**20 // len(line)) + text


_TEXT_MUTATIONS: tuple[Callable[[random.Random, bytes], tuple[str, bytes]], ...] = (
    _replace_number, _replace_number, _deep_nesting, _flip_bytes, _insert_bytes, _truncate,
    _duplicate_line, _huge_file,
)
