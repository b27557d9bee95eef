"""Independent checks of every constraint formula in :mod:`wuerfel_cvx.scenes.geometry`.

The reference values never come from the package itself: they come from

* sympy, which differentiates the seed's determinant (eq. 7) and the rod length
  (eq. 5) symbolically, with the points as functions of time, and
* central finite differences along a smooth random trajectory
  ``p(t) = p0 + v0 t + a0 t^2 / 2 + eps sin(w t + phi)``, whose velocity and
  acceleration are known in closed form.

The seed's own formulas (eq. 8, 10, 13/15) are transcribed literally here so the
tests also document where the seed is wrong (see ``docs/seed-errata.md``).

Tolerances: the identities are exact in real arithmetic, so only float64
round-off separates the two sides.  Each side is a short sum (at most 18 products)
of O(1) numbers, so the error is below ~20 machine epsilons (2.2e-16) times the
sum of the absolute values of the terms; ``1e-12`` times that scale leaves a
margin of more than 100 while still catching any wrong coefficient or sign.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pytest
import sympy as sp
from numpy.typing import NDArray

from oracles import penetration_depth
from wuerfel_cvx.scenes.geometry import (
    cross,
    edge_distances,
    edge_parameter,
    polygon_overlap_depth,
    rectangle_corners,
    rot90,
    seed_side_acceleration_collinear,
    side_acceleration,
    side_gradients,
    side_rate,
    side_value,
    side_velocity_product,
    square_corners,
)

pytestmark = pytest.mark.unit

FloatArray = NDArray[np.float64]
Points3 = tuple[FloatArray, FloatArray, FloatArray]

#: Relative tolerance of exact identities in float64 (see the module docstring).
RTOL_EXACT = 1e-12
#: Number of random samples per test.
N_SAMPLES = 200

# --------------------------------------------------------------------------- sympy


_NAMES = ("i", "j", "k")
_T = sp.Symbol("t", real=True)


def _coords(prefix: str) -> list[sp.Symbol]:
    """Symbols ``prefix x_i, prefix y_i, ..., prefix y_k`` in the order i, j, k."""
    return [sp.Symbol(f"{prefix}{axis}_{name}", real=True) for name in _NAMES for axis in "xy"]


P_SYMS = _coords("p")
V_SYMS = _coords("v")
A_SYMS = _coords("a")


def seed_determinant(coords: list[sp.Expr]) -> sp.Expr:
    """Return the seed's eq. (7): ``det [[1, 1, 1], [x_i, x_j, x_k], [y_i, y_j, y_k]]``."""
    xi, yi, xj, yj, xk, yk = coords
    return sp.Matrix([[1, 1, 1], [xi, xj, xk], [yi, yj, yk]]).det()


def _time_derivatives_of_determinant() -> tuple[sp.Expr, sp.Expr, sp.Expr]:
    """Differentiate A(p(t)) twice; return A, dA/dt, d2A/dt2 in p, v, a symbols."""
    funcs = [sp.Function(str(s))(_T) for s in P_SYMS]
    area = seed_determinant(funcs)
    rules: dict[sp.Expr, sp.Expr] = {}
    for f, p, v, a in zip(funcs, P_SYMS, V_SYMS, A_SYMS, strict=True):
        rules[sp.Derivative(f, (_T, 2))] = a
        rules[sp.Derivative(f, _T)] = v
        rules[f] = p
    # xreplace works top-down, so a second derivative is replaced before its inner x(t).
    first = sp.diff(area, _T).xreplace(rules)
    second = sp.diff(area, _T, 2).xreplace(rules)
    return area.xreplace(rules), sp.expand(first), sp.expand(second)


SYM_A, SYM_DA, SYM_DDA = _time_derivatives_of_determinant()
ALL_SYMS = P_SYMS + V_SYMS + A_SYMS


def _lambdify(expr: sp.Expr) -> Callable[..., FloatArray]:
    return sp.lambdify(ALL_SYMS, expr, modules="numpy")  # type: ignore[no-any-return]


NUM_A = _lambdify(SYM_A)
NUM_DA = _lambdify(SYM_DA)
NUM_DDA = _lambdify(SYM_DDA)


# --------------------------------------------------------------------------- samples


