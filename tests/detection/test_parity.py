"""Parity space of redundant sensor sets (detection.parity) and the sensor arrangement by
gradient (detection.sensor_configuration).

References: SciPy's null space and subspace angles, the cross products of plane normals
for 2-D fault planes in a 3-D parity space, Table 1 of Park et al. (2004) as printed in the
spec, the chi-square law of the fault-free statistic (binomial interval of its false-alarm
count), an independent NumPy Monte Carlo of the missed-isolation probability.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg
import scipy.stats

from jaxfdi.detection import _parity as ps
from jaxfdi.detection import _sensor_configuration as sc
from jaxfdi.models.f16._plant import skewed_rate_axes

GROUPS = np.arange(6).reshape(3, 2)
SIGMA = 0.01
# compiled once: eager, each of their dozens of small operations would be compiled on its own
ISOLABILITY = jax.jit(sc.isolability)
CALIBRATE = jax.jit(ps.isolation_threshold, static_argnums=6)


@pytest.fixture(scope="module")
def spec():
    return ps.parity_space(skewed_rate_axes(), GROUPS)


def _random_sets():
    rng = np.random.default_rng(4)
    return [
        (rng.standard_normal((9, 3)), np.arange(9).reshape(3, 3)),  # three 3-axis sensors
        (rng.standard_normal((7, 4)), np.arange(7)[:, None]),  # seven single channels, 4 states
        (rng.standard_normal((8, 3)), np.arange(8).reshape(4, 2)),
    ]  # four 2-DOF sensors


@pytest.mark.parametrize("case", range(4))
def test_v_is_an_orthonormal_left_null_space(spec, case):
    """V H = 0, V V^T = I, and V^T V is SciPy's projector onto the left null space."""
    space = spec if case == 0 else ps.parity_space(*_random_sets()[case - 1])
    H, V = np.asarray(space.H), np.asarray(space.V)
    assert V.shape == (H.shape[0] - H.shape[1], H.shape[0])
    np.testing.assert_allclose(V @ H, 0.0, atol=1e-12)
    np.testing.assert_allclose(V @ V.T, np.eye(V.shape[0]), atol=1e-12)
    null = scipy.linalg.null_space(H.T)
    np.testing.assert_allclose(V.T @ V, null @ null.T, atol=1e-12)
    # each fault basis is orthonormal and spans the group's columns of V
    for g, group in enumerate(np.asarray(space.groups)):
        Q = np.asarray(space.fault_bases[g])
        np.testing.assert_allclose(Q.T @ Q, np.eye(Q.shape[1]), atol=1e-12)
        np.testing.assert_allclose(Q @ Q.T @ V[:, group], V[:, group], atol=1e-12)


def test_isolation_functions_equal_the_plane_normal_formula(spec):
    """FI_k = 1 - |p . u_k| / ||p|| (Park et al. 2004) with u_k the unit normal of FP_k (the cross
    product of V's two columns of sensor k); the singular direction of two planes is the
    cross product of their normals; the principal angles equal SciPy's."""
    V = np.asarray(spec.V)
    normals = np.stack([np.cross(V[:, 2 * k], V[:, 2 * k + 1]) for k in range(3)])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    p = np.random.default_rng(1).standard_normal((50, 3))
    expected = 1.0 - np.abs(p @ normals.T) / np.linalg.norm(p, axis=1, keepdims=True)
    np.testing.assert_allclose(ps.isolation_functions(spec, p), expected, atol=1e-13)
    assert float(ps.isolation_functions(spec, jnp.zeros(3))[0]) == 0.0
    dirs = np.asarray(ps.singular_directions(spec).direction)
    for i in range(3):
        for k in range(3):
            if i != k:
                line = np.cross(normals[i], normals[k])
                assert abs(abs(dirs[i, k] @ line) / np.linalg.norm(line) - 1.0) < 1e-12
    angles = np.asarray(ps.subspace_angles(spec))
    Q = np.asarray(spec.fault_bases)
    for i, k in ((0, 1), (0, 2), (1, 2)):
        np.testing.assert_allclose(
            angles[i, k], np.sort(scipy.linalg.subspace_angles(Q[i], Q[k])), atol=1e-12
        )
    space = ps.parity_space(*_random_sets()[0])
    Q = np.asarray(space.fault_bases)
    np.testing.assert_allclose(
        np.asarray(ps.subspace_angles(space))[0, 2],
        np.sort(scipy.linalg.subspace_angles(Q[0], Q[2])),
        atol=1e-12,
    )


