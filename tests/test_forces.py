"""Blade-element fin force, fin moment/power, and the body equations (19)-(20).

The references here are independent re-derivations:

* the fin force by numerical blade-element quadrature over the span,
  ``dF = -1/2 lambda rho D_p |v| v ds`` with ``v = s g' n`` (eqs. 7-9, 11 with
  erratum 4), plus the inertial reaction ``-m_p a(S_p/2)`` (eqs. 10, 15);
* the fin moment by quadrature of eq. (14), times ``g'`` for the power;
* the body accelerations from eq. (20) typed in as the paper prints it.

Conventions: x forward, y left, right fin at ``y = -C_p``,
``m = (cos g, -sin g)``, ``n = (-sin g, -cos g)``.
"""

import math

import numpy as np
import pytest
from scipy.integrate import quad

from pectoral_gym.model.averaging import mean_fin_power
from pectoral_gym.model.dynamics import body_accel, body_rhs, fin_angle_eq21, fin_force_right, linearised_rate
from pectoral_gym.model.params import FishParams, body_coefficients, coefficient_vector

P = FishParams()
LAM, RHO, DP, SP, MP = P.fin_force_coef, P.water_density, P.fin_chord, P.fin_span, P.fin_effective_mass


def unit_vectors(g):
    m = np.array([math.cos(g), -math.sin(g)])  # eq. (7)
    n = np.array([-math.sin(g), -math.cos(g)])  # eq. (8)
    return m, n


def blade_element_drag(g, gd, lam=LAM):
    """Hydrodynamic force on the right fin by quadrature of dF over s in [0, S_p] (body x, y)."""
    _, n = unit_vectors(g)

    def df(s, k):
        v = s * gd * n  # eq. (9)
        return (-0.5 * lam * RHO * DP * np.linalg.norm(v) * v)[k]

    return np.array([quad(df, 0.0, SP, args=(k,), epsabs=0, epsrel=1e-12)[0] for k in range(2)])


def joint_force(g, gd, gdd, lam=LAM, mp=MP):
    """Force the right fin exerts on the body: F_hydro - m_p a(S_p/2) (eq. 15), projected (16)-(17)."""
    m, n = unit_vectors(g)
    a_half = 0.5 * SP * (gdd * n - gd**2 * m)  # eq. (10) at s = S_p/2
    return blade_element_drag(g, gd, lam) - mp * a_half


def blade_element_moment(g, gd):
    """z-moment about the pivot of the hydrodynamic force on the right fin, eq. (14), by quadrature."""
    m, n = unit_vectors(g)

    def dm(s):
        v = s * gd * n
        df = -0.5 * LAM * RHO * DP * np.linalg.norm(v) * v
        r = s * m
        return r[0] * df[1] - r[1] * df[0]

    return quad(dm, 0.0, SP, epsabs=0, epsrel=1e-12)[0]


RNG = np.random.default_rng(20240611)
SAMPLES = [
    (float(RNG.uniform(0, math.pi)), float(RNG.uniform(-20, 20)), float(RNG.uniform(-600, 600))) for _ in range(12)
] + [(math.pi / 2, 5.0, 0.0), (math.pi / 2, -5.0, 0.0), (0.3, 0.0, 200.0), (2.5, 3.0, -100.0)]


@pytest.mark.parametrize("g,gd,gdd", SAMPLES)
def test_fin_force_matches_blade_element_quadrature(g, gd, gdd):
    fx, fy = fin_force_right(g, gd, gdd, P.fin_drag_constant, P.fin_inertia_constant)
    ref = joint_force(g, gd, gdd)
    scale = P.fin_drag_constant * gd**2 + P.fin_inertia_constant * (abs(gdd) + gd**2) + 1e-12
    np.testing.assert_allclose([fx, fy], ref, rtol=1e-9, atol=1e-10 * scale)


@pytest.mark.parametrize("g,gd,gdd", SAMPLES[:6])
def test_fin_force_drag_part_alone(g, gd, gdd):
    fx, fy = fin_force_right(g, gd, gdd, P.fin_drag_constant, 0.0)
    np.testing.assert_allclose([fx, fy], blade_element_drag(g, gd), rtol=1e-9, atol=1e-14)


@pytest.mark.parametrize("g,gd,gdd", SAMPLES[:6])
def test_fin_force_inertial_part_alone(g, gd, gdd):
    fx, fy = fin_force_right(g, gd, gdd, 0.0, P.fin_inertia_constant)
    m, n = unit_vectors(g)
    np.testing.assert_allclose([fx, fy], -MP * 0.5 * SP * (gdd * n - gd**2 * m), rtol=1e-12, atol=1e-15)


def test_normal_force_closed_form_constant():
    # |F_n| = integral of 1/2 lambda rho D_p s^2 g'^2 ds = lambda rho D_p S_p^3 g'^2 / 6
    gd = 3.7
    f = blade_element_drag(1.0, gd)
    assert np.linalg.norm(f) == pytest.approx(P.fin_drag_constant * gd**2, rel=1e-10)


