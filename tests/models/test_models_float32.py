"""float32 models: every model constructor gives finite float32 arrays equal to its
float64 model rounded (``c2d`` exponentiates in float64, then casts), with x64 off as a
new user has it (a subprocess: the suite runs with x64 on); engine scenarios refuse
float32 with a clear error; ``c2d`` reports a non-finite discretisation."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import jax.numpy as jnp
import numpy as np
import pytest

from jaxfdi.models import _vtol as vtol
from jaxfdi.models import c2d, engine_model

_CHILD = r"""
import json, sys
import jax, numpy as np
assert not jax.config.jax_enable_x64
from jaxfdi.models import engine_model, kitsat3_params, _vtol as vtol
from jaxfdi.models._rigid_body import rigid_body_params
from jaxfdi.models._fault_modes import bias_modes, noise_inflation_modes
out = {}
def put(name, tree):
    for i, leaf in enumerate(jax.tree.leaves(tree)):
        out[f"{name}/{i}"] = {"dtype": str(leaf.dtype), "value": np.asarray(leaf, np.float64).tolist()}
engine = engine_model()
put("engine", engine)
put("vtol", vtol.vtol_model())
put("vtol_unknown_input", vtol.vtol_unknown_input(include_disturbance=True))
put("vtol_true_plant", vtol.vtol_true_plant(uncertainty=0.7))
put("noise_inflation_modes", noise_inflation_modes(engine, 50.0, 0.01))
put("bias_modes", bias_modes(engine, 1e-4, 1.0))
put("rigid_body", rigid_body_params())
put("kitsat3", kitsat3_params())
errors = {}
from jaxfdi.scenarios.engine import engine_study, scenario_runs
for name, call in (("scenario_runs", lambda: scenario_runs(1, 0)), ("engine_study", lambda: engine_study(1))):
    try:
        call()
        errors[name] = None
    except ValueError as error:
        errors[name] = str(error)
json.dump({"models": out, "errors": errors}, sys.stdout)
"""


@pytest.fixture(scope="module")
def float32_run():
    env = {k: v for k, v in os.environ.items() if k != "JAX_ENABLE_X64"}
    env["JAX_PLATFORMS"] = env.get("JAX_PLATFORMS", "cpu")
    done = subprocess.run(
        [sys.executable, "-c", _CHILD], capture_output=True, text=True, env=env, timeout=300
    )
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout)


def _float64_models():
    from jaxfdi.models import bias_modes, kitsat3_params, noise_inflation_modes
    from jaxfdi.models._rigid_body import rigid_body_params

    engine = engine_model(dtype=jnp.float64)
    return {
        "engine": engine,
        "vtol": vtol.vtol_model(dtype=jnp.float64),
        "vtol_unknown_input": vtol.vtol_unknown_input(include_disturbance=True, dtype=jnp.float64),
        "vtol_true_plant": vtol.vtol_true_plant(uncertainty=0.7, dtype=jnp.float64),
        "noise_inflation_modes": noise_inflation_modes(engine, 50.0, 0.01),
        "bias_modes": bias_modes(engine, 1e-4, 1.0),
        "rigid_body": rigid_body_params(dtype=jnp.float64),
        "kitsat3": kitsat3_params(dtype=jnp.float64),
    }


def test_every_model_is_finite_float32_and_the_float64_model_rounded(float32_run):
    import jax

    models = float32_run["models"]
    for name, tree in _float64_models().items():
        leaves = jax.tree.leaves(tree)
        for i, ref in enumerate(leaves):
            got = models[f"{name}/{i}"]
            value = np.asarray(got["value"], np.float64).reshape(np.shape(ref))
            assert got["dtype"] == "float32", (name, i, got["dtype"])
            assert np.all(np.isfinite(value)), (name, i)
            ref = np.asarray(ref, np.float64)
            # the float64 model cast to float32 (one rounding, 6e-8), to 1e-6 relative
            err = np.max(
                np.abs(value - ref) / np.maximum(np.abs(ref), np.max(np.abs(ref)) * 1e-12 + 1e-300)
            )
            assert err < 1e-6, f"{name} leaf {i}: relative error {err:.2e}"


def test_engine_model_float32_under_x64_is_the_float64_model_cast():
    f64, f32 = engine_model(), engine_model(dtype=jnp.float32)
    assert f32.Phi.dtype == jnp.float32 and f64.Phi.dtype == jnp.float64
    for name in ("Phi", "Gamma"):
        np.testing.assert_array_equal(
            getattr(f32, name), np.asarray(getattr(f64, name)).astype(np.float32)
        )


def test_engine_scenarios_refuse_float32(float32_run):
    for name, message in float32_run["errors"].items():
        assert message is not None and "jaxfdi.enable_x64()" in message, (name, message)


def test_c2d_reports_a_non_finite_discretisation():
    with pytest.raises(ValueError, match="not finite even in float64"):
        c2d(np.array([[1e3]]), np.ones((1, 1)), 1.0)
    with pytest.raises(ValueError, match="overflow float32"):
        c2d(np.array([[100.0]]), np.ones((1, 1)), 1.0, dtype=jnp.float32)