TABLE_1 = [  # (fault type, sensors that cannot be told apart, fault vectors of each, rate affected)
    (1, (0, 1), ([1, -1], [-1, 1]), 0),
    (2, (0, 2), ([1, 1], [-1, 1]), 1),
    (3, (1, 2), ([1, 1], [1, 1]), 2),
]
MAGNITUDES = [1e-6, 1e-3, 0.1, 1.0, 37.0, 1e4, -0.5, -1e3]


@pytest.mark.parametrize("fault_type,pair,vectors,rate", TABLE_1)
def test_table_1(spec, fault_type, pair, vectors, rate):
    """Each fault type is indistinguishable between exactly its two sensors, for every
    magnitude: FI = 1 for both, FI = 0 for the third (noise-free), on the singular line
    the library finds for the pair; the rate it corrupts is Table 1's."""
    H = np.asarray(spec.H)
    other = ({0, 1, 2} - set(pair)).pop()
    for sensor, f in zip(pair, vectors):
        for a in MAGNITUDES:
            m = np.zeros(6)
            m[list(GROUPS[sensor])] = a * np.asarray(f, float)
            fi = np.asarray(ps.isolation_functions(spec, ps.parity_vector(spec, m)))
            np.testing.assert_allclose(fi[list(pair)], 1.0, atol=1e-12)
            assert abs(fi[other]) < 1e-12
            assert fi[other] < 0.5  # far from any isolation threshold: exactly two suspects
        rates = H[GROUPS[sensor]].T @ np.asarray(f, float)
        assert np.argmax(np.abs(rates)) == rate and np.sum(np.abs(rates) > 1e-12) == 1
    faults = np.asarray(ps.singular_faults(spec))
    for sensor, f in zip(pair, vectors):
        k = pair[1] if sensor == pair[0] else pair[0]
        assert abs(abs(faults[sensor, k] @ np.asarray(f, float)) / np.linalg.norm(f) - 1.0) < 1e-12
    angles = np.degrees(np.asarray(ps.subspace_angles(spec)))[pair[0], pair[1]]
    np.testing.assert_allclose(
        angles, [0.0, 90.0], atol=1e-9
    )  # a shared line, and orthogonal planes


def test_fd_false_alarm_rate_within_its_binomial_interval(spec):
    """Fault-free, FD / sigma^2 ~ chi2(3): at P_fa = 0.01 the alarms of 2e5 samples lie in
    the 99.9 % binomial interval, and the statistic passes a KS test against chi2(3)."""
    n, pfa = 200_000, 0.01
    noise = SIGMA * jax.random.normal(jax.random.key(0), (n, 6))
    fd = ps.fault_detection_statistic(ps.parity_vector(spec, noise))
    threshold = ps.detection_threshold(spec, SIGMA, pfa)
    np.testing.assert_allclose(threshold / SIGMA**2, scipy.stats.chi2.isf(pfa, 3), rtol=1e-12)
    alarms = int(jnp.sum(fd > threshold))
    low, high = scipy.stats.binom.interval(0.999, n, pfa)
    assert low <= alarms <= high, (alarms, low, high)
    assert (
        scipy.stats.kstest(np.asarray(fd[:20_000]) / SIGMA**2, scipy.stats.chi2(3).cdf).pvalue
        > 1e-3
    )


def test_isolation_threshold_meets_its_missed_isolation_probability(spec):
    """T_I from 1e5 draws at FNR 10 and P_MI = 0.01; an independent NumPy Monte Carlo
    (its own draws and its own FI, by the normals) finds the faulty sensor's FI <= T_I in
    a fraction inside the 99.9 % binomial interval of 0.01; T_I is close to the
    small-noise value 1 - z_{0.995} / FNR."""
    t_d = ps.detection_threshold(spec, SIGMA, 1e-6)
    cal = CALIBRATE(spec, SIGMA, 10.0, 0.01, t_d, jax.random.key(3), 100_000)
    assert float(cal.missed_isolation) <= 0.01 and int(cal.detected) > 99_000
    assert abs(float(cal.threshold) - (1 - scipy.stats.norm.isf(0.005) / 10.0)) < 0.01
    rng = np.random.default_rng(11)
    n = 100_000
    V = np.asarray(spec.V)
    normals = np.stack([np.cross(V[:, 2 * k], V[:, 2 * k + 1]) for k in range(3)])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    sensor = rng.integers(0, 3, n)
    angle = rng.uniform(0, 2 * np.pi, n)
    m = SIGMA * rng.standard_normal((n, 6))
    size = 10.0 * SIGMA * np.sqrt(2.0)
    m[np.arange(n), 2 * sensor] += size * np.cos(angle)
    m[np.arange(n), 2 * sensor + 1] += size * np.sin(angle)
    p = m @ V.T
    detected = np.sum(p * p, axis=1) > float(t_d)
    fi = 1.0 - np.abs(np.sum(p * normals[sensor], axis=1)) / np.linalg.norm(p, axis=1)
    missed = int(np.sum(detected & (fi <= float(cal.threshold))))
    low, high = scipy.stats.binom.interval(0.999, int(detected.sum()), 0.01)
    assert low <= missed <= high, (missed, low, high)