@dataclass(frozen=True)
class Triple:
    """Positions, velocities and accelerations of three points, each ``(N, 2)``."""

    p: Points3
    v: Points3
    a: Points3

    def flat_args(self) -> list[FloatArray]:
        """Coordinate columns in the order of ``ALL_SYMS``."""
        return [q[:, c] for group in (self.p, self.v, self.a) for q in group for c in (0, 1)]

    def scale(self) -> FloatArray:
        """Sum of |terms| bound for d2A/dt2: |p|^2 + |p| |a| + |v|^2 per sample, >= 1."""
        pn, vn, an = (
            np.max([np.abs(q).max(axis=1) for q in group], axis=0)
            for group in (self.p, self.v, self.a)
        )
        return np.asarray(1.0 + 12.0 * (pn * pn + pn * an + vn * vn), dtype=np.float64)


def _three(rng: np.random.Generator, n: int, scale: float) -> Points3:
    """Three arrays ``(n, 2)`` uniform in ``[-scale, scale]``."""
    return (
        rng.uniform(-scale, scale, size=(n, 2)),
        rng.uniform(-scale, scale, size=(n, 2)),
        rng.uniform(-scale, scale, size=(n, 2)),
    )


def random_triple(rng: np.random.Generator, n: int = N_SAMPLES) -> Triple:
    """Independent random positions (m), velocities (m/s) and accelerations (m/s^2)."""
    p = _three(rng, n, 2.0)
    v = _three(rng, n, 3.0)
    a = _three(rng, n, 10.0)
    return Triple(p, v, a)


def collinear_triple(
    rng: np.random.Generator, edges: FloatArray | None = None, n: int = N_SAMPLES
) -> tuple[Triple, FloatArray]:
    """Random triples with ``p_k = p_i + alpha (p_j - p_i)`` (so A = 0), and alpha.

    ``edges`` optionally fixes ``p_j - p_i`` (e.g. axis-aligned edges).
    """
    base = random_triple(rng, n)
    p_i, p_j, _ = base.p
    if edges is not None:
        p_j = p_i + edges
    alpha = rng.uniform(-0.5, 1.5, size=n)
    p_k = p_i + alpha[:, None] * (p_j - p_i)
    return Triple((p_i, p_j, p_k), base.v, base.a), alpha


def assert_scaled_close(actual: FloatArray, expected: FloatArray, scale: FloatArray) -> None:
    """``|actual - expected| <= RTOL_EXACT * scale`` elementwise (float64 round-off)."""
    actual = np.asarray(actual, dtype=np.float64)
    expected = np.asarray(expected, dtype=np.float64)
    assert actual.shape == expected.shape
    err = np.abs(actual - expected)
    assert np.all(err <= RTOL_EXACT * scale), f"max scaled error {np.max(err / scale):.3e}"


@pytest.fixture
def rng() -> np.random.Generator:
    """Return a fixed-seed generator so every run sees the same samples."""
    return np.random.default_rng(20240531)


# --------------------------------------------------------------------------- A itself


def test_seed_determinant_is_the_cross_product_form() -> None:
    """Symbolically: det of eq. (7) == (p_j - p_i) x (p_k - p_i) (module docstring)."""
    xi, yi, xj, yj, xk, yk = P_SYMS
    documented = (xj - xi) * (yk - yi) - (yj - yi) * (xk - xi)
    assert sp.expand(seed_determinant(P_SYMS) - documented) == 0


def test_side_value_equals_seed_determinant_exactly_on_integers(rng: np.random.Generator) -> None:
    """On small integers every float64 operation is exact, so equality must be exact."""
    pts = [rng.integers(-1000, 1001, size=(N_SAMPLES, 2)).astype(np.float64) for _ in range(3)]
    args = [q[:, c] for q in pts for c in (0, 1)]
    det = sp.lambdify(P_SYMS, seed_determinant(P_SYMS), modules="numpy")
    np.testing.assert_array_equal(side_value(*pts), det(*args))


def test_side_value_equals_seed_determinant_on_floats(rng: np.random.Generator) -> None:
    t = random_triple(rng)
    assert_scaled_close(side_value(*t.p), NUM_A(*t.flat_args()), t.scale())


def test_side_value_broadcasts_over_leading_axes(rng: np.random.Generator) -> None:
    p_i, p_j = rng.normal(size=(2, 2))
    p_k = rng.normal(size=(5, 3, 2))
    out = side_value(p_i, p_j, p_k)
    assert out.shape == (5, 3)
    assert out[2, 1] == side_value(p_i, p_j, p_k[2, 1])


# --------------------------------------------------------------------------- gradients


