"""The perf report's default-run targets: each ratio judged against its limit and its floor."""

from __future__ import annotations

import pandas as pd
import pytest

from wuerfel_cvx.lab.bench.report_stages import verdicts

pytestmark = pytest.mark.unit


def _rows() -> pd.DataFrame:
    """Default-run rows: tilted-drop and stack-20 for CLARABEL and OSQP (times in s)."""
    return pd.DataFrame({
        "scene": ["tilted-drop", "tilted-drop", "stack-20", "stack-20"],
        "solver": ["CLARABEL", "OSQP", "CLARABEL", "OSQP"],
        "call_over_solver_mean": [2.5, 30.0, 4.0, 4.0],
        "bare_call_over_solver": [1.2, 4.0, 1.0, 1.1],
        "call_wall_time_per_step": [1e-3, 1e-3, 4e-4, 1.2e-4],
        "bare_call_time_per_step": [1e-4, 1e-4, 3e-4, 1e-4],
    })


def _results() -> pd.DataFrame:
    """The peer engine's row: MuJoCo's own step, 0.04 ms."""
    return pd.DataFrame({"scene": ["stack-20"], "solver": ["MUJOCO"], "status": ["ok"],
                         "solver_time_per_step_mean": [4e-5]})


def test_a_call_target_is_met_or_not_with_its_floor() -> None:
    tilted = verdicts(_rows(), _results())[0]
    assert tilted.startswith("- tilted-drop: call / solver <= 3:")
    assert "CLARABEL 2.5× (met; bare solver call 1.2×)" in tilted
    # OSQP's bare calls alone (4x) are above the limit (3x): no loop can meet it
    assert "OSQP 30× (**not met**; bare solver call 4×; the limit is below it)" in tilted
    assert "PIQP not measured" in tilted


def test_the_peer_target_is_judged_against_the_bare_calls_time() -> None:
    peer = verdicts(_rows(), _results())[-1]
    assert peer.startswith("- stack-20: call within 5× MUJOCO's step")
    # CLARABEL: 0.4 ms / 0.04 ms = 10x; its bare calls alone take 0.3 ms = 7.5x > 5x
    assert "CLARABEL 10× (**not met**; bare solver call 7.5×; the limit is below it)" in peer
    # OSQP: 0.12 ms = 3x (met); its bare calls 0.1 ms = 2.5x
    assert "OSQP 3× (met; bare solver call 2.5×)" in peer