def test_transformations_and_bad_input(spec):
    p = jax.random.normal(jax.random.key(2), (5, 3))
    np.testing.assert_allclose(
        jax.jit(ps.isolation_functions)(spec, p), ps.isolation_functions(spec, p), atol=1e-15
    )
    spaces = jax.vmap(lambda H: ps.parity_space(H, GROUPS))(
        jnp.stack([skewed_rate_axes(), -skewed_rate_axes()])
    )
    np.testing.assert_allclose(jnp.einsum("sqm,smn->sqn", spaces.V, spaces.H), 0.0, atol=1e-12)
    with pytest.raises(ValueError, match="H: expected more channels"):
        ps.parity_space(np.eye(3))
    with pytest.raises(ValueError, match="H: expected full column rank"):
        ps.parity_space(np.ones((5, 2)))
    with pytest.raises(ValueError, match="groups: expected every channel in at most one group"):
        ps.parity_space(skewed_rate_axes(), [[0, 1], [1, 2]])
    with pytest.raises(ValueError, match="groups: expected at most q = m - n = 1 channels"):
        ps.parity_space(
            np.vstack([np.eye(3), [[1.0, 1.0, 1.0]]]), [[0, 1], [2, 3]]
        )  # q = 1 < d = 2
    with pytest.raises(ValueError, match="groups: the fault subspace of group 0"):
        ps.parity_space(
            np.vstack([np.eye(3), np.eye(3)[:2]]), [[2], [0]]
        )  # channel 2 alone measures z
    with pytest.raises(ValueError, match="groups: expected"):
        ps.parity_space(skewed_rate_axes(), [[0, 9]])
    with pytest.raises(ValueError, match="missed_isolation"):
        ps.isolation_threshold(spec, SIGMA, 10.0, 1.5, 1.0, jax.random.key(0), 10)


def test_sensor_arrangement_geometry_and_optimiser(spec):
    """The projector-based isolability (differentiable, no SVD of H) equals the parity
    space's principal angles on random arrangements; the paper's arrangement has the
    largest possible smallest dihedral angle (90 deg) and detectability (0.5), which Adam
    approaches from random starts; quaternion axes are orthonormal pairs."""
    rng = np.random.default_rng(5)
    for _ in range(3):
        q = rng.standard_normal((3, 4))
        H = sc.sensor_axes(jnp.asarray(q))
        pairs = np.asarray(H).reshape(3, 2, 3)
        np.testing.assert_allclose(
            np.einsum("sij,skj->sik", pairs, pairs),
            np.broadcast_to(np.eye(2), (3, 2, 2)),
            atol=1e-12,
        )
        iso = ISOLABILITY(H, GROUPS)
        angles = np.asarray(ps.subspace_angles(ps.parity_space(H, GROUPS)))[..., 1]
        np.testing.assert_allclose(np.asarray(iso.dihedral), angles * (1 - np.eye(3)), atol=1e-9)
        gram = np.asarray(ps.parity_space(H, GROUPS).V)
        np.testing.assert_allclose(
            iso.detectability,
            [np.linalg.eigvalsh(gram[:, g].T @ gram[:, g])[0] for g in GROUPS],
            atol=1e-12,
        )
    iso = ISOLABILITY(spec.H, GROUPS)
    assert abs(np.degrees(float(iso.min_dihedral)) - 90.0) < 1e-9
    np.testing.assert_allclose(iso.detectability, 0.5, atol=1e-12)
    assert float(iso.isotropy) < 1e-12
    result = sc.optimize_configuration(
        jax.random.key(1), starts=2, steps=150, objective="separation"
    )
    best = ISOLABILITY(result.axes[result.best], GROUPS)
    assert np.all(np.asarray(result.objective[:, -1]) > np.asarray(result.objective[:, 0]))
    assert np.degrees(float(best.min_dihedral)) > 85.0 and float(np.min(best.detectability)) > 0.45