def test_side_gradients_equal_sympy_gradient(rng: np.random.Generator) -> None:
    t = random_triple(rng)
    det = seed_determinant(P_SYMS)
    grads = side_gradients(*t.p)
    for point, (gx_sym, gy_sym) in enumerate(zip(P_SYMS[0::2], P_SYMS[1::2], strict=True)):
        for axis, sym in enumerate((gx_sym, gy_sym)):
            expected = _lambdify(sp.diff(det, sym))(*t.flat_args())
            expected = np.broadcast_to(expected, (N_SAMPLES,))
            assert_scaled_close(grads[point][:, axis], expected, t.scale())


def test_side_gradients_sum_to_zero_and_k_gradient_is_normal(rng: np.random.Generator) -> None:
    t = random_triple(rng)
    g_i, g_j, g_k = side_gradients(*t.p)
    assert_scaled_close(np.abs(g_i + g_j + g_k).max(axis=1), np.zeros(N_SAMPLES), t.scale())
    p_i, p_j, _ = t.p
    n = np.stack([-(p_j - p_i)[:, 1], (p_j - p_i)[:, 0]], axis=-1)  # seed eq. (12)
    np.testing.assert_array_equal(g_k, n)


# --------------------------------------------------------------------------- dA/dt


def test_side_rate_equals_sympy_time_derivative(rng: np.random.Generator) -> None:
    t = random_triple(rng)
    assert_scaled_close(side_rate(*t.p, *t.v), NUM_DA(*t.flat_args()), t.scale())


def test_sympy_rate_is_gradient_dot_velocity() -> None:
    """Sanity of the sympy pipeline itself: dA/dt == sum_q dA/dp_q . v_q."""
    det = seed_determinant(P_SYMS)
    chain = sum(sp.diff(det, p) * v for p, v in zip(P_SYMS, V_SYMS, strict=True))
    assert sp.expand(SYM_DA - chain) == 0


@dataclass(frozen=True)
class Trajectory:
    """``p(t) = p0 + v0 t + a0 t^2 / 2 + eps sin(w t + phi)`` for three points."""

    p0: FloatArray
    v0: FloatArray
    a0: FloatArray
    eps: FloatArray
    w: FloatArray
    phi: FloatArray

    @classmethod
    def random(cls, rng: np.random.Generator, n: int = N_SAMPLES) -> Trajectory:
        """Random trajectories for three points: arrays ``(3, n, 2)``."""
        shape = (3, n, 2)
        return cls(
            p0=rng.uniform(-2.0, 2.0, shape),
            v0=rng.uniform(-3.0, 3.0, shape),
            a0=rng.uniform(-10.0, 10.0, shape),
            eps=rng.uniform(0.0, 0.2, shape),
            w=rng.uniform(0.5, 3.0, shape),
            phi=rng.uniform(0.0, 2 * np.pi, shape),
        )

    def position(self, t: float) -> FloatArray:
        """Positions at time ``t`` (s)."""
        return self.p0 + self.v0 * t + self.a0 * t**2 / 2 + self.eps * np.sin(self.w * t + self.phi)

    def velocity(self, t: float) -> FloatArray:
        """Exact velocities at ``t``."""
        return self.v0 + self.a0 * t + self.eps * self.w * np.cos(self.w * t + self.phi)

    def acceleration(self, t: float) -> FloatArray:
        """Exact accelerations at ``t``."""
        return self.a0 - self.eps * self.w**2 * np.sin(self.w * t + self.phi)

    def area(self, t: float) -> FloatArray:
        """A(t) from the sympy-lambdified eq. (7), not from the package."""
        p = self.position(t)
        zeros = [np.zeros(p.shape[1])] * 12
        return np.asarray(NUM_A(*[p[q][:, c] for q in range(3) for c in (0, 1)], *zeros))


def test_side_rate_matches_central_difference(rng: np.random.Generator) -> None:
    traj = Trajectory.random(rng)
    t0, h = 0.37, 1e-4
    fd = (traj.area(t0 + h) - traj.area(t0 - h)) / (2 * h)
    # Truncation h^2/6 |A'''| ~ 1e-7, round-off ~ 1e-16 |A| / h ~ 1e-11.
    rate = side_rate(*traj.position(t0), *traj.velocity(t0))
    np.testing.assert_allclose(rate, fd, rtol=0, atol=1e-5)
    # The check is sharp enough to see a velocity error of 1 %:
    wrong = side_rate(*traj.position(t0), *(1.01 * traj.velocity(t0)))
    assert np.max(np.abs(wrong - fd)) > 1e-3


# --------------------------------------------------------------------------- d2A/dt2