def test_power_stroke_pushes_body_forward():
    # Right fin sweeping backward (g' > 0) at g = 90 deg: water pushes the fin (and body) forward, no sideways force.
    fx, fy = fin_force_right(math.pi / 2, 4.0, 0.0, P.fin_drag_constant, 0.0)
    assert fx > 0
    assert fy == pytest.approx(0.0, abs=1e-15)
    # recovery (g' < 0) pulls it back
    fx, _ = fin_force_right(math.pi / 2, -4.0, 0.0, P.fin_drag_constant, 0.0)
    assert fx < 0


def test_fin_angled_back_pushes_right_fin_side_to_the_right():
    # g > 90 deg: the blade faces partly sideways; during the power stroke the water pushes the body to -y (right)
    _, fy = fin_force_right(math.radians(120), 4.0, 0.0, P.fin_drag_constant, 0.0)
    assert fy < 0
    _, fy = fin_force_right(math.radians(60), 4.0, 0.0, P.fin_drag_constant, 0.0)
    assert fy > 0


def test_force_odd_in_rate_for_drag():
    for g, gd, _ in SAMPLES[:5]:
        a = np.array(fin_force_right(g, gd, 0.0, P.fin_drag_constant, 0.0))
        b = np.array(fin_force_right(g, -gd, 0.0, P.fin_drag_constant, 0.0))
        np.testing.assert_allclose(a, -b, rtol=1e-14, atol=1e-300)


# --------------------------------------------------------------------------- moment and power

POWER_PATTERNS = [
    (math.radians(90), math.radians(20), 1.0, 4.0),
    (math.radians(100), math.radians(12), 0.8, 5.0),
    (math.radians(70), math.radians(35), 0.5, 0.5),
    (math.radians(120), math.radians(5), 2.0, 1.0),
]


def test_moment_closed_form_by_quadrature():
    # magnitude lambda rho D_p S_p^4 / 8 g'^2; power M g' >= 0 (the fin always works on the water)
    for g, gd, _ in SAMPLES[:6]:
        mz = blade_element_moment(g, gd)
        assert abs(mz) == pytest.approx(LAM * RHO * DP * SP**4 / 8 * gd**2, rel=1e-10)
        assert mz * gd >= 0


@pytest.mark.parametrize("beat", POWER_PATTERNS)
def test_mean_fin_power_matches_quadrature(beat):
    g0, ga, tp, zeta = beat
    t1 = tp / (zeta + 1.0)

    def power(t):
        g, gd, _ = (float(x[0]) for x in fin_angle_eq21(np.array([t]), *beat))
        return blade_element_moment(g, gd) * gd

    energy = quad(power, 0.0, t1, epsabs=0, epsrel=1e-10)[0] + quad(power, t1, tp, epsabs=0, epsrel=1e-10)[0]
    assert energy > 0
    got = mean_fin_power(ga, tp, zeta, SP, P.fin_drag_constant)
    assert got == pytest.approx(energy / tp, rel=1e-8)


def test_mean_fin_power_equals_drag_work_on_water():
    # Independent of the moment: P = integral over the span of -dF . v = 1/2 lambda rho D_p |v|^3 ds.
    beat = POWER_PATTERNS[0]
    g0, ga, tp, zeta = beat
    t1 = tp / (zeta + 1.0)

    def power(t):
        gd = float(fin_angle_eq21(np.array([t]), *beat)[1][0])
        return quad(lambda s: 0.5 * LAM * RHO * DP * abs(s * gd) ** 3, 0.0, SP, epsabs=0, epsrel=1e-12)[0]

    energy = quad(power, 0.0, t1, epsrel=1e-10)[0] + quad(power, t1, tp, epsrel=1e-10)[0]
    assert mean_fin_power(ga, tp, zeta, SP, P.fin_drag_constant) == pytest.approx(energy / tp, rel=1e-8)


def test_mean_fin_power_zero_without_motion():
    assert mean_fin_power(0.0, 1.0, 4.0, SP, P.fin_drag_constant) == 0.0


# --------------------------------------------------------------------------- body equations (19)-(20)


def eq20(vx, vy, om, fx, fy, tau, p=P):
    """Eqs. (19)-(20) as printed (alpha = arctan(vy/vx), |V| = sqrt(vx^2 + vy^2))."""
    m1 = p.body_mass - p.added_mass_x
    m2 = p.body_mass - p.added_mass_y
    j3 = p.body_inertia - p.added_inertia
    c1 = 0.5 * p.water_density * p.wetted_area * p.drag_coef
    c2 = 0.5 * p.water_density * p.wetted_area * p.lift_coef
    c4 = p.moment_coef / j3
    speed = math.sqrt(vx**2 + vy**2)
    alpha = math.atan(vy / vx)
    f1 = m2 / m1 * vy * om - c1 / m1 * vx * speed + c2 / m1 * vy * speed * alpha
    f2 = -m1 / m2 * vx * om - c1 / m2 * vy * speed - c2 / m2 * vx * speed * alpha
    f3 = (m1 - m2) / j3 * vx * vy - c4 * om**2 * np.sign(om)
    return f1 + fx / m1, f2 + fy / m2, f3 + tau / j3


