"""The study engine (``jaxfdi._studies.study``): one program per structure whatever the runs and
seed, methods-as-data equal to the same methods run one by one, on-device per-case
means equal to host-side means of the same runs, and decisions independent of the chunk
size and of the device count.

The toy study: a 2-state tracking model, a bias fault on one sensor, a Kalman filter
whose measurement noise is a filter parameter, and the windowed chi-square detector with
its threshold as a detector parameter, so the grid is (2 filters) x (3 thresholds)."""

import subprocess
import sys
import textwrap
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _compiles import counting_compiles

import jaxfdi
from jaxfdi import fault, no_fault, stack_faults
from jaxfdi._studies import montecarlo, study
from jaxfdi.models import LinearGaussianModel

HERE = Path(__file__).resolve().parent
TESTS = HERE.parent  # the shared helpers (_compiles)
T = 60
MODEL = LinearGaussianModel(
    Phi=np.array([[1.0, 0.1], [0.0, 1.0]]),
    Gamma=np.array([[0.005], [0.1]]),
    C=np.eye(2),
    D=np.zeros((2, 1)),
    Q=1e-4 * np.eye(2),
    R=1e-2 * np.eye(2),
)
R_SCALES = np.array([1.0, 1.5])
THRESHOLDS = np.array([6.0, 9.2, 13.8])


def toy_run(key, f, r_scale, threshold):
    """One run: the plant with fault ``f``, a KF with R scaled, a chi-square detector."""
    us = jnp.ones((T, 1))
    model = MODEL._replace(R=MODEL.R * r_scale)
    kf = jaxfdi.filters.kalman_filter(model, unroll_factorizations=False)
    result = jaxfdi.monitor(
        jaxfdi.linear_simulator(MODEL, f),
        kf,
        jaxfdi.detection.chi2_detector(threshold, 2),
        jnp.zeros(2),
        kf.init(jnp.zeros(2), MODEL.Q),
        us,
        key,
        f.onset,
        keep_history=True,
    )
    return result.record, result.history.statistic


def toy_study(averaged=True) -> study.Study:
    cases = stack_faults([fault("bias", "sensor", 1, 30, 0.15), no_fault()])
    methods = {
        f"R x{r} chi2 {t}": (i, j) for i, r in enumerate(R_SCALES) for j, t in enumerate(THRESHOLDS)
    }
    run = toy_run if averaged else _record_only
    return study.Study(
        "toy",
        cases,
        ("sensor 1", "none"),
        (study.Structure("kf-chi2", run, (R_SCALES, THRESHOLDS), methods, averaged=averaged),),
    )


def _record_only(key, f, r_scale, threshold):
    return toy_run(key, f, r_scale, threshold)[0]


def _program(spec):
    s = spec.structures[0]
    summary = study._case_mean_summary(len(spec.case_names)) if s.averaged else None
    return montecarlo._compiled(study._program(s), False, summary, True)


def test_one_program_per_structure_whatever_runs_and_seed():
    """Six methods, one compiled program; other seeds and run counts (filling a chunk)
    compile nothing new: the chunk program holds one executable, and no backend
    compilation happens after the first study."""
    spec = toy_study()
    with counting_compiles() as compiles:
        study.run_study(spec, 200, 0, chunk_size=64)
        first = len(compiles)
        for runs, seed in ((200, 1), (333, 7), (64, 12)):
            study.run_study(spec, runs, seed, chunk_size=64)
    assert _program(spec)._cache_size() == 1
    assert len(compiles) == first  # nothing compiled after the first study
    # the default chunk on a CPU is one shape whatever the runs: a small study is padded up to it
    assert (
        montecarlo.default_chunk_size()
        == montecarlo.CHUNK_BY_PLATFORM["cpu"]
        == montecarlo.MIN_CHUNK
    )
    with counting_compiles() as compiles:
        study.run_study(spec, 3, 0)
        first = len(compiles)
        for runs, seed in ((40, 1), (150, 2)):
            study.run_study(spec, runs, seed)
    assert len(compiles) == first