def test_side_acceleration_equals_sympy_second_derivative(rng: np.random.Generator) -> None:
    t = random_triple(rng)
    assert_scaled_close(side_acceleration(*t.p, *t.v, *t.a), NUM_DDA(*t.flat_args()), t.scale())


def test_side_acceleration_exact_on_integers(rng: np.random.Generator) -> None:
    """Integers up to 100 keep every product and sum exact in float64."""

    def ints() -> Points3:
        a, b, c = rng.integers(-100, 101, size=(3, N_SAMPLES, 2)).astype(np.float64)
        return a, b, c

    t = Triple(ints(), ints(), ints())
    np.testing.assert_array_equal(side_acceleration(*t.p, *t.v, *t.a), NUM_DDA(*t.flat_args()))


def test_sympy_velocity_part_has_factor_two() -> None:
    """d2A/dt2 at a = 0 is exactly 2 (v_i x v_j + v_j x v_k + v_k x v_i)."""
    vxi, vyi, vxj, vyj, vxk, vyk = V_SYMS
    cyclic = (vxi * vyj - vyi * vxj) + (vxj * vyk - vyj * vxk) + (vxk * vyi - vyk * vxi)
    velocity_part = SYM_DDA.subs({a: 0 for a in A_SYMS})
    assert sp.expand(velocity_part - 2 * cyclic) == 0
    assert sp.expand(velocity_part - cyclic) != 0


def test_side_velocity_product_matches_sympy(rng: np.random.Generator) -> None:
    t = random_triple(rng)
    z = np.zeros((N_SAMPLES, 2))
    zero = Triple(t.p, t.v, (z, z, z))
    assert_scaled_close(side_velocity_product(*t.v), NUM_DDA(*zero.flat_args()), t.scale())


def test_side_acceleration_hand_example_factor_two() -> None:
    """p_j = (1, t), p_k = (0.5 + t, 0), p_i = 0: A(t) = -t/2 - t^2, so A'' = -2.

    The seed's eq. (13) as printed (no factor 2) gives -1 here.
    """
    p = (np.array([0.0, 0.0]), np.array([1.0, 0.0]), np.array([0.5, 0.0]))
    v = (np.array([0.0, 0.0]), np.array([0.0, 1.0]), np.array([1.0, 0.0]))
    a = (np.zeros(2),) * 3
    assert side_acceleration(*p, *v, *a) == -2.0
    assert seed_side_acceleration_collinear(*p, *v, *a) == -2.0
    assert seed_eq13_as_printed(*p, *v, *a) == -1.0


def test_side_acceleration_matches_second_central_difference(rng: np.random.Generator) -> None:
    traj = Trajectory.random(rng)
    t0, h = -0.21, 1e-3
    fd = (traj.area(t0 + h) - 2 * traj.area(t0) + traj.area(t0 - h)) / h**2
    # Truncation h^2/12 |A''''| ~ 1e-5, round-off ~ 1e-16 |A| / h^2 ~ 1e-9.
    acc = side_acceleration(*traj.position(t0), *traj.velocity(t0), *traj.acceleration(t0))
    np.testing.assert_allclose(acc, fd, rtol=0, atol=1e-3)
    # Without the factor 2 the velocity part is off by v_i x v_j + ... = O(10):
    seed = seed_eq13_general_as_printed(
        *traj.position(t0), *traj.velocity(t0), *traj.acceleration(t0)
    )
    assert np.max(np.abs(seed - fd)) > 1.0


# --------------------------------------------------------------------------- the seed's eq. (13)


