"""The ``wuerfel-cvx`` command line: runs, listings, and one-line errors for bad input.

A few cases run the real command in a subprocess (exit status, streams, files as a
user sees them); the rest call :func:`wuerfel_cvx.cli.main` in-process.
"""

from __future__ import annotations

import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from wuerfel_cvx.cli import main
from wuerfel_cvx.scenes.library import ENTRIES
from wuerfel_cvx.solve.registry import available_solvers
from wuerfel_cvx.trajectory import Trajectory

pytestmark = pytest.mark.integration

ERROR_PREFIX = "wuerfel-cvx: error:"


def run_cli(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    """Run ``python -m wuerfel_cvx.cli ARGS`` and capture its output."""
    return subprocess.run([sys.executable, "-m", "wuerfel_cvx.cli", *args], cwd=cwd,
                          capture_output=True, text=True, timeout=120, check=False)


# ------------------------------------------------------------------ subprocess
@pytest.mark.subprocess
def test_simulate_prints_a_summary_and_writes_files(tmp_path: Path) -> None:
    result = run_cli("simulate", "tilted-drop", "--steps", "20", "--out",
                     str(tmp_path / "run"), cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr
    assert "max rod drift" in result.stdout
    assert "scene tilted-drop" in result.stdout
    assert "20 steps" in result.stdout
    npz, csv = tmp_path / "run.npz", tmp_path / "run.metrics.csv"
    assert npz.is_file()
    assert csv.is_file()
    assert str(npz) in result.stdout
    loaded = Trajectory.load(npz)
    assert loaded.n_steps == 20
    assert loaded.points.shape == (21, 4, 2)
    assert len(loaded.metrics) == 20


@pytest.mark.subprocess
def test_the_demo_on_the_native_path_does_not_import_cvxpy(tmp_path: Path) -> None:
    # cvxpy takes about a second to import; only the compiled and declared paths need it
    code = ("import sys; from wuerfel_cvx.cli import main; "
            "code = main(['simulate', 'tilted-drop', '--steps', '3']); "
            "print('cvxpy imported' if 'cvxpy' in sys.modules else 'no cvxpy'); "
            "sys.exit(code)")
    result = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True,
                            text=True, timeout=300, check=False)
    assert result.returncode == 0, result.stderr
    assert result.stdout.splitlines()[-1] == "no cvxpy"


@pytest.mark.subprocess
def test_scenes_lists_every_library_pattern(tmp_path: Path) -> None:
    result = run_cli("scenes", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    listed = [line.split()[0] for line in result.stdout.splitlines() if line.strip()]
    assert listed == [entry.pattern for entry in ENTRIES]


@pytest.mark.subprocess
def test_unknown_scene_in_a_real_process(tmp_path: Path) -> None:
    result = run_cli("simulate", "no-such-scene", "--steps", "2", cwd=tmp_path)
    assert result.returncode == 2
    assert result.stdout == ""
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith(ERROR_PREFIX)
    assert "no-such-scene" in lines[0]
    assert "Traceback" not in result.stderr


# ------------------------------------------------------------------ in-process
def test_solvers_lists_the_available_solvers(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["solvers"]) == 0
    out = capsys.readouterr().out
    listed = [line.split()[0] for line in out.splitlines() if line.strip()]
    assert listed == available_solvers()
    assert "CLARABEL" in listed


def test_scenes_in_process_shows_descriptions(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["scenes"]) == 0
    out = capsys.readouterr().out
    for entry in ENTRIES:
        assert any(line.startswith(entry.pattern) and entry.description in line
                   for line in out.splitlines()), entry.pattern


VALID_SCENE = """\
name = "my-toml-scene"

[[tables]]
center = [0.0, -0.5]
size = [10.0, 1.0]

[[squares]]
center = [0.0, 1.0]
angle = 0.2
"""


def test_a_toml_path_works_as_scene(tmp_path: Path,
                                    capsys: pytest.CaptureFixture[str]) -> None:
    scene_file = tmp_path / "scene.toml"
    scene_file.write_text(VALID_SCENE)
    assert main(["simulate", str(scene_file), "--steps", "5", "--out",
                 str(tmp_path / "out")]) == 0
    captured = capsys.readouterr()
    assert "scene my-toml-scene" in captured.out
    assert "max rod drift" in captured.out
    loaded = Trajectory.load(tmp_path / "out.npz")
    assert loaded.n_steps == 5
    np.testing.assert_allclose(loaded.points[0].mean(axis=0), [0.0, 1.0], atol=1e-12)


@dataclass(frozen=True)
class BadInput:
    """One row of the bad-input table."""

    toml: str | None
    """Content of ``scene.toml`` (then ``{toml}`` in ``args`` is its path), or ``None``."""
    args: tuple[str, ...]
    expect: tuple[str, ...]
    """Fragments the error line must contain (``{toml}`` replaced by the file's path)."""


OVERLAPPING = """\
[[squares]]
center = [0.0, 0.5]

[[squares]]
center = [0.1, 1.25]
"""

BAD_INPUTS: dict[str, BadInput] = {
    "unknown scene": BadInput(None, ("no-such-scene",), ("unknown scene", "no-such-scene")),
    "missing toml": BadInput(None, ("{dir}/missing.toml",), ("{dir}/missing.toml",
                                                              "not found")),
    "malformed toml": BadInput("[[squares]\ncenter = [0.0, 1.0]\n", ("{toml}",),
                               ("{toml}", "malformed TOML")),
    "unknown key": BadInput("[[squares]]\ncenter = [0.0, 1.0]\ncolour = 'red'\n",
                            ("{toml}",), ("{toml}", "squares[0].colour", "unknown key")),
    "negative mass": BadInput("[[squares]]\ncenter = [0.0, 1.0]\nmass = -1.0\n",
                              ("{toml}",), ("{toml}", "squares[0].mass", "positive")),
    "nan in vector": BadInput("[[squares]]\ncenter = [nan, 1.0]\n", ("{toml}",),
                              ("{toml}", "squares[0].center[0]", "finite")),
    "dt zero": BadInput(None, ("tilted-drop", "--dt", "0"), ("dt", "positive")),
    "dt negative": BadInput(None, ("tilted-drop", "--dt", "-0.01"), ("dt", "positive")),
    "dt nan": BadInput(None, ("tilted-drop", "--dt", "nan"), ("dt", "nan")),
    "unknown solver": BadInput(None, ("tilted-drop", "--solver", "nosuchsolver"),
                               ("solver", "nosuchsolver", "CLARABEL", "OSQP")),
    "unknown formulation": BadInput(None, ("tilted-drop", "--formulation", "acceleration"),
                                    ("formulation", "acceleration", "velocity")),
    "unknown tolerance": BadInput(None, ("tilted-drop", "--tol", "extreme"),
                                  ("tol", "extreme", "default")),
    "overlap": BadInput(OVERLAPPING, ("{toml}",),
                        ("{toml}", "squares[0]", "overlaps squares[1]", "allow_overlap")),
}


@pytest.mark.parametrize("case", list(BAD_INPUTS.values()), ids=list(BAD_INPUTS))
def test_bad_input_exits_2_with_one_error_line(case: BadInput, tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    scene_file = tmp_path / "scene.toml"
    if case.toml is not None:
        scene_file.write_text(case.toml)

    def fill(text: str) -> str:
        return text.replace("{toml}", str(scene_file)).replace("{dir}", str(tmp_path))

    args = [fill(arg) for arg in case.args]
    status = main(["simulate", *args, "--steps", "2"])
    captured = capsys.readouterr()
    assert status == 2
    assert captured.out == ""
    lines = captured.err.splitlines()
    assert len(lines) == 1, captured.err
    line = lines[0]
    assert line.startswith(ERROR_PREFIX)
    assert "Traceback" not in captured.err
    for fragment in case.expect:
        assert fill(fragment) in line, (fragment, line)


def test_unwritable_out_is_one_error_line(tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    status = main(["simulate", "tilted-drop", "--steps", "2", "--out", str(blocker / "run")])
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 2
    assert len(err) == 1 and err[0].startswith("wuerfel-cvx: error:") and "--out" in err[0]


def test_a_directory_named_like_a_scene_does_not_shadow_the_library(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "tilted-drop").mkdir()
    monkeypatch.chdir(tmp_path)
    assert main(["simulate", "tilted-drop", "--steps", "2"]) == 0
    assert "scene tilted-drop" in capsys.readouterr().out


def test_simulate_with_sleep_saves_asleep_steps(tmp_path: Path) -> None:
    out = tmp_path / "stack"
    assert main(["simulate", "stack-3", "--steps", "70", "--sleep", "--out", str(out),
                 "--no-progress"]) == 0
    statuses = Trajectory.load(out.with_suffix(".npz")).metrics["status"]
    # At rest from the start: awake for the first 0.5 s, asleep after.
    assert (statuses.iloc[:50] == "optimal").all() and (statuses.iloc[50:] == "asleep").all()


@pytest.mark.parametrize(("flags", "islands"), [([], False), (["--islands"], True)])
def test_islands_flag_reaches_simulate(flags: list[str], islands: bool,
                                       monkeypatch: pytest.MonkeyPatch,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    import wuerfel_cvx.cli as cli
    from wuerfel_cvx.simulate import simulate

    seen: dict[str, object] = {}

    def recording(*args: object, **kwargs: object) -> Trajectory:
        seen.update(kwargs)
        return simulate(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(cli, "simulate", recording)
    assert main(["simulate", "stack-3", "--steps", "3", *flags]) == 0
    assert seen["settings"].islands is islands  # type: ignore[attr-defined]
    assert "verified steps       3/3" in capsys.readouterr().out


# ------------------------------------------------- outputs checked before the run
def _refuse_to_simulate(monkeypatch: pytest.MonkeyPatch) -> None:
    """Make the CLI's simulate fail the test if it is reached."""
    import wuerfel_cvx.cli as cli

    def not_expected(*args: object, **kwargs: object) -> Trajectory:
        raise AssertionError("the run started although its outputs were already known bad")

    monkeypatch.setattr(cli, "simulate", not_expected)


def _one_error_line(captured: pytest.CaptureResult[str]) -> str:
    assert captured.out == ""  # no summary: the run never started
    lines = captured.err.splitlines()
    assert len(lines) == 1, captured.err
    assert lines[0].startswith(ERROR_PREFIX)
    return lines[0]


@pytest.mark.parametrize("fps", ["0", "-5", "nan", "inf"])
def test_bad_fps_is_refused_before_the_run(fps: str, tmp_path: Path,
                                           monkeypatch: pytest.MonkeyPatch,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    _refuse_to_simulate(monkeypatch)
    status = main(["simulate", "tilted-drop", "--steps", "300", "--fps", fps,
                   "--animate", str(tmp_path / "a.gif")])
    line = _one_error_line(capsys.readouterr())
    assert status == 2
    assert "--fps" in line and "positive number of frames per second" in line
    assert not (tmp_path / "a.gif").exists()


@pytest.mark.parametrize(("option", "target", "reason"), [
    ("--animate", "blocker/a.gif", "blocker is a file, not a folder"),
    ("--animate", "folder.gif", "a folder of that name exists"),
    ("--out", "blocker/run", "blocker is a file, not a folder"),
    ("--out", "folder.npz", "a folder of that name exists"),
])
def test_unwritable_output_is_refused_before_the_run(
        option: str, target: str, reason: str, tmp_path: Path,
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "blocker").write_text("not a folder")
    (tmp_path / "folder.gif").mkdir()
    (tmp_path / "folder.npz").mkdir()
    monkeypatch.chdir(tmp_path)
    _refuse_to_simulate(monkeypatch)
    status = main(["simulate", "tilted-drop", "--steps", "300", option, target])
    line = _one_error_line(capsys.readouterr())
    assert status == 2
    assert line == f"{ERROR_PREFIX} {target}: {option}: cannot write ({reason})"


def test_checking_the_outputs_leaves_no_file_behind(tmp_path: Path,
                                                    monkeypatch: pytest.MonkeyPatch,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    # A bad --fps is found after --out was checked: the check must not leave files.
    _refuse_to_simulate(monkeypatch)
    status = main(["simulate", "tilted-drop", "--out", str(tmp_path / "new" / "run"),
                   "--animate", str(tmp_path / "new" / "a.gif"), "--fps", "0"])
    assert status == 2
    assert "--fps" in capsys.readouterr().err
    assert list((tmp_path / "new").iterdir()) == []


def test_version_is_the_distributions(capsys: pytest.CaptureFixture[str]) -> None:
    import tomllib
    from importlib.metadata import version

    with pytest.raises(SystemExit) as stop:
        main(["--version"])
    assert stop.value.code == 0
    assert capsys.readouterr().out == f"wuerfel-cvx {version('wuerfel_cvx')}\n"
    project = Path(__file__).resolve().parents[1] / "pyproject.toml"
    assert version("wuerfel_cvx") == tomllib.loads(project.read_text())["project"]["version"]


def test_version_in_a_real_process(tmp_path: Path) -> None:
    from importlib.metadata import version

    result = run_cli("--version", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == f"wuerfel-cvx {version('wuerfel_cvx')}"


# ------------------------------------------------------------------- Ctrl-C
def _interrupt_after(done: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """The CLI's simulate runs ``done`` real steps, then stops as Ctrl-C would."""
    import wuerfel_cvx.cli as cli
    from wuerfel_cvx.errors import Interrupted
    from wuerfel_cvx.simulate import simulate

    def interrupted(*args: object, **kwargs: object) -> Trajectory:
        kwargs["steps"] = done
        stop = Interrupted(done + 1)
        stop.trajectory = simulate(*args, **kwargs)  # type: ignore[arg-type]
        raise stop

    monkeypatch.setattr(cli, "simulate", interrupted)


def test_ctrl_c_keeps_the_steps_done(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    from PIL import Image

    _interrupt_after(3, monkeypatch)
    out, gif = tmp_path / "run", tmp_path / "run.gif"
    status = main(["simulate", "tilted-drop", "--steps", "300", "--out", str(out),
                   "--animate", str(gif), "--fps", "100", "--no-progress"])
    captured = capsys.readouterr()
    assert status == 130
    assert captured.out == ""  # no summary of a run that did not end
    assert captured.err.splitlines()[-1] == (
        f"wuerfel-cvx: interrupted during step 4 of 300; kept the 3 steps done in {out}.npz "
        f"and {gif}")
    assert "Traceback" not in captured.err
    kept = Trajectory.load(f"{out}.npz")
    assert kept.n_steps == 3 and len(kept.metrics) == 3
    with Image.open(gif) as image:
        assert image.n_frames == 4  # states 0..3, at 100 fps of 10 ms steps


def test_ctrl_c_without_outputs_says_so(monkeypatch: pytest.MonkeyPatch,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    _interrupt_after(2, monkeypatch)
    assert main(["simulate", "tilted-drop", "--no-progress"]) == 130
    assert capsys.readouterr().err == ("wuerfel-cvx: interrupted during step 3 of 200; kept the "
                                       "2 steps done (no --out or --animate to keep them in)\n")


def test_ctrl_c_outside_a_run_is_one_line(monkeypatch: pytest.MonkeyPatch,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    import wuerfel_cvx.cli as cli

    def stopped(*args: object, **kwargs: object) -> Trajectory:
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, "simulate", stopped)
    assert main(["simulate", "tilted-drop"]) == 130
    assert capsys.readouterr().err == "wuerfel-cvx: interrupted\n"


# ------------------------------------------------------------- GIF progress
@pytest.mark.parametrize(("flag", "shown"), [("--progress", True), ("--no-progress", False)])
def test_animation_progress_follows_the_flag(flag: str, shown: bool, tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["simulate", "single-drop", "--steps", "8", "--fps", "100", flag,
                 "--animate", str(tmp_path / "a.gif")]) == 0
    err = capsys.readouterr().err
    assert ("a.gif:" in err and "frame" in err) is shown  # tqdm's bar: "a.gif: ... frame/s"


def test_ctrl_c_before_any_trajectory_keeps_nothing(tmp_path: Path,
                                                    monkeypatch: pytest.MonkeyPatch,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    import wuerfel_cvx.cli as cli
    from wuerfel_cvx.errors import Interrupted

    def stopped(*args: object, **kwargs: object) -> Trajectory:
        raise Interrupted(1)  # no trajectory attached

    monkeypatch.setattr(cli, "simulate", stopped)
    assert main(["simulate", "tilted-drop", "--out", str(tmp_path / "run")]) == 130
    assert capsys.readouterr().err == ("wuerfel-cvx: interrupted during step 1 of 200; kept no "
                                       "steps\n")
    assert list(tmp_path.iterdir()) == []


# ------------------------------------------- what a new user tripped over (issue 27, item 7)
@pytest.mark.parametrize("given", ["dirout/", "existing"])
def test_out_naming_a_folder_writes_the_scene_inside_it(
        given: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "existing").mkdir()
    monkeypatch.chdir(tmp_path)
    assert main(["simulate", "tilted-drop", "--steps", "2", "--out", given]) == 0
    folder = tmp_path / given.rstrip("/")
    assert Trajectory.load(folder / "tilted-drop.npz").n_steps == 2
    assert (folder / "tilted-drop.metrics.csv").is_file()
    assert not (tmp_path / "dirout.npz").exists()
    assert f"saved {Path(given.rstrip('/')) / 'tilted-drop.npz'}" in capsys.readouterr().out


@pytest.mark.parametrize(("flags", "note"), [
    (["--table-mass", "10", "--formulation", "velocity"],
     "note: --table-mass 10: the table corners are variables of that mass held still by "
     "equalities; the tables do not move"),
    (["--friction-model", "coulomb"], "note: scene tilted-drop has no friction: "
                                      "--friction-model coulomb changes nothing"),
    ([], None),
])
def test_options_without_effect_on_the_motion_are_noted(
        flags: list[str], note: str | None, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["simulate", "tilted-drop", "--steps", "2", "--no-progress", *flags]) == 0
    err = capsys.readouterr().err
    assert err == ("" if note is None else f"wuerfel-cvx: {note}\n")


def test_friction_model_on_a_scene_with_friction_is_no_note(
        capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["simulate", "card-house", "--steps", "1", "--no-progress",
                 "--friction-model", "ccp"]) == 0
    assert "note:" not in capsys.readouterr().err


def test_help_lists_what_the_checks_accept_without_markup(
        capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    from wuerfel_cvx.lab.bench.suite import suite_names

    monkeypatch.setenv("COLUMNS", "1000")  # argparse wraps help at the terminal's width
    helps = {}
    for command in ([], ["simulate"], ["bench"], ["robustness"], ["report"], ["export-qps"]):
        with pytest.raises(SystemExit):
            main([*command, "--help"])
        helps[" ".join(command)] = " ".join(capsys.readouterr().out.split())
    for text in helps.values():
        assert "``" not in text and ":func:" not in text and ":class:" not in text
    # not listed: finding SCS would import cvxpy, a second the native path does without
    assert "(those installed: 'wuerfel-cvx solvers'; default CLARABEL)" in helps["simulate"]
    assert f"suite name ({', '.join(suite_names())})" in helps["bench"]
    assert main(["bench", "--suite", "no-such-suite"]) == 2
    assert f"known: {', '.join(suite_names())};" in capsys.readouterr().err


@pytest.mark.parametrize(("scene", "said"), [
    ("tilted-drop", "scene tilted-drop: 1 square, "),
    ("plank-drop", "scene plank-drop: 1 box, "),
])
def test_the_summary_names_squares_and_boxes(scene: str, said: str) -> None:
    from wuerfel_cvx import simulate

    assert simulate(scene, steps=1).summary().startswith(said)


def test_the_summary_counts_both_kinds() -> None:
    from wuerfel_cvx.trajectory import _bodies_text

    assert _bodies_text(2, 1) == "2 squares and 1 box"
    assert (_bodies_text(1, 0), _bodies_text(0, 3), _bodies_text(0, 0)) == (
        "1 square", "3 boxes", "0 boxes")


def test_a_fallback_shared_within_a_step_is_explained() -> None:
    import pandas as pd

    from wuerfel_cvx.cli import fallback_line

    metrics = pd.DataFrame({"status": ["optimal", "optimal", "optimal"],
                            "primary_status": ["optimal", "solver_error", "solver_error"],
                            "solver": ["CLARABEL", "OSQP", "CLARABEL+OSQP"]})
    run = Trajectory(times=np.zeros(4), points=np.zeros((4, 4, 2)),
                     velocities=np.zeros((4, 4, 2)), metrics=metrics,
                     info={"solver": "CLARABEL"})
    assert fallback_line(run) == (
        "fallback             2 steps solved by CLARABEL+OSQP, OSQP after CLARABEL failed "
        "(CLARABEL+OSQP: a step whose QPs were solved partly by each)")
    metrics.loc[2, "solver"] = "OSQP"
    assert fallback_line(run) == ("fallback             2 steps solved by OSQP after "
                                  "CLARABEL failed")


# ------------------------------------------------------- noise (issue 27, item 8)
def test_a_warning_during_a_run_is_one_line(monkeypatch: pytest.MonkeyPatch,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    import warnings

    import wuerfel_cvx.cli as cli
    from wuerfel_cvx.friction.coulomb import CoulombNotConverged
    from wuerfel_cvx.simulate import simulate

    def warning(*args: object, **kwargs: object) -> Trajectory:
        warnings.warn("step 3: the Coulomb fixed point did not converge in 50 iterations",
                      CoulombNotConverged, stacklevel=1)
        return simulate(*args, **kwargs)  # type: ignore[arg-type]

    shown = warnings.showwarning
    monkeypatch.setattr(cli, "simulate", warning)
    assert main(["simulate", "tilted-drop", "--steps", "2", "--progress"]) == 0
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if "warning" in line]
    assert lines == ["wuerfel-cvx: warning: step 3: the Coulomb fixed point did not converge "
                     "in 50 iterations"], err
    assert ".py:" not in err and "warnings.warn" not in err
    assert warnings.showwarning is shown  # Python's own again after the command


@pytest.mark.subprocess
@pytest.mark.skipif("HIGHS" not in available_solvers(), reason="highspy is not installed")
def test_highs_prints_no_banner(tmp_path: Path) -> None:
    result = run_cli("simulate", "tilted-drop", "--steps", "2", "--solver", "highs",
                     cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("scene tilted-drop: 1 square, 2 steps")
    assert "HiGHS" not in result.stdout + result.stderr