@pytest.mark.parametrize("seed", range(8))
def test_body_rhs_matches_eq20(seed):
    rng = np.random.default_rng(seed)
    vx, vy, om = rng.uniform(-0.2, 0.2), rng.uniform(-0.1, 0.1), rng.uniform(-1.0, 1.0)
    fx, fy, tau = rng.uniform(-0.05, 0.05, 3) * np.array([1, 1, 0.03])
    got = body_rhs(vx, vy, om, fx, fy, tau, coefficient_vector(P))
    np.testing.assert_allclose(got, eq20(vx, vy, om, fx, fy, tau), rtol=1e-12, atol=1e-15)


def test_body_rhs_at_rest_is_forcing_over_inertia():
    got = body_rhs(0.0, 0.0, 0.0, 0.01, -0.02, 3e-4, coefficient_vector(P))
    np.testing.assert_allclose(got, [0.01 / 0.89, -0.02 / 0.9744, 3e-4 / 4.53e-4], rtol=1e-12)


def test_body_rhs_pure_sway_limit():
    # vx = 0: alpha -> +-pi/2 (limit of arctan(vy/vx) from vx > 0), finite accelerations
    c = coefficient_vector(P)
    got = body_rhs(0.0, 0.05, 0.0, 0.0, 0.0, 0.0, c)
    c1 = 0.5 * 1000 * 0.0325 * 0.387
    c2 = 0.5 * 1000 * 0.0325 * 0.0808
    np.testing.assert_allclose(got, [c2 * 0.05 * 0.05 * math.pi / 2 / 0.89, -c1 * 0.05 * 0.05 / 0.9744, 0.0],
                               rtol=1e-12, atol=1e-15)
    assert all(math.isfinite(x) for x in got)


def test_body_rhs_custom_params():
    q = FishParams(body_mass=1.2, drag_coef=0.5, lift_coef=0.2, moment_coef=1e-2, wetted_area=0.05)
    args = (0.07, -0.02, 0.4, 0.01, 0.002, -1e-4)
    np.testing.assert_allclose(body_rhs(*args, coefficient_vector(q)), eq20(*args, p=q), rtol=1e-12)


def _jacobian(f, v, h=1e-7):
    """Central-difference Jacobian of ``f(vx, vy, om) -> 3 values`` at ``v``."""
    cols = []
    for k in range(3):
        dv = np.zeros(3)
        dv[k] = h
        cols.append((np.array(f(*(v + dv))) - np.array(f(*(v - dv)))) / (2 * h))
    return np.array(cols).T


@pytest.mark.parametrize("params", [P, FishParams(lift_coef=0.6, added_mass_y=-0.6, moment_coef=2e-3)],
                         ids=["table1", "strong-lift-and-munk"])
def test_linearised_rate_bounds_the_eigenvalues_of_eq20(params):
    # The step-size rule must bound every eigenvalue modulus of the Jacobian of eqs. (19)-(20)
    # (central differences of the paper's equations as printed, eq20 above), across speeds,
    # drift angles up to nearly +-90 deg and yaw rates.
    c = body_coefficients(params)
    rng = np.random.default_rng(3)
    for _ in range(300):
        speed, drift, om = rng.uniform(0.01, 0.3), rng.uniform(-1.5, 1.5), rng.uniform(-3.0, 3.0)
        v = np.array([speed * math.cos(drift), speed * math.sin(drift), om])
        jac = _jacobian(lambda a, b, w: eq20(a, b, w, 0.0, 0.0, 0.0, p=params), v)
        largest = np.max(np.abs(np.linalg.eigvals(jac)))
        assert largest <= linearised_rate(speed, om, 0.0, *c)


def test_linearised_rate_is_tight_where_the_yaw_damping_sets_the_step():
    # Table 1, turning on the spot: the largest eigenvalue is the yaw damping 2 c4 |w|; the bound
    # adds only the Coriolis rotation (|w| m1/m2 beside 2 c4 |w| = 38 |w|)
    jac = _jacobian(lambda a, b, w: eq20(a + 1e-12, b, w, 0.0, 0.0, 0.0), np.array([0.0, 0.0, 1.5]))
    largest = np.max(np.abs(np.linalg.eigvals(jac)))
    assert largest == pytest.approx(2 * P.c4 * 1.5, rel=1e-6)
    assert linearised_rate(0.0, 1.5, 0.0, *body_coefficients(P)) <= 1.05 * largest


def test_linearised_rate_bounds_the_oscillation_averaged_yaw_damping():
    c = body_coefficients(P)
    for om in (-0.5, 0.0, 0.05, 0.3, 2.0):
        for amplitude in (0.1, 1.0, 3.0):
            slope = _jacobian(lambda a, b, w, A=amplitude: body_accel(a, b, w, 0.0, 0.0, 0.0, *c, A),
                              np.array([0.0, 0.0, om]))[2, 2]
            assert abs(slope) <= linearised_rate(0.0, om, amplitude, *c) * (1 + 1e-6)  # equal at om = 0