def seed_alpha_eq10(p_i: FloatArray, p_j: FloatArray, p_k: FloatArray) -> tuple[FloatArray, ...]:
    """Both ratios of the seed's eq. (10): x-ratio and y-ratio (nan/inf if undefined)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        ax = (p_k[..., 0] - p_i[..., 0]) / (p_j[..., 0] - p_i[..., 0])
        ay = (p_k[..., 1] - p_i[..., 1]) / (p_j[..., 1] - p_i[..., 1])
    return ax, ay


def seed_eq13_as_printed(
    p_i: FloatArray,
    p_j: FloatArray,
    p_k: FloatArray,
    v_i: FloatArray,
    v_j: FloatArray,
    v_k: FloatArray,
    a_i: FloatArray,
    a_j: FloatArray,
    a_k: FloatArray,
) -> FloatArray:
    """Eq. (15) literally (alpha from the x-ratio of eq. 10, velocity terms without 2)."""
    n = np.stack([-p_j[..., 1] + p_i[..., 1], p_j[..., 0] - p_i[..., 0]], axis=-1)  # eq. (12)
    alpha = seed_alpha_eq10(p_i, p_j, p_k)[0]
    return np.asarray(
        a_k[..., 0] * n[..., 0]
        + a_k[..., 1] * n[..., 1]
        + a_j[..., 0] * (-alpha * n[..., 0])
        + a_j[..., 1] * (-alpha * n[..., 1])
        + a_i[..., 0] * (alpha - 1) * n[..., 0]
        + a_i[..., 1] * (alpha - 1) * n[..., 1]
        + v_i[..., 0] * v_j[..., 1]
        - v_j[..., 0] * v_i[..., 1]
        + v_j[..., 0] * v_k[..., 1]
        - v_k[..., 0] * v_j[..., 1]
        + v_k[..., 0] * v_i[..., 1]
        - v_i[..., 0] * v_k[..., 1],
        dtype=np.float64,
    )


def seed_eq13_general_as_printed(
    p_i: FloatArray,
    p_j: FloatArray,
    p_k: FloatArray,
    v_i: FloatArray,
    v_j: FloatArray,
    v_k: FloatArray,
    a_i: FloatArray,
    a_j: FloatArray,
    a_k: FloatArray,
) -> FloatArray:
    """Combine the exact acceleration part with the seed's velocity part (no factor 2)."""
    acc_part = side_acceleration(p_i, p_j, p_k, 0 * v_i, 0 * v_j, 0 * v_k, a_i, a_j, a_k)
    return np.asarray(acc_part + cross(v_i, v_j) + cross(v_j, v_k) + cross(v_k, v_i))


def test_seed_eq13_as_printed_does_not_match_second_derivative(
    rng: np.random.Generator,
) -> None:
    """Erratum: at A = 0 the printed eq. (13) misses exactly v_i x v_j + v_j x v_k + v_k x v_i."""
    t, _ = collinear_triple(rng)
    exact = NUM_DDA(*t.flat_args())
    printed = seed_eq13_as_printed(*t.p, *t.v, *t.a)
    vel = cross(t.v[0], t.v[1]) + cross(t.v[1], t.v[2]) + cross(t.v[2], t.v[0])
    # The x-ratio alpha loses digits when |x_j - x_i| is small: compare with a looser scale.
    loose = t.scale() * (1.0 + 1.0 / np.abs(t.p[1][:, 0] - t.p[0][:, 0]))
    assert_scaled_close(exact - printed, vel, loose)
    assert np.median(np.abs(exact - printed)) > 1.0  # the gap is O(|v|^2), not round-off


def test_seed_collinear_form_equals_exact_on_the_line(rng: np.random.Generator) -> None:
    t, _ = collinear_triple(rng)
    exact = NUM_DDA(*t.flat_args())
    assert_scaled_close(seed_side_acceleration_collinear(*t.p, *t.v, *t.a), exact, t.scale())
    assert_scaled_close(side_acceleration(*t.p, *t.v, *t.a), exact, t.scale())


@pytest.mark.parametrize(
    "direction",
    [(1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0)],
    ids=["right", "left", "up", "down"],
)
def test_seed_collinear_form_on_axis_aligned_edges(
    rng: np.random.Generator, direction: tuple[float, float]
) -> None:
    """Axis-aligned edges, where eq. (10) divides by zero, still give the exact value."""
    lengths = rng.uniform(0.1, 2.0, size=(N_SAMPLES, 1))
    t, _ = collinear_triple(rng, edges=lengths * np.array(direction))
    ax, ay = seed_alpha_eq10(*t.p)
    assert not np.any(np.isfinite(ax) & np.isfinite(ay))  # eq. (10) is undefined everywhere
    got = seed_side_acceleration_collinear(*t.p, *t.v, *t.a)
    assert np.all(np.isfinite(got))
    assert_scaled_close(got, NUM_DDA(*t.flat_args()), t.scale())


def test_seed_collinear_form_is_off_by_A_times_edge_term(rng: np.random.Generator) -> None:
    """Off the line the collinear form is wrong by (A / |e|^2) <a_j - a_i, e>, e = p_j - p_i.

    Writing p_k - p_i = alpha e + beta rot90(e) gives beta = A / |e|^2 and the exact
    acceleration part minus the collinear one = beta <a_j - a_i, e>.
    """
    t = random_triple(rng)
    p_i, p_j, p_k = t.p
    e = p_j - p_i
    e2 = np.sum(e * e, axis=1)
    area = side_value(p_i, p_j, p_k)
    exact = NUM_DDA(*t.flat_args())
    collinear = seed_side_acceleration_collinear(*t.p, *t.v, *t.a)
    predicted_gap = area / e2 * np.sum((t.a[1] - t.a[0]) * e, axis=1)
    scale = t.scale() * (1.0 + np.abs(area) / e2 + 1.0 / e2)
    assert_scaled_close(exact - collinear, predicted_gap, scale)
    off = np.abs(area) > 0.1
    assert off.sum() > N_SAMPLES // 2
    assert np.median(np.abs(exact - collinear)[off]) > 0.1  # genuinely different


