"""The benchmark report and its plots, from the fixture in tests/fixtures/.

The expected numbers are computed here straight from the fixture CSV with the csv module,
independently of the report's pandas code.
"""

from __future__ import annotations

import csv
import math
import re
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest
from matplotlib.figure import Figure

from wuerfel_cvx.errors import InputError
from wuerfel_cvx.lab.bench import plots, schema
from wuerfel_cvx.lab.bench.report import markdown_table, write_report
from wuerfel_cvx.lab.bench.shgeom import DEFAULT_TIME_SHIFT, shifted_geometric_mean

pytestmark = pytest.mark.integration

FIXTURES = Path(__file__).resolve().parent / "fixtures"
RESULTS = FIXTURES / "results-small.csv"


def fixture_rows() -> list[dict[str, str]]:
    with RESULTS.open(encoding="utf-8", newline="") as handle:
        return list(csv.DictReader(handle))


def table_after(text: str, heading: str) -> list[list[str]]:
    """Cells of the first Markdown table after ``heading`` (header and rule dropped)."""
    lines = text.splitlines()
    start = lines.index(heading)
    first = next(i for i in range(start + 1, len(lines)) if lines[i].startswith("|"))
    rows = []
    for line in lines[first + 2:]:
        if not line.startswith("|"):
            break
        cells = re.split(r"(?<!\\)\|", line.strip())[1:-1]
        rows.append([cell.strip() for cell in cells])
    return rows


