"""``jaxfdi.rotation``: the one quaternion algebra of the INS and the spacecraft
(Hamilton product, scalar first)."""

import jax.numpy as jnp
import numpy as np

from jaxfdi import rotation


def _unit(v):
    return v / np.linalg.norm(v)


def test_hamilton_product_scalar_first_in_vector_form():
    rng = np.random.default_rng(1)
    for _ in range(20):
        p, q = rng.normal(size=4), rng.normal(size=4)
        vector_form = np.concatenate(
            [[p[0] * q[0] - p[1:] @ q[1:]], p[0] * q[1:] + q[0] * p[1:] + np.cross(p[1:], q[1:])]
        )
        np.testing.assert_allclose(
            rotation.quaternion_multiply(jnp.asarray(p), jnp.asarray(q)),
            vector_form,
            rtol=1e-14,
            atol=1e-14,
        )
        conjugate = np.asarray(rotation.quaternion_conjugate(jnp.asarray(q)))
        np.testing.assert_array_equal(conjugate, q * np.array([1.0, -1.0, -1.0, -1.0]))
        np.testing.assert_allclose(
            rotation.quaternion_multiply(jnp.asarray(q), jnp.asarray(conjugate)),
            [q @ q, 0.0, 0.0, 0.0],
            atol=1e-14,
        )


def test_rotate_is_the_sandwich_product_and_the_dcm():
    rng = np.random.default_rng(2)
    for _ in range(20):
        q, v = jnp.asarray(_unit(rng.normal(size=4))), jnp.asarray(rng.normal(size=3))
        v_quaternion = jnp.concatenate([jnp.zeros(1), v])
        sandwich = rotation.quaternion_multiply(
            rotation.quaternion_multiply(q, v_quaternion), rotation.quaternion_conjugate(q)
        )
        np.testing.assert_allclose(rotation.rotate(q, v), sandwich[1:], rtol=1e-13, atol=1e-14)
        np.testing.assert_allclose(
            rotation.rotate(q, v), rotation.quaternion_to_dcm(q) @ v, rtol=1e-13, atol=1e-14
        )


def test_skew_is_the_cross_product():
    rng = np.random.default_rng(3)
    v, a = rng.normal(size=3), rng.normal(size=3)
    np.testing.assert_allclose(
        rotation.skew(jnp.asarray(v)) @ a, np.cross(v, a), rtol=1e-14, atol=1e-15
    )