# --------------------------------------------------------------------------- dA/dt at A = 0 (eq. 8)


def test_seed_eq8_rate_form_misses_the_i_term(rng: np.random.Generator) -> None:
    """At A = 0, dA/dt = <v_k, n> - alpha <v_j, n> - (1 - alpha) <v_i, n>.

    The seed's eq. (8)/(9) compares only <v_k, n> with alpha <v_j, n>; that drops
    (1 - alpha) <v_i, n> and is right only when p_i does not move along n.
    """
    t, alpha = collinear_triple(rng)
    p_i, p_j, _ = t.p
    v_i, v_j, v_k = t.v
    n = rot90(p_j - p_i)

    def dot(u: FloatArray, w: FloatArray) -> FloatArray:
        return np.asarray(np.sum(u * w, axis=1))

    full = dot(v_k, n) - alpha * dot(v_j, n) - (1 - alpha) * dot(v_i, n)
    exact = NUM_DA(*t.flat_args())
    assert_scaled_close(full, exact, t.scale())
    assert_scaled_close(side_rate(*t.p, *t.v), exact, t.scale())
    seed = dot(v_k, n) - alpha * dot(v_j, n)
    sign_disagrees = np.sign(seed) != np.sign(exact)
    assert sign_disagrees.any()  # eq. (8) misclassifies approaching points


# --------------------------------------------------------------------------- alpha (eq. 10)


def test_edge_parameter_equals_seed_eq10_when_defined(rng: np.random.Generator) -> None:
    t, alpha = collinear_triple(rng)
    ax, ay = seed_alpha_eq10(*t.p)
    got = edge_parameter(*t.p)
    # Condition of the ratio ~ 1 / |difference|: scale the tolerance with it.
    dx = np.abs(t.p[1][:, 0] - t.p[0][:, 0])
    dy = np.abs(t.p[1][:, 1] - t.p[0][:, 1])
    np.testing.assert_array_less(np.abs(got - alpha), 1e-12 * (1 + 1 / np.hypot(dx, dy)))
    np.testing.assert_array_less(np.abs(got - ax), 1e-12 * (1 + 1 / dx))
    np.testing.assert_array_less(np.abs(got - ay), 1e-12 * (1 + 1 / dy))


def test_edge_parameter_on_axis_aligned_edges() -> None:
    p_i = np.array([[0.0, 0.0], [2.0, 1.0], [3.0, 3.0], [0.0, 0.0]])
    p_j = np.array([[1.0, 0.0], [2.0, 3.0], [1.0, 3.0], [0.0, -4.0]])
    p_k = np.array([[0.25, 0.0], [2.0, 2.5], [3.5, 3.0], [0.0, -1.0]])
    got = edge_parameter(p_i, p_j, p_k)
    np.testing.assert_allclose(got, [0.25, 0.75, -0.25, 0.25], rtol=0, atol=1e-15)
    ax, ay = seed_alpha_eq10(p_i, p_j, p_k)
    assert not np.all(np.isfinite(ax)) and not np.all(np.isfinite(ay))


def test_edge_parameter_is_the_projection_off_the_line() -> None:
    """A point 3 m beside the edge projects to the same alpha as its foot point."""
    p_i, p_j = np.array([1.0, 1.0]), np.array([3.0, 1.0])
    assert edge_parameter(p_i, p_j, np.array([1.5, 4.0])) == 0.25
    assert edge_parameter(p_i, p_j, np.array([1.5, -4.0])) == 0.25


# --------------------------------------------------------------------------- rods (eq. 5/6)