@pytest.fixture(scope="module")
def report(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("reports")
    return write_report(RESULTS, root)


@pytest.fixture(scope="module")
def readme(report: Path) -> str:
    return report.read_text(encoding="utf-8")


# ------------------------------------------------------------------ shifted geomean


def test_shifted_geometric_mean_matches_hand_computation() -> None:
    # exp((log 2e-3 + log 5e-3) / 2) - 1e-3 = sqrt(1e-5) - 1e-3
    assert shifted_geometric_mean([1e-3, 4e-3], shift=1e-3) == pytest.approx(
        math.sqrt(1e-5) - 1e-3, rel=1e-12)
    assert shifted_geometric_mean([2.0, 8.0], shift=0.0) == pytest.approx(4.0, rel=1e-12)
    assert shifted_geometric_mean([0.007] * 5) == pytest.approx(0.007, rel=1e-12)


def test_shift_damps_tiny_times_but_not_typical_ones() -> None:
    # B is 5x slower than A on a tiny point, equal on a typical one: unshifted, B would
    # look 2.2x slower overall; shifted by 0.1 ms, about 1.3x.
    a, b = [2e-5, 1e-2], [1e-4, 1e-2]
    assert shifted_geometric_mean(b, 0.0) / shifted_geometric_mean(a, 0.0) == pytest.approx(
        math.sqrt(5))
    assert shifted_geometric_mean(b) / shifted_geometric_mean(a) < 1.4
    # Twice as slow on typical times (2-20 ms) still shows as nearly twice as slow.
    fast, slow = [2e-3, 1e-2], [4e-3, 2e-2]
    assert shifted_geometric_mean(slow) / shifted_geometric_mean(fast) > 1.95
    assert DEFAULT_TIME_SHIFT == 1e-4
    assert shifted_geometric_mean([0.0, 1e-3]) > 0  # a zero time is harmless


@pytest.mark.parametrize("values", [[], [1.0, math.nan], [-1.0], [1.0, math.inf]])
def test_shifted_geometric_mean_rejects_bad_input(values: list[float]) -> None:
    with pytest.raises(ValueError):
        shifted_geometric_mean(values)


def test_zero_without_shift_is_rejected() -> None:
    with pytest.raises(ValueError):
        shifted_geometric_mean([0.0, 1.0], shift=0.0)


# ------------------------------------------------------------- front and exponent


def test_pareto_front_of_hand_made_points() -> None:
    points = [(1, 10), (2, 5), (3, 7), (4, 1), (5, 1), (2, 6), (0.5, 20), (6, 0.5), (3, 5),
              (math.nan, 0.1)]
    x, y = zip(*points, strict=True)
    front = plots.pareto_front(x, y)
    # (2, 6), (3, 7) and (3, 5) are beaten by (2, 5); (5, 1) by (4, 1); NaN never counts.
    assert front.tolist() == [6, 0, 1, 3, 7]


def test_pareto_front_of_one_point_and_of_none() -> None:
    assert plots.pareto_front([3.0], [4.0]).tolist() == [0]
    assert plots.pareto_front([], []).tolist() == []


def test_fitted_exponent_recovers_power_law() -> None:
    n = np.array([1, 2, 5, 10, 50, 210])
    assert plots.fitted_exponent(n, 3e-4 * n**1.5) == pytest.approx(1.5, abs=1e-10)
    assert plots.fitted_exponent(n, 7.0 * n**1.0) == pytest.approx(1.0, abs=1e-10)


def test_fitted_exponent_needs_two_sizes() -> None:
    with pytest.raises(ValueError):
        plots.fitted_exponent([5, 5], [1e-3, 2e-3])


def test_log_floor_is_a_decade_below_smallest_positive() -> None:
    assert plots.log_floor([0.0, 3e-7, 2e-3]) == pytest.approx(1e-8)
    assert plots.log_floor([0.0, math.nan]) == pytest.approx(1e-12)


def test_markdown_table_escapes_pipes_and_checks_widths() -> None:
    table = markdown_table(["a", "b"], [["x|y", 1]], align="lr")
    assert table.splitlines() == ["| a | b |", "| --- | ---: |", "| x\\|y | 1 |"]
    with pytest.raises(ValueError):
        markdown_table(["a", "b"], [["only one"]])


# -------------------------------------------------------------------------- report


def test_report_is_written_under_suite_name(report: Path) -> None:
    assert report.name == "README.md"
    assert report.parent.name == "fixture"
    assert report.is_file()


def test_header_names_machine_and_versions_from_rows(readme: str) -> None:
    rows = fixture_rows()
    assert readme.startswith("# Benchmark report: `fixture`")
    assert f"**CPU:** {rows[0]['cpu']}" in readme
    assert f"**Python:** {rows[0]['python_version']}" in readme
    assert f"**wuerfel_cvx:** {rows[0]['package_version']}" in readme
    assert f"**cvxpy:** {rows[0]['cvxpy_version']}" in readme
    versions = {row["solver"]: row["solver_version"] for row in rows}
    assert set(versions) == {"CLARABEL", "OSQP", "PIQP", "SCS", "PYMUNK"}
    for solver, version in versions.items():
        assert f"{solver} {version}" in readme
    assert re.search(r"\*\*Report generated:\*\* \d{4}-\d\d-\d\d \d\d:\d\d UTC", readme)
    finished = sorted(row["finished_at"] for row in rows)
    first, last = (stamp[:16].replace("T", " ") for stamp in (finished[0], finished[-1]))
    assert first != last
    assert f"finished {first} – {last} UTC" in readme
    assert "wuerfel-cvx bench --suite fixture --out" in readme
    assert re.search(r"wuerfel-cvx report \S+/results\.csv", readme)


def expected_outcomes() -> dict[tuple[str, str], dict[str, int]]:
    counts: dict[tuple[str, str], dict[str, int]] = defaultdict(lambda: defaultdict(int))
    for row in fixture_rows():
        count = counts[(row["formulation"], row["solver"])]
        count["points"] += 1
        success = row["success"] == "true"
        checked = success and row["verified"] != ""
        count["success"] += success
        count["checked"] += checked
        count["verified"] += checked and row["verified"] == "true"
    return counts


def rate(numerator: int, denominator: int) -> str:
    return "n/a" if denominator == 0 else f"{100 * numerator / denominator:.1f} %"


def test_success_table_has_independently_computed_rates(readme: str) -> None:
    expected = expected_outcomes()
    table = {(cells[0], cells[1]): cells for cells in table_after(readme, "## Success")}
    assert set(table) == set(expected)
    for key, count in expected.items():
        cells = table[key]
        assert int(cells[2]) == count["points"]
        assert int(cells[6]) == count["success"]
        assert cells[7] == rate(count["success"], count["points"])
    assert table[("velocity", "OSQP")][7] == "92.3 %"  # 12 of 13: one failed step
    assert table[("velocity", "SCS")][7] == "0.0 %"  # the error row


def test_verified_table_counts_claims_that_survive_the_check(readme: str) -> None:
    expected = expected_outcomes()
    table = {(cells[0], cells[1]): cells for cells in table_after(readme, "### Verified rate")}
    assert set(table) == set(expected)
    for key, count in expected.items():
        assert [int(c) for c in table[key][2:5]] == [count["success"], count["checked"],
                                                     count["verified"]]
        assert table[key][5] == rate(count["verified"], count["checked"])
    assert table[("velocity", "OSQP")][5] == "83.3 %"  # 10 of 12 claims verified
    assert table[("peer", "PYMUNK")][5] == "n/a"  # no residual check for peers


def test_time_table_uses_points_every_solver_completed(readme: str) -> None:
    solvers = ("CLARABEL", "OSQP", "PIQP")
    done: dict[str, dict[tuple[str, ...], float]] = defaultdict(dict)
    for row in fixture_rows():
        if row["formulation"] == "velocity" and row["status"] == "ok":
            key = (row["scene"], row["tol"], row["dt"], row["table_mass"], row["extra_rod"])
            done[row["solver"]][key] = float(row["wall_time_per_step_median"])
    common = set.intersection(*(set(done[solver]) for solver in solvers))
    assert set(done) == set(solvers)  # SCS completed nothing
    section = readme.split("### Formulation `velocity`", 1)[1]
    assert f"Over {len(common)} grid points" in section.split("\n\n")[1]
    assert "Left out (completed no grid point): SCS" in section.split("\n\n")[1]
    table = {cells[1]: cells for cells in table_after(readme, "### Formulation `velocity`")}
    assert set(table) == set(solvers)
    means = {}
    for solver in solvers:
        logs = [math.log(done[solver][key] + 1e-4) for key in common]
        means[solver] = math.exp(sum(logs) / len(logs)) - 1e-4
        assert table[solver][2] == f"{1e3 * means[solver]:.3g}"
    fastest = min(means, key=means.__getitem__)
    assert table[fastest][3] == "1.00"
    slowest = max(means, key=means.__getitem__)
    assert table[slowest][3] == f"{means[slowest] / means[fastest]:.2f}"


def test_accuracy_table_lists_solvers_that_completed(readme: str) -> None:
    table = {(cells[0], cells[1]): cells for cells in table_after(readme, "## Accuracy")}
    completed = {(r["formulation"], r["solver"]) for r in fixture_rows() if r["status"] == "ok"}
    assert set(table) == completed
    errors = [float(r["trajectory_error"]) for r in fixture_rows()
              if (r["formulation"], r["solver"], r["status"]) == ("velocity", "OSQP", "ok")]
    assert table[("velocity", "OSQP")][5] == f"{max(errors):.3g}"
    not_plotted = [r for r in fixture_rows() if r["status"] != "ok" or not r["trajectory_error"]]
    assert f"Left out: {len(not_plotted)} grid points" in readme


def test_every_failed_or_errored_row_is_listed(readme: str) -> None:
    bad = [row for row in fixture_rows() if row["status"] != "ok"]
    assert {row["status"] for row in bad} == {"failed", "error"}
    table = table_after(readme, "## Failed and errored grid points")
    assert len(table) == len(bad)
    for row in bad:
        match = [cells for cells in table if cells[2] == row["solver"]
                 and cells[0] == row["scene"] and cells[6] == row["status"]]
        assert len(match) == 1
        assert match[0][7] == (row["failed_step"] or "–")
        assert match[0][8] == row["error"].replace("|", "\\|")


def test_every_linked_image_exists_and_is_an_image(report: Path, readme: str) -> None:
    links = re.findall(r"\]\(([^)]+\.(?:png|svg))\)", readme)
    stems = {Path(link).stem for link in links}
    assert {"pareto", "pareto-headline", "drift-penetration", "scaling", "success",
            "success-by-scene", "timing-breakdown"} <= stems
    for link in links:
        assert not Path(link).is_absolute()
        path = report.parent / link
        data = path.read_bytes()
        assert len(data) > 1000
        if path.suffix == ".png":
            assert data.startswith(b"\x89PNG\r\n\x1a\n")
        else:
            assert b"<svg" in data[:2000]


def test_scaling_table_gives_fixture_exponent(readme: str) -> None:
    table = table_after(readme, "## Time per step against size")
    assert {cells[2] for cells in table} == {"CLARABEL", "OSQP", "PIQP", "PYMUNK"}
    assert all(cells[4] == "1.40" for cells in table)  # the fixture's t ~ n^1.4


def test_report_leaves_out_plots_without_data(tmp_path: Path) -> None:
    rows = [row for row in fixture_rows() if row["scene"] == "tilted-drop"]
    results = tmp_path / "run" / "results.csv"  # no series directory next to it
    results.parent.mkdir()
    stale = tmp_path / "out" / "fixture" / "scaling.png"  # from an earlier report
    stale.parent.mkdir(parents=True)
    stale.write_bytes(b"old")
    with results.open("w", encoding="utf-8", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]), lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
    readme = write_report(results, tmp_path / "out").read_text(encoding="utf-8")
    assert "## Time per step against size" not in readme  # one square only
    assert "### Drift and penetration over time" not in readme
    assert not stale.exists()
    assert "### Speed against accuracy" in readme
    assert "wuerfel-cvx bench --suite fixture --out bench-results/fixture" in readme


