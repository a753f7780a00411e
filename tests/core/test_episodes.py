"""Group faults, several episodes per run and the multi-episode record, against
plain-Python references (loops over steps written from the definitions)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxfdi
from jaxfdi import (
    NEVER,
    FaultKind,
    as_stack,
    concat_faults,
    episodes,
    fault,
    fault_group,
    fault_label,
    no_fault,
    stack_faults,
    summarize_episodes,
)
from jaxfdi._simulation.faults import active_label
from jaxfdi._studies.metrics import episode_record_init, episode_record_update
from jaxfdi.models import engine_model

KINDS = ["bias", "ramp", "impulse", "scale", "stuck", "none"]


# ---------------------------------------------------------------- faults: groups, labels, episodes


def test_unknown_kind_or_target_raises_value_error_naming_it():
    for call, name in (
        (lambda: fault("foo", "sensor", 0, 5), "kind"),
        (lambda: fault("bias", "gyro", 0, 5), "target"),
        (lambda: fault(42, "sensor", 0, 5), "kind"),
        (lambda: fault("bias", 7, 0, 5), "target"),
    ):
        with pytest.raises(ValueError, match=f"^{name}: expected one of"):
            call()
    with pytest.raises(ValueError, match="magnitudes: expected a scalar or shape \\(2,\\)"):
        fault_group("bias", "sensor", [0, 1], 5, [0.1, 0.2, 0.3])
    with pytest.raises(ValueError, match="components: expected shape \\(G,\\)"):
        fault_group("bias", "sensor", [], 5, 0.1)


def test_existing_constructions_keep_working():
    """Positional Fault (seven fields) still builds; its label defaults to -1 (derived)."""
    f = jaxfdi.Fault(*(jnp.asarray(v) for v in (1, 1, 2, 5, 0.3, 0.0, NEVER)))
    assert f.label == -1 and int(fault_label(f, 1)) == 4
    assert int(fault_label(f._replace(label=9), 1)) == 9
    assert int(fault("bias", "sensor", 2, 5).label) == -1
    # a stack built by hand without label: the scalar default is broadcast over the stack
    hand = jaxfdi.Fault(
        *(
            jnp.asarray(v)
            for v in ([1, 1], [1, 0], [2, 0], [5, 8], [0.3, 0.1], [0.0, 0.0], [NEVER, NEVER])
        )
    )
    assert as_stack(hand).label.tolist() == [-1, -1]
    assert [int(active_label(hand, k, 1)) for k in (4, 5, 8)] == [0, 4, 4]
    assert np.asarray(episodes(hand, 1)[2]).tolist() == [4, 1]


def test_group_fault_applies_each_component_and_is_labelled_as_one():
    """Both axes of one sensor biased by magnitude * direction, labelled 9; the simulator's
    mode is 9 while it acts (noise-free engine: sensor_fault is exactly the bias)."""
    direction = np.array([0.6, -0.8])
    group = fault_group(
        "bias", "sensor", [1, 3], onset=10, magnitudes=2.0 * direction, end=25, label=9
    )
    assert group.kind.shape == (2,) and list(np.asarray(group.label)) == [9, 9]
    model = engine_model()._replace(Q=jnp.zeros((7, 7)), R=jnp.zeros((5, 5)))
    _, truth, _ = jaxfdi.simulate(
        jaxfdi.linear_simulator(model, group),
        jnp.zeros(7),
        jnp.full((30, 1), 0.01),
        jax.random.key(0),
    )
    expected = np.zeros((30, 5))
    expected[10:25, 1], expected[10:25, 3] = 2.0 * direction
    np.testing.assert_allclose(truth.sensor_fault, expected, atol=1e-12)
    np.testing.assert_array_equal(
        truth.mode, np.where((np.arange(30) >= 10) & (np.arange(30) < 25), 9, 0)
    )


def random_stack(rng, size):
    """A stack of ``size`` random faults (some NONE, some repeats of an earlier entry's
    onset/end/label as a group would make, some explicit labels), as dicts and a Fault."""
    spec = []
    for i in range(size):
        if i and rng.random() < 0.25:  # another component of an earlier entry's group
            d = dict(spec[int(rng.integers(0, i))])
            d["component"] = int(rng.integers(0, 5))
            if d["label"] < 0:
                d["label"] = int(rng.integers(0, 9))
        else:
            onset = int(
                rng.integers(0, 45)
            )  # a fault ends after its onset (fault() refuses end <= onset)
            end = NEVER if rng.random() < 0.3 else onset + int(rng.integers(1, 45))
            d = dict(
                kind=str(rng.choice(KINDS)),
                target=str(rng.choice(["actuator", "sensor"])),
                component=int(rng.integers(0, 2)),
                onset=onset,
                end=end,
                label=int(rng.choice([-1, -1, 3, 7])),
            )
        spec.append(d)
    return spec, stack_faults([fault(magnitude=0.5, **d) for d in spec])


def python_label(d, num_inputs):
    if d["kind"] == "none":
        return 0
    if d["label"] >= 0:
        return d["label"]
    return 1 + d["component"] + (0 if d["target"] == "actuator" else num_inputs)


def python_active(d, k):
    if d["kind"] == "none":
        return False
    if d["kind"] == "impulse":
        return k == d["onset"] and k < d["end"]
    return d["onset"] <= k < d["end"]


def test_active_label_and_episodes_equal_python_loops():
    rng = np.random.default_rng(7)
    num_inputs = 2
    labels_at = jax.jit(jax.vmap(active_label, in_axes=(None, 0, None)), static_argnums=2)
    episodes_of = jax.jit(episodes, static_argnums=1)
    for _ in range(60):
        spec, stack = random_stack(rng, int(rng.integers(1, 6)))
        got = np.asarray(labels_at(stack, jnp.arange(50), num_inputs))
        for k in range(50):
            live = [python_label(d, num_inputs) for d in spec if python_active(d, k)]
            assert got[k] == (live[0] if live else 0), (spec, k)
        onsets, ends, labels = (np.asarray(a) for a in episodes_of(stack, num_inputs))
        seen, expected = set(), []
        for d in spec:
            end = min(d["end"], d["onset"] + 1) if d["kind"] == "impulse" else d["end"]
            key = (d["onset"], end, python_label(d, num_inputs))
            if d["kind"] == "none" or key in seen:
                expected.append((NEVER, NEVER, 0))
            else:
                seen.add(key)
                expected.append(key)
        assert list(zip(onsets, ends, labels)) == expected, spec


def test_concat_faults_joins_scalars_and_stacks_and_simulates():
    group = fault_group("bias", "sensor", [0, 1], 5, 1.0, end=10, label=8)
    stack = concat_faults(group, fault("bias", "actuator", 0, 20, 0.1, end=30), no_fault())
    assert stack.kind.shape == (4,) and list(np.asarray(stack.kind)) == [1, 1, 1, 0]
    onsets, ends, labels = (np.asarray(a) for a in episodes(stack, 1))
    assert list(onsets) == [5, NEVER, 20, NEVER] and list(labels) == [8, 0, 1, 0]
    assert [int(active_label(stack, k, 1)) for k in (4, 5, 12, 20, 29, 30)] == [0, 8, 0, 1, 1, 0]
    assert int(FaultKind.NONE) == int(stack.kind[3])


# ---------------------------------------------------------------- the multi-episode record


def reference_episode_record(alarms, labels, healthy, onsets, ends, episode_labels, grace):
    """The EpisodeRecord's definition as a plain loop over steps."""
    E = len(onsets)
    close = []
    for e in range(E):
        later = [onsets[j] for j in range(E) if onsets[j] > onsets[e]]
        close.append(min(ends[e] + grace, min(later, default=NEVER)))
    detection, isolated = [-1] * E, [-1] * E
    false_alarms, first_false, outside_steps, first_unhealthy = 0, -1, 0, -1
    for k, (alarm, label, ok) in enumerate(zip(alarms, labels, healthy)):
        inside = [onsets[e] <= k < close[e] for e in range(E)]
        if not ok and first_unhealthy < 0:
            first_unhealthy = k
        if not any(inside):
            outside_steps += 1
            if alarm:
                false_alarms += 1
                if first_false < 0:
                    first_false = k
        for e in range(E):
            if alarm and inside[e] and detection[e] < 0:
                detection[e], isolated[e] = k, label
    return dict(
        close=close,
        detection_step=detection,
        isolated=isolated,
        false_alarms=false_alarms,
        first_false_alarm=first_false,
        outside_steps=outside_steps,
        steps=len(alarms),
        first_unhealthy=first_unhealthy,
    )