def test_rod_second_derivative_is_seed_eq6() -> None:
    """d2/dt2 of |p_i - p_j|^2 / 2 == <a_i - a_j, p_i - p_j> + |v_i - v_j|^2."""
    fx_i, fy_i, fx_j, fy_j = (sp.Function(n)(_T) for n in ("xi", "yi", "xj", "yj"))
    half_sq = ((fx_i - fx_j) ** 2 + (fy_i - fy_j) ** 2) / 2
    second = sp.diff(half_sq, _T, 2)
    pxi, pyi, pxj, pyj = sp.symbols("pxi pyi pxj pyj", real=True)
    vxi, vyi, vxj, vyj = sp.symbols("vxi vyi vxj vyj", real=True)
    axi, ayi, axj, ayj = sp.symbols("axi ayi axj ayj", real=True)
    rules: dict[sp.Expr, sp.Expr] = {}
    for f, p, v, a in zip(
        (fx_i, fy_i, fx_j, fy_j),
        (pxi, pyi, pxj, pyj),
        (vxi, vyi, vxj, vyj),
        (axi, ayi, axj, ayj),
        strict=True,
    ):
        rules[sp.Derivative(f, (_T, 2))] = a
        rules[sp.Derivative(f, _T)] = v
        rules[f] = p
    eq6 = (
        (axi - axj) * (pxi - pxj) + (ayi - ayj) * (pyi - pyj) + (vxi - vxj) ** 2 + (vyi - vyj) ** 2
    )
    assert sp.expand(second.xreplace(rules) - eq6) == 0
    # Eq. (6) is the second derivative of eq. (5) up to the factor 2, not of eq. (5) itself:
    assert sp.expand(sp.diff(2 * half_sq, _T, 2).xreplace(rules) - eq6) != 0


def test_rod_eq6_matches_central_difference(rng: np.random.Generator) -> None:
    traj = Trajectory.random(rng)
    t0, h = 0.8, 1e-3

    def half_sq(t: float) -> FloatArray:
        d = traj.position(t)[0] - traj.position(t)[1]
        return np.asarray(0.5 * np.sum(d * d, axis=1))

    fd = (half_sq(t0 + h) - 2 * half_sq(t0) + half_sq(t0 - h)) / h**2
    p, v, a = traj.position(t0), traj.velocity(t0), traj.acceleration(t0)
    eq6 = np.sum((a[0] - a[1]) * (p[0] - p[1]), axis=1) + np.sum((v[0] - v[1]) ** 2, axis=1)
    np.testing.assert_allclose(eq6, fd, rtol=0, atol=1e-3)


# --------------------------------------------------------------------------- sign convention


UNIT_SQUARE = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
#: Outward unit normals of the unit square's counter-clockwise edges e -> e + 1.
UNIT_SQUARE_OUTWARD = np.array([[0.0, -1.0], [1.0, 0.0], [0.0, 1.0], [-1.0, 0.0]])