def test_plots_return_nothing_without_data(tmp_path: Path) -> None:
    results = schema.read_results(RESULTS)
    one_size = results[results["scene"] == "tilted-drop"]
    assert plots.plot_scaling(one_size, tmp_path) == []
    assert plots.plot_drift_penetration(results, tmp_path / "no-series", tmp_path) == []
    failed_only = results[results["status"] != "ok"]
    assert plots.plot_pareto(failed_only, tmp_path) == []
    assert list(tmp_path.iterdir()) == []


def test_mixed_suites_are_refused(tmp_path: Path) -> None:
    rows = fixture_rows()
    rows[-1]["suite"] = "other"
    mixed = tmp_path / "results.csv"
    with mixed.open("w", encoding="utf-8", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]), lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
    with pytest.raises(InputError, match="several suites"):
        write_report(mixed, tmp_path / "reports")
    assert not (tmp_path / "reports").exists()


def test_fixture_is_valid_and_has_the_promised_cases() -> None:
    results = schema.read_results(RESULTS)
    assert set(results["suite"]) == {"fixture"}
    assert {"ok", "failed", "error"} <= set(results["status"])
    assert results["table_mass"].notna().any()
    assert results["n_squares"].nunique() >= 3
    assert set(results["dt"]) == {0.01, 0.02}
    assert set(results["tol"]) >= {"low", "default", "high", "native"}
    series = list((FIXTURES / "series").glob("*.csv"))
    assert series
    assert all(path.name in {schema.series_file_name(p) for p in results["point_id"]}
               for path in series)


