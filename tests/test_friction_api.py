"""The friction model as an argument: names, formulations that take it, the CLI flag."""

from __future__ import annotations

import pytest

from wuerfel_cvx import simulate
from wuerfel_cvx.cli import main
from wuerfel_cvx.errors import InputError
from wuerfel_cvx.scenes.library import slope_scene

pytestmark = pytest.mark.unit


@pytest.mark.parametrize("model", ["ccp", "coulomb", " CCP "])
@pytest.mark.parametrize("formulation", ["velocity", "velocity-baumgarte", "rigid"])
def test_both_models_run_in_the_formulations_with_friction(model: str,
                                                           formulation: str) -> None:
    run = simulate(slope_scene(), dt=0.01, steps=2, formulation=formulation,
                   friction_model=model)
    assert run.info["friction_model"] == model.strip().lower()
    assert run.metrics["verified"].all()


def test_seed_refuses_a_scene_with_friction_and_the_coulomb_model() -> None:
    with pytest.raises(InputError, match="'seed' formulation has no friction.*scene has"):
        simulate(slope_scene(), steps=1, formulation="seed")
    with pytest.raises(InputError, match="friction_model 'coulomb' needs"):
        simulate("stack-2", steps=1, formulation="seed", friction_model="coulomb")
    assert simulate("stack-2", steps=1, formulation="seed").info["friction_model"] is None


def test_an_unknown_friction_model_names_the_known_ones() -> None:
    with pytest.raises(InputError, match="unknown friction model 'exact'.*ccp, coulomb"):
        simulate(slope_scene(), steps=1, friction_model="exact")


def test_the_cli_flag_takes_the_model_and_rejects_others(
        capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["simulate", "friction-slope", "--steps", "3", "--friction-model",
                 "coulomb", "--no-progress"]) == 0
    assert "friction (coulomb)" in capsys.readouterr().out
    assert main(["simulate", "friction-slope", "--steps", "3", "--friction-model",
                 "exact", "--no-progress"]) == 2
    error = capsys.readouterr().err.strip().splitlines()
    assert len(error) == 1 and "unknown friction model 'exact'" in error[0]