def test_methods_as_data_equal_one_by_one():
    """Each method of the grid equals the same filter and detector run alone through
    ``monte_carlo`` on the same keys: integer fields exactly, float fields to 1e-12."""
    spec = toy_study()
    runs, seed = 20, 3
    result = study.run_study(spec, runs, seed)
    cases = jax.tree_util.tree_map(
        lambda leaf: np.repeat(np.asarray(leaf), runs, axis=0), spec.cases
    )
    for name, (i, j) in spec.structures[0].methods.items():
        alone = jaxfdi.monte_carlo(
            lambda k, f, i=i, j=j: toy_run(k, f, R_SCALES[i], THRESHOLDS[j])[0],
            jax.random.key(seed),
            2 * runs,
            cases,
            chunk_size=2 * runs,
        )
        grid = result.outputs[name]
        for field in (
            "onset",
            "first_alarm",
            "detection_step",
            "false_alarms",
            "isolated",
            "first_unhealthy",
        ):
            np.testing.assert_array_equal(
                getattr(grid, field), getattr(alone, field), err_msg=f"{name} {field}"
            )
        np.testing.assert_allclose(
            grid.estimate, alone.estimate, rtol=1e-12, atol=0, equal_nan=True
        )
    detections = [
        tuple(result.outputs[n].detection_step[:runs]) for n in spec.structures[0].methods
    ]
    assert len(set(detections)) > 1, "the thresholds and noise scales must make a difference"


def test_drawn_cases_give_each_run_its_own_case():
    """A study whose runs differ beyond their noise (here a random onset per run) draws
    its cases: run ``i`` (case-major) gets slice ``i`` of ``draw(runs, seed)``, so its
    records equal the runs' loop on those per-run faults; the onsets drawn come back in
    the records. A draw of the wrong length is refused, naming the argument."""
    runs, seed = 6, 4

    def draw(runs, seed):
        onsets = np.asarray(jax.random.randint(jax.random.key(seed + 2), (2 * runs,), 10, 50))
        return stack_faults(
            [
                fault("bias", "sensor", 1, int(k), 0.15) if i < runs else no_fault()
                for i, k in enumerate(onsets)
            ]
        )

    spec = toy_study(averaged=False)._replace(cases=draw)
    result = study.run_study(spec, runs, seed)
    faults = draw(runs, seed)
    name = "R x1.5 chi2 9.2"  # one cell: the grid itself is test_methods_as_data_equal_one_by_one's
    alone = jaxfdi.monte_carlo(
        lambda k, f: toy_run(k, f, R_SCALES[1], THRESHOLDS[1])[0],
        jax.random.key(seed),
        2 * runs,
        faults,
        chunk_size=2 * runs,
    )
    for field in ("onset", "first_alarm", "detection_step", "false_alarms"):
        np.testing.assert_array_equal(getattr(result.outputs[name], field), getattr(alone, field))
    np.testing.assert_array_equal(
        result.outputs["R x1.0 chi2 9.2"].onset[:runs], faults.onset[:runs]
    )
    assert len(set(faults.onset[:runs].tolist())) > 1
    with pytest.raises(ValueError, match="study.cases: the draw"):
        study.run_study(spec._replace(cases=lambda runs, seed: draw(runs + 1, seed)), runs, seed)


def _shared_model_run(key, f, threshold, model):
    us = jnp.ones((T, 1))
    kf = jaxfdi.filters.kalman_filter(model, unroll_factorizations=False)
    return jaxfdi.monitor(
        jaxfdi.linear_simulator(model, f),
        kf,
        jaxfdi.detection.chi2_detector(threshold, 2),
        jnp.zeros(2),
        kf.init(jnp.zeros(2), model.Q),
        us,
        key,
        f.onset,
    ).record