def test_headline_scene_can_be_chosen_and_must_exist(tmp_path: Path) -> None:
    readme = write_report(RESULTS, tmp_path, headline="stack-3").read_text(encoding="utf-8")
    assert "Scene `stack-3`:" in readme
    with pytest.raises(InputError, match="not in the results"):
        write_report(RESULTS, tmp_path, headline="no-such-scene")


def test_report_carries_a_copy_of_its_results(tmp_path: Path) -> None:
    readme = write_report(RESULTS, tmp_path)
    copy = readme.parent / "results.csv"
    assert copy.read_bytes() == RESULTS.read_bytes()
    assert "[`results.csv`](results.csv)" in readme.read_text(encoding="utf-8")


def test_step_over_solver_ratio_is_reported_per_solver(readme: str) -> None:
    # The fixture's solver time is a fixed share of each step, so the ratio is 1 / share.
    shares = {"CLARABEL": 0.35, "OSQP": 0.2, "PIQP": 0.3, "SCS": 0.4}
    table = table_after(readme, "### Formulation `velocity`")
    assert table, "no velocity time table"
    for cells in table:
        expected = 1.0 / shares[cells[1]]
        assert float(cells[-1]) == pytest.approx(expected, abs=0.006)


def test_each_completed_grid_point_has_its_own_timing_row(readme: str) -> None:
    done = [row for row in fixture_rows()
            if row["status"] == "ok" and row["wall_time_per_step_median"]]
    assert 0 < len(done) <= 60  # the fixture is a small suite: the table is shown
    table = table_after(readme, "### Each grid point")
    assert len(table) == len(done)
    shown = {tuple(cells[:7]): cells for cells in table}  # the fixture has one path
    assert len(shown) == len(done)  # the key tells every grid point apart
    for row in done:
        mass = f"{float(row['table_mass']):.3g}" if row["table_mass"] else "fixed"
        cells = shown[(row["scene"], row["formulation"], row["solver"], row["tol"],
                       f"{float(row['dt']):.3g}", mass,
                       "yes" if row["sleep"] == "true" else "no")]
        assert cells[7] == f"{1e3 * float(row['wall_time_per_step_median']):.3g}"
        if row["step_over_solver_median"]:
            assert cells[9] == f"{float(row['step_over_solver_median']):.2f}"