@pytest.fixture(scope="module")
def random_episode_runs():
    """300 runs of 40 steps with 4 random episodes each (some beyond the horizon, some
    never ending, some sharing an onset, some absent), random alarms, labels and health."""
    rng = np.random.default_rng(11)
    R, T, E = 300, 40, 4
    onsets = rng.integers(0, 45, size=(R, E))
    onsets[rng.random((R, E)) < 0.1] = NEVER
    onsets[:, 1] = np.where(rng.random(R) < 0.1, onsets[:, 0], onsets[:, 1])
    ends = np.where(rng.random((R, E)) < 0.3, NEVER, onsets + rng.integers(1, 15, size=(R, E)))
    ends = np.minimum(ends, NEVER)
    episode_labels = rng.integers(1, 6, size=(R, E))
    alarms = rng.random((R, T)) < rng.uniform(0.0, 0.4, size=(R, 1))
    labels = rng.integers(1, 6, size=(R, T))
    healthy = ~((rng.random((R, 1)) < 0.15) & (np.arange(T) >= rng.integers(0, T, size=(R, 1))))
    grace = rng.integers(0, 4, size=R)

    def one(alarm_row, label_row, healthy_row, onset, end, episode_label, g):
        def body(record, step):
            return episode_record_update(record, *step), None

        record0 = episode_record_init(onset, end, episode_label, g)
        return jax.lax.scan(body, record0, (jnp.arange(T), alarm_row, label_row, healthy_row))[0]

    records = jax.jit(jax.vmap(one))(alarms, labels, healthy, onsets, ends, episode_labels, grace)
    return (alarms, labels, healthy, onsets, ends, episode_labels, grace), records