def test_shared_data_is_an_argument_not_a_constant():
    """A structure's ``shared`` data (here the whole model) reaches every run as it is:
    the records equal the runs with the model closed over, and another model's values
    compile nothing new."""
    base = toy_study(averaged=False)
    methods = {f"chi2 {t}": (j,) for j, t in enumerate(THRESHOLDS)}
    spec = base._replace(
        structures=(
            study.Structure(
                "shared model", _shared_model_run, (THRESHOLDS,), methods, shared=MODEL
            ),
        )
    )
    result = study.run_study(spec, 8, 2)
    cases = jax.tree_util.tree_map(lambda leaf: np.repeat(np.asarray(leaf), 8, axis=0), spec.cases)
    alone = jaxfdi.monte_carlo(
        lambda k, f: _shared_model_run(k, f, THRESHOLDS[0], MODEL),
        jax.random.key(2),
        16,
        cases,
        chunk_size=16,
    )
    np.testing.assert_array_equal(result.outputs["chi2 6.0"].detection_step, alone.detection_step)
    np.testing.assert_array_equal(result.outputs["chi2 6.0"].false_alarms, alone.false_alarms)
    with counting_compiles() as compiles:
        noisier = spec.structures[0]._replace(shared=MODEL._replace(R=4.0 * MODEL.R))
        other = study.run_study(spec._replace(structures=(noisier,)), 8, 2)
    assert not compiles
    assert any(
        (other.outputs[n].detection_step != result.outputs[n].detection_step).any() for n in methods
    )


def test_cases_may_have_their_own_run_counts():
    """``runs`` per case: case ``c`` gets ``runs[c]`` runs, case-major (``case_slices``),
    on the keys of one split over all of them, and its per-case mean counts only its own
    runs (host means of the same runs, 1e-12)."""
    spec = toy_study()
    counts = (3, 7)
    result = study.run_study(spec, counts, 6)
    assert result.runs == counts
    assert study.case_slices(counts, 2) == [slice(0, 3), slice(3, 10)]
    assert study.case_slices(4, 2) == [slice(0, 4), slice(4, 8)]
    cases = jax.tree_util.tree_map(
        lambda leaf: np.repeat(np.asarray(leaf), counts, axis=0), spec.cases
    )
    records, traces = jaxfdi.monte_carlo(
        study.grid_run(spec.structures[0]), jax.random.key(6), 10, cases, chunk_size=10
    )
    for name, (i, j) in spec.structures[0].methods.items():
        np.testing.assert_array_equal(
            result.outputs[name].detection_step, records.detection_step[:, i, j]
        )
        host = [traces[part, i, j].mean(axis=0) for part in study.case_slices(counts, 2)]
        np.testing.assert_allclose(result.means[name], np.stack(host), rtol=1e-12, atol=1e-12)
    with pytest.raises(ValueError, match="runs: expected one count or 2 counts"):
        study.run_study(spec, (3, 4, 5), 0)
    with pytest.raises(ValueError, match=r"runs\[1\]"):
        study.run_study(spec, (3, 0), 0)