def test_grid_point_table_names_the_table_mass(readme: str) -> None:
    header = next(line for line in readme.split("### Each grid point", 1)[1].splitlines()
                  if line.startswith("|"))
    assert "| table mass (kg) |" in header
    table = table_after(readme, "### Each grid point")
    heavy = {float(r["table_mass"]) for r in fixture_rows()
             if r["table_mass"] and r["status"] == "ok" and r["wall_time_per_step_median"]}
    assert heavy == {1e6, 1e9}  # the fixture's heavy-table variants
    assert {cells[5] for cells in table} == {"fixed", "1e+06", "1e+09"}


def test_reference_is_named_as_the_same_formulation_at_dt8(readme: str) -> None:
    accuracy = readme.split("## Accuracy", 1)[1].split("##", 1)[0]
    assert "the same formulation at dt/8" in accuracy
    assert "the same scene at dt/8" not in readme  # the old, vaguer wording


def test_a_metrics_csv_is_named_for_what_it_is(tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    from wuerfel_cvx import simulate
    from wuerfel_cvx.cli import main

    saved = simulate("tilted-drop", steps=3).save(tmp_path / "run.npz")
    metrics = saved.with_name("run.metrics.csv")
    assert metrics.is_file()
    assert main(["report", str(metrics), "--root", str(tmp_path / "reports")]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err == (
        f"wuerfel-cvx: error: {metrics}: is a per-step metrics file of one run (from "
        "'simulate --out' or Trajectory.save); 'report' takes a benchmark results CSV "
        "written by 'wuerfel-cvx bench'\n")
    assert not (tmp_path / "reports").exists()


def test_a_results_csv_with_a_wrong_header_still_lists_the_columns(tmp_path: Path) -> None:
    rows = fixture_rows()
    broken = tmp_path / "results.csv"
    with broken.open("w", encoding="utf-8", newline="") as handle:
        fields = [name for name in rows[0] if name != "energy_gain"]
        writer = csv.DictWriter(handle, fieldnames=fields, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
    # the fixture is of schema version 3, so the version-4 to -6 columns are missing too
    with pytest.raises(InputError,
                       match=r"missing \['islands', 'solve_path', 'polish', "
                             r"'reuse_active_sets', 'polished_fraction', 'reused_fraction', "
                             r"'polish_rejected_steps', 'polish_rejections', "
                             r"'max_push_at_distance', 'max_push_gap_product', "
                             r"'call_wall_time_per_step', "
                             r"'call_over_solver_mean', 'search_time_per_step', "
                             r"'build_time_per_step', 'solve_time_per_step', "
                             r"'solver_time_per_step_mean', 'polish_time_per_step', "
                             r"'update_time_per_step', 'record_time_per_step', "
                             r"'outside_steps_time_per_step', 'bare_call_time_per_step', "
                             r"'bare_call_over_solver', 'kkt_factor_time', "
                             r"'max_overlap_depth', 'energy_gain', "
                             r"'friction_model', "):
        write_report(broken, tmp_path / "reports")


# ------------------------------------------------------------------ legends and scales
Drawn = dict[str, Figure]


@pytest.fixture
def drawn(monkeypatch: pytest.MonkeyPatch) -> Drawn:
    """The figures the plot functions would save, by stem (nothing is written)."""
    from wuerfel_cvx.lab.bench import plots_accuracy, plots_cost

    figures: Drawn = {}

    def keep(figure: Figure, out_dir: Path, stem: str) -> list[Path]:
        figures[stem] = figure
        return [out_dir / f"{stem}.png"]

    for module in (plots_accuracy, plots_cost):
        monkeypatch.setattr(module, "save_figure", keep)
    return figures


def legend_texts(figure: Figure) -> list[str]:
    legends = [*figure.legends, *(axis.get_legend() for axis in figure.axes)]
    return [text.get_text() for legend in legends if legend is not None
            for text in legend.get_texts()]


def test_legends_list_only_the_solvers_and_lines_drawn(tmp_path: Path, drawn: Drawn) -> None:
    results = schema.read_results(RESULTS)
    # One tolerance and one dt of the velocity formulation, without the peer engine.
    one = results[(results["formulation"] == "velocity") & (results["tol"] == "default")
                  & (results["dt"] == results["dt"].min())]
    assert plots.plot_pareto(one, tmp_path)
    assert plots.plot_pareto_headline(one, tmp_path)
    shown = {str(s) for s in plots.pareto_points(one)["solver"].unique()}
    for stem in ("pareto", "pareto-headline"):
        texts = legend_texts(drawn[stem])
        assert "across tol presets" not in texts and "across dt" not in texts
        assert "Pareto front" in texts
        assert "PYMUNK" not in texts
        assert {text.split(" ")[0] for text in texts} - {"Pareto"} == shown
    assert plots.plot_pareto(results, tmp_path)  # the whole fixture sweeps both
    texts = legend_texts(drawn["pareto"])
    assert {"across tol presets", "across dt", "Pareto front", "PYMUNK"} <= set(texts)


def test_timing_bars_are_logarithmic_with_peers_only(tmp_path: Path, drawn: Drawn) -> None:
    results = schema.read_results(RESULTS)
    assert plots.plot_timing_breakdown(results, tmp_path)
    axis = drawn["timing-breakdown"].axes[0]
    assert axis.get_yscale() == "log"
    assert "whole step (no split)" in legend_texts(drawn["timing-breakdown"])
    ours = results[results["formulation"] != "peer"]
    assert plots.plot_timing_breakdown(ours, tmp_path)
    axis = drawn["timing-breakdown"].axes[0]
    assert axis.get_yscale() == "linear"
    assert legend_texts(drawn["timing-breakdown"]) == ["solver's own time",
                                                        "modelling (rest of step)"]


def test_solver_time_above_the_step_time_gives_no_modelling_mean(tmp_path: Path) -> None:
    # A solver whose own report exceeds the whole step (Clarabel's clock did, in a busy
    # benchmark worker) leaves a negative modelling time: no mean of it, and the reason.
    rows = fixture_rows()
    target = next(row for row in rows if row["formulation"] == "velocity"
                  and row["solver"] == "OSQP" and row["status"] == "ok")
    wall = float(target["wall_time_per_step_median"])
    target["solver_time_per_step_median"] = repr(2.0 * wall)
    target["modelling_time_per_step_median"] = repr(-wall)
    target["step_over_solver_median"] = "0.5"
    results = tmp_path / "results.csv"
    with results.open("w", encoding="utf-8", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    text = write_report(results, tmp_path / "reports").read_text(encoding="utf-8")
    section = text.split("### Formulation `velocity`", 1)[1].split("###", 1)[0]
    assert "No modelling time for OSQP: on some grid point the solver reported more" in section
    table = {cells[1]: cells for cells in table_after(text, "### Formulation `velocity`")}
    assert table["OSQP"][6] == "–" and table["CLARABEL"][6] != "–"
