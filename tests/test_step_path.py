"""The step path: one contact search per state, a Simulation object, self-describing runs."""

from __future__ import annotations

import dataclasses
import inspect
import os
import signal
from pathlib import Path

import numpy as np
import pytest

from qp_bank import AGREEMENT
from wuerfel_cvx import Scene, simulate
from wuerfel_cvx.errors import Interrupted, StepFailure
from wuerfel_cvx.formulations import StepQP, VelocityFormulation
from wuerfel_cvx.lab.bench.schema import read_results
from wuerfel_cvx.lab.bench.suite import Suite
from wuerfel_cvx.lab.bench.sweep import run_sweep
from wuerfel_cvx.step import contacts as contacts_module
from wuerfel_cvx.step import simulation as simulation_module
from wuerfel_cvx.step.contacts import Contacts, find_contacts
from wuerfel_cvx.step.metrics import deepest_penetration
from wuerfel_cvx.step.model import Model, State
from wuerfel_cvx.step.simulation import Simulation
from wuerfel_cvx.step.sleep import SleepSettings
from wuerfel_cvx.trajectory import Trajectory

pytestmark = pytest.mark.integration

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def count_searches(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """Record every contact search (each runs ``contacts._search`` once) and who asked for it.

    ``"pass"`` for a Gauss-Newton pass whose solution outran the searched reach
    (``VelocityFormulation._reached_contacts``), ``"state"`` for every other search.
    """
    calls: list[str] = []
    search = contacts_module._search

    def counting(*args: object) -> contacts_module.Contacts:
        callers = {frame.function for frame in inspect.stack()[1:8]}
        calls.append("pass" if "_reached_contacts" in callers else "state")
        return search(*args)  # type: ignore[arg-type]

    monkeypatch.setattr(contacts_module, "_search", counting)
    return calls


@pytest.mark.parametrize(("scene", "options"), [
    ("tilted-drop", {}),
    ("rain-20", {"islands": True}),  # 18 searches per step before: one per island and more
    ("stack-5", {"sleep": SleepSettings(time=0.1)}),
    ("tilted-drop", {"formulation": "rigid"}),
    ("tilted-drop", {"formulation": "seed"}),
])
def test_each_step_searches_contacts_once(scene: str, options: dict[str, object],
                                          monkeypatch: pytest.MonkeyPatch) -> None:
    calls = count_searches(monkeypatch)
    steps = 80  # the tilted square lands after about 0.55 s
    trajectory = simulate(scene, dt=0.01, steps=steps, **options)  # type: ignore[arg-type]
    metrics = trajectory.metrics
    asleep = int((metrics["status"] == "asleep").sum())
    # the initial state and each state reached by a step in which something moved
    assert calls.count("state") == 1 + steps - asleep
    # a pass's own search only where its solution outran the reach: at most once per pass
    if not options.get("islands"):  # one QP per step
        assert calls.count("pass") <= int(metrics["passes"].sum())
    assert metrics["n_contacts"].max() > 0


def test_a_sleeping_stack_stops_searching(monkeypatch: pytest.MonkeyPatch) -> None:
    calls = count_searches(monkeypatch)
    trajectory = simulate("stack-5", dt=0.01, steps=60, sleep=SleepSettings(time=0.1))
    asleep = int((trajectory.metrics["status"] == "asleep").sum())
    assert asleep > 30  # the stack is at rest from the start: asleep after 0.1 s
    assert calls == ["state"] * (1 + 60 - asleep)


def test_simulate_is_a_loop_over_the_simulation_object() -> None:
    simulation = Simulation(Scene.named("two-corner-landing"), dt=0.01, solver="OSQP")
    records = [simulation.step() for _ in range(30)]
    stepped = simulation.trajectory()
    looped = simulate("two-corner-landing", dt=0.01, steps=30, solver="OSQP")
    assert np.array_equal(stepped.points, looped.points)
    assert np.array_equal(stepped.velocities, looped.velocities)
    assert [record.step for record in records] == list(range(1, 31))
    assert all(len(record.qps) == len(record.solutions) == 1 for record in records)
    assert stepped.info["steps"] == looped.info["steps"] == 30


def test_the_penetration_from_the_step_contacts_is_the_fresh_search_one() -> None:
    """A row's penetration comes from the next step's search, with that step's reach.

    A search at margin 0 finds the same deepest point.
    """
    trajectory = simulate("overlap-recovery", dt=0.01, steps=40)
    model = trajectory.model()
    assert model is not None
    fresh = [deepest_penetration(model, points) for points in trajectory.points[1:]]
    assert max(fresh) > 1e-3  # the scene starts overlapping: there is something to measure
    assert np.array_equal(trajectory.metrics["penetration_m"].to_numpy(), np.array(fresh))


def test_restricted_contacts_are_those_of_the_subset_model() -> None:
    scene = Scene.named("pyramid-4")
    model, state = Model.from_scene(scene), State.initial(scene)
    reach = VelocityFormulation().body_reach(model, state, 0.01)
    everything = find_contacts(model, state.points, reach)
    boxes = np.array([1, 2, 5, 9])
    corners = (4 * boxes[:, None] + np.arange(4)).ravel()
    subset = model.subset(boxes)
    kept_reach = np.concatenate([reach[boxes], reach[model.n_boxes:]])
    searched = find_contacts(subset, state.points[corners], kept_reach)
    restricted = everything.restricted(boxes, model.n_boxes, model.n_tables)

    def rows(contacts: Contacts) -> set[tuple[int, int, int, float]]:
        return {(int(p), int(i), int(j), float(d)) for p, i, j, d in zip(
            contacts.point, contacts.edge_i, contacts.edge_j, contacts.distance, strict=True)}

    assert len(searched) > 0
    assert rows(restricted) == rows(searched)


def test_a_trajectory_carries_its_scene_and_model_options(tmp_path: Path) -> None:
    scene = Scene.from_toml(EXAMPLES / "tilted-drop.toml")
    trajectory = simulate(scene, dt=0.01, steps=3, formulation="velocity", table_mass=2.0,
                          extra_rod=True)
    loaded = Trajectory.load(trajectory.save(tmp_path / "run"))
    assert loaded.scene == scene
    model = loaded.model()
    assert model is not None and model.table_mass == 2.0
    assert model.rods.shape[0] == 6 * scene.n_boxes  # the sixth rod came back too


def test_a_suite_may_name_its_scene_by_a_toml_path(tmp_path: Path) -> None:
    scene_file = tmp_path / "my scene.toml"
    scene_file.write_text((EXAMPLES / "tilted-drop.toml").read_text())
    suite = Suite.from_dict({"name": "by-path", "defaults": {"duration": 0.05},
                             "grid": [{"scenes": [str(scene_file)], "solvers": ["OSQP"]}]})
    summary = run_sweep(suite, tmp_path / "out", progress=False, echo=lambda _: None)
    row = read_results(summary.results).iloc[0]
    assert row["status"] == "ok", row["error"]
    assert row["n_squares"] == 1
    assert np.isfinite(row["trajectory_error"])  # the dt/8 reference of the file ran too
    assert np.isfinite(row["energy_gain"])


@dataclasses.dataclass(frozen=True)
class InterruptedAt(VelocityFormulation):
    """The velocity formulation, with Ctrl-C pressed while building step ``at``'s QP."""

    at: int = 7
    calls: list[int] = dataclasses.field(default_factory=lambda: [0])

    def build(self, model: Model, state: State, contacts: Contacts, dt: float) -> StepQP:
        """The step QP, or a :class:`KeyboardInterrupt` in step ``at``."""
        self.calls[0] += 1
        if self.calls[0] == self.at:
            raise KeyboardInterrupt
        return super().build(model, state, contacts, dt)


def test_ctrl_c_keeps_the_steps_done_so_far() -> None:
    formulation = InterruptedAt(at=7)
    with pytest.raises(Interrupted) as caught:
        simulate("tilted-drop", dt=0.01, steps=50, formulation=formulation)
    assert isinstance(caught.value, KeyboardInterrupt)  # code that knows only Ctrl-C stops
    assert caught.value.step == 7
    kept = caught.value.trajectory
    assert kept.n_steps == 6 and len(kept.metrics) == 6
    full = simulate("tilted-drop", dt=0.01, steps=6)
    assert np.array_equal(kept.points, full.points)


def test_every_solved_step_records_its_path() -> None:
    trajectory = simulate("stack-3", dt=0.01, steps=5, solver="OSQP")
    assert set(trajectory.metrics["path"]) == {"native"}
    assert trajectory.info["solve_path"] == "native"
    compiled = simulate("stack-3", dt=0.01, steps=3, solver="OSQP", solve_path="compiled")
    assert list(compiled.metrics["path"]) == ["declared", "compiled", "compiled"]
    scs = simulate("stack-3", dt=0.01, steps=2, solver="SCS")
    assert list(scs.metrics["path"]) == ["declared", "compiled"]  # SCS has no adapter


def test_frozen_formulation_options_reach_the_reach() -> None:
    wide = dataclasses.replace(VelocityFormulation(), contact_margin=4.0)
    narrow = simulate("tilted-drop", dt=0.01, steps=1)
    widened = simulate("tilted-drop", dt=0.01, steps=1, formulation=wide)
    assert widened.metrics["n_contacts"].iloc[0] > narrow.metrics["n_contacts"].iloc[0]


def test_a_ctrl_c_that_a_solver_takes_still_stops_the_run(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A Ctrl-C that a solver turns into a failed status still stops the run as interrupted.

    A solver library that checks for signals itself may do that; the run must not then
    report a solver failure.
    """
    real = simulation_module.solve_with_fallback

    def solver_taking_ctrl_c(qp: StepQP, solvers: list[str], tol: str, step: int,
                             cache: object, **options: object) -> object:
        if step == 5:
            try:
                os.kill(os.getpid(), signal.SIGINT)  # the user presses Ctrl-C ...
                signal.pthread_sigmask(signal.SIG_BLOCK, [])  # (let the handler run)
            except KeyboardInterrupt:
                pass  # ... and the solver takes it
            raise StepFailure(step, solvers[0], "solver_error")
        return real(qp, solvers, tol, step, cache, **options)  # type: ignore[arg-type]

    previous = signal.signal(signal.SIGINT, signal.default_int_handler)  # as in a terminal
    try:
        monkeypatch.setattr(simulation_module, "solve_with_fallback", solver_taking_ctrl_c)
        with pytest.raises(Interrupted) as caught:
            simulate("tilted-drop", dt=0.01, steps=20)
    finally:
        signal.signal(signal.SIGINT, previous)
    assert caught.value.step == 5 and caught.value.trajectory.n_steps == 4
    assert signal.getsignal(signal.SIGINT) is previous  # the handler is put back


@pytest.mark.parametrize("solver", ["CLARABEL", "OSQP", "PIQP"])
def test_a_native_run_follows_one_through_cvxpy(solver: str) -> None:
    # rain-8 in the rigid formulation meets new structures (14 in 80 steps) as its squares
    # land: native solvers set up and updated in place, against compiled cvxpy problems.
    steps = 80
    runs = [simulate("rain-8", dt=0.01, steps=steps, solver=solver, formulation="rigid",
                     tol="high", solve_path=path) for path in ("compiled", "native")]
    through_cvxpy, native = runs
    assert through_cvxpy.metrics["verified"].all() and native.metrics["verified"].all()
    assert (native.metrics["path"] == "native").all()
    assert native.info["native_updates"] >= 5
    assert not (through_cvxpy.metrics["path"] == "native").any()
    # each step's velocities within AGREEMENT (m/s; tests/qp_bank.py) of the exact ones
    # move the squares at most dt AGREEMENT farther apart
    bound = steps * 0.01 * AGREEMENT  # m
    assert float(np.max(np.abs(native.points - through_cvxpy.points))) <= bound


@pytest.mark.parametrize("options", [{}, {"friction_model": "coulomb"},
                                     {"sleep": SleepSettings()}],
                         ids=["default", "coulomb", "sleep"])
def test_a_steps_stages_add_up_to_its_wall_time(options: dict[str, object]) -> None:
    """The lap timer gives every interval of a step to one stage.

    The stages' sum is the step's time to round-off; the solver's own time and the polish
    lie within the solve stage.
    """
    scene = "friction-slide" if options.get("friction_model") else "stack-3"
    trajectory = simulate(scene, dt=0.01, steps=60, **options)  # type: ignore[arg-type]
    m = trajectory.metrics
    stages = m[[f"{stage}_time_s" for stage in simulation_module.STAGES]]
    assert (stages.to_numpy() >= 0.0).all()
    np.testing.assert_allclose(stages.sum(axis=1), m["step_time_s"], rtol=1e-12, atol=0.0)
    solved = m[m["status"] != simulation_module.ASLEEP]
    assert len(solved)
    assert (solved["solver_time_s"] + solved["polish_time_s"] <= solved["solve_time_s"]).all()
    if options.get("sleep"):
        assert (m["status"] == simulation_module.ASLEEP).any()
        asleep = m[m["status"] == simulation_module.ASLEEP]
        assert (asleep[["build_time_s", "solve_time_s"]].to_numpy() == 0.0).all()