def test_device_means_equal_host_means():
    """The per-case mean of the traces, summed on the device in chunks with padding,
    equals the mean of the same runs' traces kept and averaged on the host (1e-12)."""
    spec = toy_study()
    runs, seed = 30, 5
    result = study.run_study(spec, runs, seed, chunk_size=16)  # 60 runs: 4 chunks, the last padded
    cases = jax.tree_util.tree_map(
        lambda leaf: np.repeat(np.asarray(leaf), runs, axis=0), spec.cases
    )
    grid = study.grid_run(spec.structures[0])
    _, traces = jaxfdi.monte_carlo(grid, jax.random.key(seed), 2 * runs, cases, chunk_size=60)
    for name, (i, j) in spec.structures[0].methods.items():
        host = traces[:, i, j].reshape(2, runs, T).mean(axis=1)
        np.testing.assert_allclose(result.means[name], host, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("chunk_size", [7, 64])
def test_chunk_size_does_not_change_decisions(chunk_size):
    spec = toy_study(averaged=False)
    reference = study.run_study(spec, 25, 9, chunk_size=50)
    other = study.run_study(spec, 25, 9, chunk_size=chunk_size)
    for name in reference.outputs:
        for field in ("first_alarm", "detection_step", "false_alarms", "isolated"):
            np.testing.assert_array_equal(
                getattr(other.outputs[name], field), getattr(reference.outputs[name], field)
            )


def test_two_devices_give_the_same_decisions(tmp_path):
    """The toy study in a process with two (virtual CPU) devices, runs sharded over both,
    gives the same integer records and means equal to rounding."""
    out = tmp_path / "two.npz"
    script = textwrap.dedent(f"""
        import sys, numpy as np, jax
        jax.config.update("jax_enable_x64", True)
        sys.path[:0] = [{str(HERE)!r}, {str(TESTS)!r}]
        from test_study import toy_study
        from jaxfdi._studies import study
        assert len(jax.local_devices()) == 2, jax.local_devices()
        r = study.run_study(toy_study(), 25, 9, chunk_size=16)
        np.savez({str(out)!r}, **{{n + "|" + f: np.asarray(getattr(r.outputs[n], f)) for n in r.outputs
                                  for f in ("detection_step", "isolated", "false_alarms")}},
                 **{{n + "|mean": r.means[n] for n in r.means}})
    """)
    env = {
        **__import__("os").environ,
        "XLA_FLAGS": "--xla_force_host_platform_device_count=2",
        "JAX_PLATFORMS": "cpu",
    }
    proc = subprocess.run(
        [sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=600
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    two = np.load(out)
    one = study.run_study(toy_study(), 25, 9, chunk_size=16)
    for key in two.files:
        name, field = key.split("|")
        if field == "mean":
            np.testing.assert_allclose(two[key], one.means[name], rtol=1e-12, atol=1e-12)
        else:
            np.testing.assert_array_equal(two[key], getattr(one.outputs[name], field))


def test_bad_study_is_refused_with_the_argument_named():
    spec = toy_study()
    with pytest.raises(ValueError, match="study.case_names"):
        study.run_study(spec._replace(case_names=("one",)), 2, 0)
    bad = spec.structures[0]._replace(methods={"x": (0, 5)})
    with pytest.raises(ValueError, match=r"kf-chi2.methods\['x'\]"):
        study.run_study(spec._replace(structures=(bad,)), 2, 0)
    with pytest.raises(ValueError, match="runs"):
        study.run_study(spec, 0, 0)
    with pytest.raises(TypeError, match="study"):
        study.run_study({"name": "x"}, 2, 0)
    with pytest.raises(ValueError, match="structures"):
        study.run_study(spec, 2, 0, structures=["no such structure"])


def test_result_frame_is_each_method_and_case_scored_by_brute_force():
    """``StudyResult.to_frame``: a row per method and case; a DetectionRecord scored by ``fault_row`` on that case's
    runs (checked here by counting the runs by hand) with SciPy's exact intervals; a per-run bool as a rate with its
    exact interval and a per-run number as its mean with the normal interval; histories left out."""
    from scipy import stats

    def run(key, f, r_scale, threshold):
        record, statistic = toy_run(key, f, r_scale, threshold)
        return {
            "record": record,
            "peak": jnp.max(statistic),
            "late": statistic[-1] > threshold,
            "trace": statistic,
        }

    methods = {"R x1 chi2 9.2": (0, 1), "R x1.5 chi2 6.0": (1, 0)}
    spec = toy_study()._replace(
        structures=(study.Structure("kf-chi2", run, (R_SCALES, THRESHOLDS), methods),),
        horizon=T,
        labels=(1, None),
    )
    runs = 40
    result = jaxfdi.run_study(spec, runs=runs, seed=4)
    frame = result.to_frame(level=0.9)
    assert frame[["method", "case"]].values.tolist() == [
        [m, c] for m in methods for c in ("sensor 1", "none")
    ]
    assert not any(c.startswith("trace") for c in frame.columns)
    for i, (method, case) in enumerate(frame[["method", "case"]].values):
        out = result.outputs[method]
        part = slice(0, runs) if case == "sensor 1" else slice(runs, 2 * runs)
        rec = jax.tree_util.tree_map(lambda x: np.asarray(x)[part], out["record"])
        row = frame.loc[i]
        if (
            case == "sensor 1"
        ):  # every run faulty from step 30: detected = an alarm at or after the onset
            k = int(np.sum(rec.detection_step >= 0))
            assert row["record.detection_rate"] == k / runs
            ci = stats.binomtest(k, runs).proportion_ci(0.9, method="exact")
            assert (
                row["record.detection_rate_low"],
                row["record.detection_rate_high"],
            ) == pytest.approx((ci.low, ci.high), rel=1e-12)
        else:  # fault-free: a false alarm is any alarm in the run
            k = int(np.sum(rec.first_alarm >= 0))
            assert row["record.false_alarm_rate"] == k / runs and np.isnan(
                row["record.detection_rate"]
            )
        late = np.asarray(out["late"])[part]
        ci = stats.binomtest(int(late.sum()), runs).proportion_ci(0.9, method="exact")
        assert row["late"] == late.mean() and row["late_low"] == pytest.approx(ci.low, rel=1e-12)
        peak = np.asarray(out["peak"])[part]
        half = stats.norm.ppf(0.95) * peak.std(ddof=1) / np.sqrt(runs)
        assert row["peak_mean"] == pytest.approx(peak.mean(), rel=1e-12)
        assert row["peak_mean_high"] - row["peak_mean"] == pytest.approx(half, rel=1e-9)
    assert "<table" in result._repr_html_() and "40 runs per case, seed 4" in result._repr_html_()
    bare = result._replace(horizon=None)
    with pytest.raises(ValueError, match="horizon: expected the runs' length"):
        bare.to_frame()
    assert "horizon: expected" in bare._repr_html_()
    assert len(repr(result)) < 100


def test_detection_summary_frame_has_each_rate_over_its_own_denominator():
    from scipy import stats

    record = jaxfdi.DetectionRecord(  # 6 runs: 4 faulty (1 unhealthy), 2 fault-free (1 false alarm)
        onset=np.array([5, 5, 5, 5, 2**30, 2**30]),
        first_alarm=np.array([6, 2, -1, 7, 3, -1]),
        detection_step=np.array([6, 7, -1, 7, -1, -1]),
        false_alarms=np.array([0, 1, 0, 0, 1, 0]),
        pre_onset_steps=np.array([5, 5, 5, 5, 20, 20]),
        isolated=np.full(6, -1),
        first_label=np.full(6, -1),
        estimate=np.full(6, np.nan),
        first_unhealthy=np.array([-1, -1, -1, 9, -1, -1]),
    )
    summary = jaxfdi.summarize_detection(record, horizon=20)
    frame = summary.to_frame()
    assert (
        frame.shape[0] == 1
        and frame.loc[0, "faulty_runs"] == 3
        and frame.loc[0, "detection_rate"] == 2 / 3
    )
    for rate, k, n in (
        ("detection_rate", 2, 3),
        ("false_alarm_rate", 2, 5),
        ("pre_onset_alarm_rate", 1, 3),
    ):
        ci = stats.binomtest(k, n).proportion_ci(0.95, method="exact")
        assert (frame.loc[0, f"{rate}_low"], frame.loc[0, f"{rate}_high"]) == pytest.approx(
            (ci.low, ci.high)
        )
    assert "false_alarm_rate_per_step_low" not in frame and "<table" in summary._repr_html_()