def _shoelace(polygon: FloatArray) -> float:
    x, y = polygon[:, 0], polygon[:, 1]
    return float(0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


@pytest.mark.parametrize("edge", range(4))
def test_contact_edge_sign_convention_unit_square(edge: int) -> None:
    """Contact order (i, j) = (corner e + 1, corner e): A > 0 outside, < 0 inside."""
    assert _shoelace(UNIT_SQUARE) == 1.0  # counter-clockwise
    p_i, p_j = UNIT_SQUARE[(edge + 1) % 4], UNIT_SQUARE[edge]
    mid = (p_i + p_j) / 2
    outward = UNIT_SQUARE_OUTWARD[edge]
    assert side_value(p_i, p_j, mid + 0.5 * outward) == 0.5  # A / |e| = distance, |e| = 1
    assert side_value(p_i, p_j, mid - 0.25 * outward) == -0.25
    assert side_value(p_i, p_j, np.array([0.5, 0.5])) == -0.5  # the centre
    assert side_value(p_i, p_j, mid) == 0.0
    n = rot90(p_j - p_i)
    np.testing.assert_array_equal(n, outward)
    np.testing.assert_array_equal(side_gradients(p_i, p_j, mid)[2], outward)
    # The counter-clockwise order gives the opposite sign (the trap in the seed):
    assert side_value(p_j, p_i, mid + 0.5 * outward) == -0.5


def test_rot90_and_cross_conventions() -> None:
    np.testing.assert_array_equal(rot90(np.array([1.0, 0.0])), [0.0, 1.0])
    np.testing.assert_array_equal(rot90(np.array([0.0, 1.0])), [-1.0, 0.0])
    assert cross(np.array([1.0, 0.0]), np.array([0.0, 1.0])) == 1.0
    assert cross(np.array([2.0, 3.0]), np.array([5.0, 7.0])) == 2 * 7 - 3 * 5


@pytest.mark.parametrize("angle", [0.0, 0.3, -1.2, np.pi / 4, np.pi])
def test_square_corners_counter_clockwise(angle: float) -> None:
    corners = square_corners((1.5, -0.5), 2.0, angle)
    assert _shoelace(corners) == pytest.approx(4.0, rel=1e-14)
    np.testing.assert_allclose(corners.mean(axis=0), [1.5, -0.5], atol=1e-14)
    sides = np.linalg.norm(np.roll(corners, -1, axis=0) - corners, axis=1)
    np.testing.assert_allclose(sides, 2.0, rtol=1e-14)
    rect = rectangle_corners((0.0, 0.0), 3.0, 1.0, angle)
    assert _shoelace(rect) == pytest.approx(3.0, rel=1e-14)


def test_edge_distances_point_inside_unit_square() -> None:
    d = edge_distances(np.array([[0.5, 0.25]]), UNIT_SQUARE)
    np.testing.assert_allclose(d, [[-0.25, -0.5, -0.75, -0.5]], rtol=0, atol=1e-15)
    np.testing.assert_allclose(penetration_depth(np.array([[0.5, 0.25]]), UNIT_SQUARE), [0.25])


def test_edge_distances_and_depth_outside_and_on_boundary() -> None:
    pts = np.array([[0.5, -0.1], [1.3, 0.5], [2.0, 2.0], [0.0, 0.5]])
    d = edge_distances(pts, UNIT_SQUARE)
    np.testing.assert_allclose(d[0], [0.1, -0.5, -1.1, -0.5], atol=1e-15)
    np.testing.assert_allclose(d[1], [-0.5, 0.3, -0.5, -1.3], atol=1e-15)
    np.testing.assert_array_equal(penetration_depth(pts, UNIT_SQUARE), [0.0, 0.0, 0.0, 0.0])


def test_edge_distances_match_outward_normal_projection(rng: np.random.Generator) -> None:
    """On a rotated, scaled square: distance = <p - m_e, unit outward normal of edge e>."""
    poly = square_corners((0.3, -2.0), 1.7, 0.9)
    pts = rng.uniform(-3.0, 3.0, size=(N_SAMPLES, 2))
    head = np.roll(poly, -1, axis=0)
    mids = (poly + head) / 2
    rotation_cw = np.array([[0.0, 1.0], [-1.0, 0.0]])  # (x, y) -> (y, -x)
    outward = (head - poly) @ rotation_cw.T
    outward /= np.linalg.norm(outward, axis=1, keepdims=True)
    assert np.all(np.sum((mids - poly.mean(axis=0)) * outward, axis=1) > 0)
    expected = np.einsum("pec,ec->pe", pts[:, None, :] - mids[None], outward)
    np.testing.assert_allclose(edge_distances(pts, poly), expected, rtol=0, atol=1e-13)
    inside = np.all(expected < 0, axis=1)
    depth = np.where(inside, -np.max(expected, axis=1), 0.0)
    np.testing.assert_allclose(penetration_depth(pts, poly), depth, rtol=0, atol=1e-13)


@pytest.mark.parametrize(
    ("shift", "depth"),
    [
        ((0.75, 0.0), 0.25),  # overlap 0.25 m along x
        ((0.75, 0.1), 0.25),  # 0.25 along x beats 0.9 along y
        ((0.2, -0.9), 0.1),  # 0.1 along y
        ((1.0, 0.0), 0.0),  # touching
        ((1.5, 0.3), 0.0),  # separated
        ((0.0, 0.0), 1.0),  # coincident
    ],
)
def test_polygon_overlap_depth_unit_squares(shift: tuple[float, float], depth: float) -> None:
    other = UNIT_SQUARE + np.array(shift)
    assert polygon_overlap_depth(UNIT_SQUARE, other) == pytest.approx(depth, abs=1e-14)
    assert polygon_overlap_depth(other, UNIT_SQUARE) == pytest.approx(depth, abs=1e-14)


def test_polygon_overlap_depth_corner_first() -> None:
    """A unit square at 45 degrees, centre 0.6 m above a floor: depth sqrt(2)/2 - 0.6."""
    floor = rectangle_corners((0.0, -0.5), 10.0, 1.0, 0.0)
    diamond = square_corners((0.0, 0.6), 1.0, np.pi / 4)
    assert polygon_overlap_depth(diamond, floor) == pytest.approx(np.sqrt(0.5) - 0.6, abs=1e-14)
    # Lifted so that its lowest corner is 0.043 m above the floor: separated.
    lifted = square_corners((0.0, 0.75), 1.0, np.pi / 4)
    assert polygon_overlap_depth(lifted, floor) == 0.0
