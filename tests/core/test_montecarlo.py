"""Monte Carlo driver: equals a loop, independent of chunking and of the device count,
and the chi-square test's false-alarm rate is statistically the design Pfa."""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _problems import engine_false_alarm_study
from scipy import stats

import jaxfdi

TESTS = Path(__file__).resolve().parents[1]  # the shared helpers (_problems)


def test_monte_carlo_equals_python_loop_for_any_chunk_size():
    def run_one(key, scale):
        return {
            "draw": scale * jax.random.normal(key, (3,)),
            "label": (scale > 1.5).astype(jnp.int32),
        }

    scales = jnp.linspace(1.0, 2.0, 7)
    key = jax.random.key(5)
    keys = jax.random.split(key, 7)
    loop = [run_one(keys[i], scales[i]) for i in range(7)]
    for chunk_size in (1, 3, 7, 100):  # 3 does not divide 7: the last chunk is padded
        out = jaxfdi.monte_carlo(run_one, key, 7, scales, chunk_size=chunk_size)
        assert isinstance(out["draw"], np.ndarray) and out["draw"].shape == (7, 3)
        for i in range(7):
            # XLA may vectorise a batch of 3 and one of 7 differently: equal to rounding
            np.testing.assert_allclose(out["draw"][i], loop[i]["draw"], rtol=1e-14, atol=1e-15)
            assert out["label"][i] == loop[i]["label"]


def test_progress_is_reported_per_chunk():
    calls = []
    jaxfdi.monte_carlo(
        lambda k, _: jax.random.normal(k),
        jax.random.key(0),
        10,
        None,
        chunk_size=4,
        progress=lambda done, total, seconds: calls.append((done, total)),
    )
    assert calls == [(4, 10), (8, 10), (10, 10)]


@pytest.fixture(scope="module")
def single_device_study():
    return engine_false_alarm_study(num_runs=24, T=30, window=2, pfa=0.05, chunk_size=10)


def test_sharded_over_two_devices_equals_one_device(single_device_study, tmp_path):
    """The same study in a process with two (virtual CPU) devices, the run axis sharded
    over both, gives the same integer records and statistics equal to rounding."""
    out = tmp_path / "sharded.npz"
    script = textwrap.dedent(f"""
        import sys, numpy as np, jax
        jax.config.update("jax_enable_x64", True)
        sys.path.insert(0, {str(TESTS)!r})
        from _problems import engine_false_alarm_study
        assert len(jax.local_devices()) == 2, jax.local_devices()
        record, last = engine_false_alarm_study(num_runs=24, T=30, window=2, pfa=0.05, chunk_size=10)
        np.savez({str(out)!r}, last=last, **record._asdict())
    """)
    env = dict(
        os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2", JAX_PLATFORMS="cpu"
    )
    subprocess.run([sys.executable, "-c", script], check=True, env=env, timeout=600)
    sharded = np.load(out)
    record, last = single_device_study
    np.testing.assert_allclose(sharded["last"], last, rtol=1e-12)
    for name, value in record._asdict().items():
        np.testing.assert_array_equal(sharded[name], value, err_msg=name)
    assert len(jax.local_devices()) == 1


def _inside_binomial_99(count, trials, p):
    low, high = stats.binom.interval(0.99, trials, p)
    return low <= count <= high, (low, count, high)


def test_false_alarm_rate_is_the_design_pfa():
    """Fault-free Monte Carlo with x0 ~ N(0, P0): the NIS of the correct KF is chi2(5) and
    independent over steps, so with window 1 the alarm count over runs x steps is
    Binomial(runs * T, Pfa); with window 4 the alarms at the last step are independent
    over runs, Binomial(runs, Pfa). Both counts lie in the binomial 99 % interval."""
    runs, T, pfa = 200, 100, 0.01
    record, _ = engine_false_alarm_study(runs, T, window=1, pfa=pfa, seed=1)
    ok, detail = _inside_binomial_99(int(record.false_alarms.sum()), runs * T, pfa)
    assert ok, detail
    assert int(record.pre_onset_steps.sum()) == runs * T

    runs_w, pfa_w = 2000, 0.05
    _, last = engine_false_alarm_study(runs_w, 20, window=4, pfa=pfa_w, seed=2)
    threshold = float(jaxfdi.detection.chi2_threshold(20, pfa_w))
    ok, detail = _inside_binomial_99(int((last > threshold).sum()), runs_w, pfa_w)
    assert ok, detail
    # and the statistic itself is chi2(20): Kolmogorov-Smirnov at the 1 % level
    assert stats.kstest(last, stats.chi2(20).cdf).pvalue > 0.01


def test_a_hundred_thousand_runs_fit_by_chunking():
    """10^5 runs of a small scan in chunks of 2^14: the output is the small per-run record,
    so memory is bounded by the chunk, not by the number of runs."""
    n = 100_000

    def run_one(key, _):
        steps = jax.random.normal(key, (20,))
        return jnp.argmax(jnp.cumsum(steps) > 3.0).astype(jnp.int32)

    out = jaxfdi.monte_carlo(run_one, jax.random.key(0), n, None, chunk_size=16384)
    assert out.shape == (n,) and out.dtype == np.int32
    # P(random walk exceeds 3 within 20 steps) > 0; check the crossing fraction is sane
    frac = np.mean(out > 0)
    assert 0.2 < frac < 0.8
