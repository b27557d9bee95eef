"""Scene files named in a suite: found beside the suite file, wherever the command runs."""

from __future__ import annotations

from pathlib import Path

import pytest

from wuerfel_cvx.cli import main
from wuerfel_cvx.errors import InputError
from wuerfel_cvx.lab.bench.runner import reference_file_name
from wuerfel_cvx.lab.bench.suite import Suite
from wuerfel_cvx.scenes.scene import Scene

pytestmark = pytest.mark.unit

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"

SUITE = """name = "files"
[defaults]
duration = 0.05
[[grid]]
scenes = ["{scene}", "tilted-drop"]
"""


def suite_in(folder: Path, scene: str) -> Path:
    """A suite file in ``folder`` naming ``scene`` and the library's tilted drop."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "files.toml"
    path.write_text(SUITE.format(scene=scene))
    return path


def test_a_scene_file_is_found_beside_the_suite_from_any_folder(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    suite_file = suite_in(tmp_path / "suites", "scenes/drop.toml")
    (tmp_path / "suites" / "scenes").mkdir()
    scene_file = tmp_path / "suites" / "scenes" / "drop.toml"
    scene_file.write_text(Scene.named("tilted-drop").to_toml())
    monkeypatch.chdir(tmp_path)  # not the suite's folder
    by_file, by_name = Suite.from_toml(Path("suites") / "files.toml").points
    assert by_file.scene == "scenes/drop.toml"  # as written: the point's id stays put
    assert by_file.point_id.startswith("scenes/drop.toml|")
    assert by_file.scene_input == str(scene_file.resolve())
    assert (by_name.scene_file, by_name.scene_input) == (None, "tilted-drop")
    key = by_file.reference_key
    assert key is not None and key[0] == str(scene_file.resolve())
    assert reference_file_name(key).startswith("drop-rigid-")
    assert suite_file.is_file()


def test_a_missing_scene_file_is_an_input_error_naming_the_field(tmp_path: Path) -> None:
    suite_file = suite_in(tmp_path, "scenes/nowhere.toml")
    with pytest.raises(InputError) as caught:
        Suite.from_toml(suite_file)
    assert caught.value.field == "grid[0].scenes"
    assert "'scenes/nowhere.toml' not found" in str(caught.value)
    assert str(tmp_path / "scenes" / "nowhere.toml") in str(caught.value)


@pytest.mark.parametrize("name", ["friction-smoke", "islands"])
def test_the_suites_with_scene_files_load_outside_the_repository(
        name: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    suite = Suite.from_toml(BENCHMARKS / f"{name}.toml")
    files = [point.scene_input for point in suite.points if point.scene_file is not None]
    assert files and all(Path(file).is_file() for file in files)
    assert all(Path(file).parent == BENCHMARKS / "scenes" for file in files)


def test_bench_with_a_missing_scene_file_is_one_line_and_exit_2_before_the_sweep(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    suite_file = suite_in(tmp_path, "scenes/nowhere.toml")
    monkeypatch.chdir(tmp_path)
    assert main(["bench", "--suite", str(suite_file), "--out", "out", "--no-progress"]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.count("\n") == 1
    assert captured.err.startswith(f"wuerfel-cvx: error: {suite_file}: grid[0].scenes: ")
    assert not (tmp_path / "out").exists()