def test_streaming_episode_record_equals_brute_force(random_episode_runs):
    (alarms, labels, healthy, onsets, ends, episode_labels, grace), records = random_episode_runs
    for i in range(alarms.shape[0]):
        ref = reference_episode_record(
            list(alarms[i]),
            list(labels[i]),
            list(healthy[i]),
            list(onsets[i]),
            list(ends[i]),
            list(episode_labels[i]),
            int(grace[i]),
        )
        got = {name: np.asarray(getattr(records, name)[i]).tolist() for name in ref}
        assert got == ref, i
        delay = [d - o if d >= 0 else -1 for d, o in zip(ref["detection_step"], onsets[i])]
        assert np.asarray(records.delay[i]).tolist() == delay


def test_summarize_episodes_equals_counting(random_episode_runs):
    (_, _, _, onsets, _, episode_labels, _), records = random_episode_runs
    Ts = 0.5
    s = summarize_episodes(records, Ts)
    detection, isolated = np.asarray(records.detection_step), np.asarray(records.isolated)
    first_unhealthy, steps = np.asarray(records.first_unhealthy), np.asarray(records.steps)
    healthy_runs = [i for i in range(onsets.shape[0]) if first_unhealthy[i] < 0]
    assert s.runs == onsets.shape[0] and s.unhealthy_runs == onsets.shape[0] - len(healthy_runs)
    assert 0 < s.unhealthy_runs < s.runs
    for e in range(onsets.shape[1]):
        began = [i for i in healthy_runs if onsets[i, e] < steps[i]]
        detected = [i for i in began if detection[i, e] >= 0]
        correct = [i for i in detected if isolated[i, e] == episode_labels[i, e]]
        delays = [(detection[i, e] - onsets[i, e]) * Ts for i in detected]
        assert s.episodes[e] == len(began)
        assert s.detection_rate[e] == pytest.approx(len(detected) / len(began))
        assert s.isolation_rate[e] == pytest.approx(len(correct) / len(began))
        assert s.delay_mean[e] == pytest.approx(sum(delays) / len(delays))
        assert s.delay_median[e] == pytest.approx(
            sorted(delays)[len(delays) // 2]
            if len(delays) % 2
            else sum(sorted(delays)[len(delays) // 2 - 1 : len(delays) // 2 + 1]) / 2
        )
    false_alarms, outside_steps = (
        np.asarray(records.false_alarms),
        np.asarray(records.outside_steps),
    )
    fa_runs = [i for i in healthy_runs if false_alarms[i] > 0]
    assert s.false_alarm_runs == len(fa_runs)
    assert s.false_alarm_rate == pytest.approx(len(fa_runs) / len(healthy_runs))
    outside = sum(int(outside_steps[i]) for i in healthy_runs)
    assert s.false_alarm_rate_per_step == pytest.approx(
        sum(int(false_alarms[i]) for i in healthy_runs) / outside
    )


def test_four_episodes_in_one_flight():
    """Four satellite episodes (the GPS/INS shape): two transient, a group, a permanent
    one; a windowed test that lags 2 steps after each clears; grace 2 makes those lags
    no false alarms, grace 0 counts them."""
    stack = concat_faults(
        fault("bias", "sensor", 0, 10, 1.0, end=20),
        fault("ramp", "sensor", 1, 30, 0.0, 0.1, end=40),
        fault_group("bias", "sensor", [2, 3], 50, [0.3, 0.4], end=60, label=12),
        fault("bias", "sensor", 4, 70, 1.0),
    )
    onsets, ends, labels = episodes(stack, 1)
    T = 80
    alarm = np.zeros(T, bool)
    label = np.zeros(T, int)
    for start, stop, lab in (
        (12, 22, 2),
        (35, 42, 3),
        (51, 62, 5),
        (71, 80, 6),
    ):  # 3rd isolated wrongly
        alarm[start:stop], label[start:stop] = True, lab
    alarm[3] = True  # one false alarm before any fault
    for grace, false_alarms in ((2, 1), (0, 1 + 2 + 2 + 2)):
        record = episode_record_init(onsets, ends, labels, grace)
        for k in range(T):
            record = episode_record_update(record, k, alarm[k], label[k])
        valid = np.asarray(onsets) < NEVER
        assert np.asarray(record.detection_step)[valid].tolist() == [12, 35, 51, 71]
        assert np.asarray(record.isolated)[valid].tolist() == [2, 3, 5, 6]
        assert int(record.false_alarms) == false_alarms and int(record.first_false_alarm) == 3
    s = summarize_episodes(jax.tree.map(lambda a: np.asarray(a)[None], record), Ts=0.1)
    valid_rates = s.isolation_rate[np.asarray(onsets) < NEVER]
    assert valid_rates.tolist() == [1.0, 1.0, 0.0, 1.0]
