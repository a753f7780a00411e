"""Monte Carlo on two local processes (jax.distributed, gloo collectives on CPU) gives the
records and the streaming counts of one process, bit for bit; run keys depend only on
the run's index; the launcher options are checked."""

import os
import sys

import _multiprocess_study as study_module
import jax
import numpy as np
import pytest

from jaxfdi import distributed
from jaxfdi._studies.montecarlo import run_keys

TESTS = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))  # the shared helpers


def _same_bits(a, b) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()


def test_two_processes_equal_one_process(tmp_path):
    """2 processes x 1 CPU device, chunks of 8 runs (4 per device) against this process
    with chunks of 4 (4 on its one device): every record field and every streaming count
    identical, on both processes (each returns the whole study)."""
    prefix = str(tmp_path / "out_")
    command = [sys.executable, os.path.join(TESTS, "_multiprocess_study.py"), prefix, "8"]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([TESTS, os.environ.get("PYTHONPATH", "")]))
    try:
        distributed.launch_local(command, 2, timeout_s=240, env=env)
    except RuntimeError:  # e.g. the free port was taken meanwhile: once more on another one
        distributed.launch_local(command, 2, timeout_s=240, env=env)
    records, counts = study_module.study(4), study_module.study(4, reduce=True)
    assert int(counts.runs) == study_module.NUM_RUNS and int(counts.detected_runs) > 0
    for rank in range(2):
        saved = np.load(f"{prefix}{rank}.npz")
        assert int(saved["process_count"]) == 2
        for name, value in records._asdict().items():
            assert _same_bits(saved[f"record_{name}"], value), (rank, name)
        for name, value in counts._asdict().items():
            assert _same_bits(saved[f"counts_{name}"], value), (rank, name)


def test_run_keys_depend_only_on_the_index():
    for key in (jax.random.key(3), jax.random.PRNGKey(3)):
        index = np.array([0, 1, 77, 4095, 99_999])
        full = jax.random.split(key, 100_000)
        got = run_keys(key, index, 100_000)
        data = (
            (lambda k: jax.random.key_data(k))
            if jax.dtypes.issubdtype(key.dtype, jax.dtypes.prng_key)
            else np.asarray
        )
        np.testing.assert_array_equal(data(got), data(full[index]))
        np.testing.assert_array_equal(
            data(run_keys(key, index[:3], 80)), data(jax.random.split(key, 80)[index[:3]])
        )


def test_allgather_keeps_int64_on_one_process():
    tree = {
        "count": np.array([2**40 + 3, -5], np.int64),
        "flag": np.array([True, False]),
        "x": np.array([0.5]),
    }
    (got,) = distributed.allgather(tree)
    np.testing.assert_array_equal(got["count"], tree["count"])
    np.testing.assert_array_equal(got["flag"], tree["flag"])
    np.testing.assert_array_equal(got["x"], tree["x"])


def test_options_are_checked():
    assert distributed.check_options(2, 1, "10.0.0.1:8476") == (2, 1, "10.0.0.1:8476")
    assert distributed.check_options("4", "0", "host:1") == (4, 0, "host:1")
    assert distributed.check_options() == (None, None, None)
    with pytest.raises(ValueError, match="--process-id"):
        distributed.check_options(2, 2, "h:1")
    with pytest.raises(ValueError, match="--num-processes"):
        distributed.check_options(0, 0, "h:1")
    with pytest.raises(ValueError, match="--coordinator"):
        distributed.check_options(2, 0, "nohostport")
    with pytest.raises(ValueError, match="also needs --coordinator"):
        distributed.check_options(2, 0)
    with pytest.raises(ValueError, match="--num-processes"):
        distributed.check_options(None, 1, "h:1")
    with pytest.raises(ValueError, match="integer"):
        distributed.check_options("two", 0, "h:1")
    info = distributed.initialize()  # nothing given, nothing in the environment: one process
    assert info.num_processes == 1 and info.process_id == 0
