"""The command line refuses what it cannot use before computing, and leaves ``--out`` as
it was when a study fails or is interrupted.

Bad options run ``main`` in-process with every runner replaced by one that fails the
test if called (and the engine's method builder by a stub): exit status 2, one line on
stderr naming the option, nothing computed, ``--out`` not created. The output folder is
checked file by file (names, bytes, modes) before and after. Two subprocess tests signal
a real ``jaxfdi run engine-chi2`` once it has started its study."""

import json
import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from jaxfdi import cli
from jaxfdi._io import files as _io
from jaxfdi.cli import main

ENGINE_NAMES = ["MM", "IMM", "IMM hand-pi", "IMM-bias hand-pi confirm 3, P2 2", "GLRT l_T=200"]


def snapshot(folder):
    """Every path under ``folder`` with its bytes and permission bits (None if absent)."""
    if not folder.exists():
        return None
    return {
        str(p.relative_to(folder)): (
            p.read_bytes() if p.is_file() else b"<dir>",
            p.stat().st_mode & 0o777,
        )
        for p in sorted(folder.rglob("*"))
    }


@pytest.fixture
def no_compute(monkeypatch):
    """Every runner fails the test if called; the engine's 7-second method builder is a
    stub with names of the real shape (one holds a comma)."""

    def computed(args, folder):
        pytest.fail("the study ran")

    for registry in (cli.RUNNERS, cli.TUNERS):
        for name, runner in list(registry.items()):
            monkeypatch.setitem(registry, name, runner._replace(run=computed))
    import jaxfdi.scenarios.engine as engine

    monkeypatch.setattr(engine, "engine_methods", lambda *a, **k: dict.fromkeys(ENGINE_NAMES))


def a_file(tmp_path):
    path = tmp_path / "a-file"
    path.write_text("x")
    return path


BIG = str(2**64)  # beyond 64 bits: jax.random.key raised OverflowError after the study had started
BAD_OPTIONS = [
    # (arguments, the option the one-line message names, what it says was expected)
    (["run", "engine-chi2", "--runs", "0"], "--runs", "an integer in [1, 2147483647]"),
    (["run", "vtol", "--runs", "-3"], "--runs", "an integer in [1,"),
    (["run", "engine", "--runs", str(2**31)], "--runs", "an integer in [1, 2147483647]"),
    (["run", "engine-chi2", "--seed", "-1"], "--seed", "an integer in [0, 4294967295]"),
    (["run", "engine-chi2", "--seed", str(2**32)], "--seed", "an integer in [0, 4294967295]"),
    (["run", "reaction-wheels", "--seed", BIG], "--seed", "an integer in [0, 4294967295]"),
    (["run", "engine-chi2", "--window", "0"], "--window", "an integer in [1,"),
    (["run", "engine-chi2", "--window", "-4"], "--window", "an integer in [1,"),
    (["run", "engine-chi2", "--pfa", "0"], "--pfa", "a finite number in (0, 1)"),
    (["run", "engine-chi2", "--pfa", "1"], "--pfa", "a finite number in (0, 1)"),
    (["run", "engine-chi2", "--pfa", "nan"], "--pfa", "a finite number in (0, 1)"),
    (["run", "engine-chi2", "--pfa", "inf"], "--pfa", "a finite number in (0, 1)"),
    (["run", "engine-chi2", "--pfa=-1e-3"], "--pfa", "a finite number in (0, 1)"),
    (["run", "engine-chi2", "--methods", "KF"], "--methods", "none: engine-chi2 has one method"),
    (["run", "engine", "--methods", "MM,Kalman"], "--methods", "names among MM; IMM; IMM hand-pi;"),
    (["run", "engine", "--methods", ","], "--methods", "names among MM; IMM;"),
    (
        ["run", "vtol", "--methods", "raw,chi2"],
        "--methods",
        "names among raw; window; MDWT-HT; MDWT-ST",
    ),
    (
        ["run", "reaction-wheels", "--methods", "fdp,kalman"],
        "--methods",
        "names among fdp; nis; credit; likelihood",
    ),
    (
        ["run", "vtol", "--window", "8"],
        "--window",
        "no value: run vtol does not read it (read by engine-chi2)",
    ),
    (["run", "engine", "--pfa", "0.01"], "--pfa", "no value: run engine does not read it"),
    (
        ["run", "engine-chi2", "--estimator", "ukf"],
        "--estimator",
        "no value: run engine-chi2 does not read it",
    ),
    (["run", "vtol", "--engage-on", "fdp"], "--engage-on", "no value: run vtol does not read it"),
    (["tune", "engine-imm", "--steps", "0"], "--steps", "an integer in [1,"),
    (["tune", "engine-chi2", "--train-runs", "0"], "--train-runs", "an integer in [1,"),
    (["tune", "engine-imm", "--runs", "0"], "--runs", "an integer in [1,"),
    (["tune", "engine-imm", "--seed", BIG], "--seed", "an integer in [0, 4294967295]"),
    (["tune", "engine-imm", "--selection-runs", "0"], "--selection-runs", "an integer in [1,"),
    (
        ["tune", "engine-imm", "--detection-weight", "nan"],
        "--detection-weight",
        "a finite number >= 0",
    ),
    (
        ["tune", "engine-imm", "--detection-weight", "-1"],
        "--detection-weight",
        "a finite number >= 0",
    ),
    (
        ["tune", "engine-imm", "--false-alarm-weight", "inf"],
        "--false-alarm-weight",
        "a finite number >= 0",
    ),
    (["tune", "engine-chi2", "--delay-weight=-inf"], "--delay-weight", "a finite number >= 0"),
    (["tune", "engine-chi2", "--delay-weight", "nan"], "--delay-weight", "a finite number >= 0"),
    (
        ["tune", "engine-imm", "--isolation-weight", "-0.5"],
        "--isolation-weight",
        "a finite number >= 0",
    ),
    (
        ["tune", "engine-imm", "--confirm-steps", "0"],
        "--confirm-steps",
        "one integer >= 1 or 7 of them",
    ),
    (
        ["tune", "engine-imm", "--confirm-steps", "3,2"],
        "--confirm-steps",
        "one integer >= 1 or 7 of them",
    ),
    (
        ["tune", "engine-imm", "--confirm-steps", "1,3,3,0,3,3,3"],
        "--confirm-steps",
        "one integer >= 1 or 7",
    ),
    (
        ["tune", "engine-imm", "--design", "zhang-li", "--freeze", "bias_walk"],
        "--freeze",
        "parameter names of design zhang-li",
    ),
    (
        ["tune", "engine-imm", "--freeze", "bias_walk"],
        "--freeze",
        "parameter names of design",
    ),  # not in zhang-li
    (
        [
            "tune",
            "engine-imm",
            "--design",
            "bias",
            "--freeze",
            "bias_prior,bias_walk,initial_mode,mu_threshold,transition",
        ],
        "--freeze",
        "at least one parameter of design bias left to train",
    ),
    (
        ["tune", "engine-chi2", "--windows", "4,0"],
        "--windows",
        "integers in [1, 2147483647] separated by commas",
    ),
    (["tune", "engine-chi2", "--windows", ""], "--windows", "integers in [1,"),
    (["tune", "engine-chi2", "--windows", "2,four"], "--windows", "integers in [1,"),
    (["tune", "engine-chi2", "--windows", "1.5"], "--windows", "integers in [1,"),
    (
        ["tune", "engine-chi2", "--design", "bias"],
        "--design",
        "no value: tune engine-chi2 does not read it",
    ),
    (
        ["tune", "engine-chi2", "--isolation-weight", "1"],
        "--isolation-weight",
        "no value: tune engine-chi2",
    ),
    (
        ["tune", "engine-chi2", "--select-thresholds"],
        "--select-thresholds",
        "no value: tune engine-chi2",
    ),
    (
        ["tune", "engine-imm", "--windows", "2,4"],
        "--windows",
        "no value: tune engine-imm does not read it",
    ),
]


@pytest.mark.parametrize(
    "argv, option, what", BAD_OPTIONS, ids=[" ".join(c[0])[:60] for c in BAD_OPTIONS]
)
def test_bad_option_exits_2_with_one_line_before_computing(
    no_compute, tmp_path, capsys, argv, option, what
):
    out = tmp_path / "out"
    assert main([*argv, "--out", str(out)]) == 2
    captured = capsys.readouterr()
    lines = captured.err.splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"jaxfdi: {option}: expected "), captured.err
    assert what in lines[0] and ", got " in lines[0], lines[0]
    assert captured.out == "" and not out.exists()


@pytest.mark.parametrize("where", ["file", "below a file", "unwritable", "not creatable"])
def test_bad_out_exits_2_before_computing(no_compute, tmp_path, capsys, where):
    if where == "file":
        out, said = a_file(tmp_path), "which is a file"
    elif where == "below a file":
        out, said = a_file(tmp_path) / "sub", "which is below the file"
    elif where == "unwritable":  # an existing folder nobody, root included, can create files in
        out, said = "/proc", "expected a writable folder"
    else:
        out, said = (
            "/proc/jaxfdi-out/results",
            "expected a writable folder",
        )  # nobody creates folders in /proc
    before = snapshot(tmp_path)
    assert main(["run", "engine-chi2", "--out", str(out)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("jaxfdi: --out: expected ") and said in err[0], err
    assert snapshot(tmp_path) == before  # no probe file left


def test_wrong_usage_is_argparse_exit_2(no_compute, capsys):
    with pytest.raises(SystemExit) as stop:
        main(["run", "engine-chi2", "--runs", "many"])
    assert stop.value.code == 2 and "--runs" in capsys.readouterr().err


def fake_runner(monkeypatch, run, name="fake"):
    monkeypatch.setitem(
        cli.RUNNERS, name, cli.Runner(run, "a study that writes files for the test")
    )


def write_study(folder):
    """A study's three kinds of file: PNG and JSON by the atomic writers, an npz by
    ``np.savez`` straight into the temporary folder."""
    _io.atomic_write(folder / "fake-fig.png", lambda tmp: open(tmp, "wb").write(b"\x89PNG new"))
    np.savez(folder / "fake-params.npz", a=np.arange(3))
    _io.write_json(folder / "fake.json", {"rows": [1.0, float("nan")]})


@pytest.fixture
def results(tmp_path):
    """An output folder that already holds an older study and an unrelated file."""
    out = tmp_path / "results"
    out.mkdir()
    (out / "fake.json").write_text('{"old": true}\n')
    (out / "fake-fig.png").write_bytes(b"old figure")
    (out / "notes.txt").write_text("mine")
    os.chmod(out / "notes.txt", 0o600)
    return out


def test_study_files_appear_together_json_last_with_normal_permissions(
    monkeypatch, results, capsys
):
    moves = []
    real_replace = os.replace

    def replace(src, dst):
        if os.path.dirname(dst) == str(results):  # a move out of the temporary folder
            moves.append(os.path.basename(dst))
        return real_replace(src, dst)

    def run(args, folder):
        write_study(folder)
        assert snapshot(results)["fake.json"][0] == b'{"old": true}\n'  # nothing published yet
        return "wrote the fake study"

    fake_runner(monkeypatch, run)
    monkeypatch.setattr(_io.os, "replace", replace)
    old_mask = os.umask(0o027)
    try:
        assert main(["run", "fake", "--out", str(results)]) == 0
    finally:
        os.umask(old_mask)
    assert capsys.readouterr().out.splitlines()[-1] == "wrote the fake study"
    assert moves == ["fake-fig.png", "fake-params.npz", "fake.json"]  # JSON last
    after = snapshot(results)
    assert sorted(after) == [
        "fake-fig.png",
        "fake-params.npz",
        "fake.json",
        "notes.txt",
    ]  # no temp folder left
    assert after["fake-fig.png"] == (b"\x89PNG new", 0o640) and after["fake-params.npz"][1] == 0o640
    written = json.loads(after["fake.json"][0])
    assert written.pop("provenance")["command"].startswith(
        "jaxfdi run fake"
    )  # issue 28: every JSON says how
    assert written == {"rows": [1.0, None]} and after["fake.json"][1] == 0o640
    assert after["notes.txt"] == (b"mine", 0o600)


def test_atomic_write_gives_the_permissions_of_a_new_file(tmp_path):
    old_mask = os.umask(0o002)
    try:
        path = _io.write_json(tmp_path / "a.json", {"x": 1})
        assert path.stat().st_mode & 0o777 == 0o664 and _io.file_mode() == 0o664
    finally:
        os.umask(old_mask)
    assert _io.current_umask() == old_mask


def interrupt_with(exc):
    def run(args, folder):
        write_study(folder)
        raise exc

    return run


@pytest.mark.parametrize("exc, status", [(KeyboardInterrupt(), 130), (RuntimeError("a bug"), None)])
def test_interrupted_or_failed_study_leaves_out_as_it_was(
    monkeypatch, results, capsys, exc, status
):
    fake_runner(monkeypatch, interrupt_with(exc))
    before = snapshot(results)
    if status is None:
        with pytest.raises(RuntimeError, match="a bug"):
            main(["run", "fake", "--out", str(results)])
    else:
        assert main(["run", "fake", "--out", str(results)]) == status
        assert (
            capsys.readouterr().err.strip()
            == f"jaxfdi: interrupted by SIGINT; {results} left as it was"
        )
    assert snapshot(results) == before


in_main_thread = pytest.mark.skipif(
    threading.current_thread() is not threading.main_thread(),
    reason="the CLI handles signals in the main thread only",
)


@in_main_thread
def test_sigterm_in_process_leaves_out_as_it_was_and_restores_the_handler(
    monkeypatch, results, capsys
):
    def run(args, folder):
        write_study(folder)
        os.kill(os.getpid(), signal.SIGTERM)
        for _ in range(1000):  # the handler raises at the next bytecode; never reached in full
            time.sleep(0.01)
        pytest.fail("SIGTERM did not stop the study")

    fake_runner(monkeypatch, run)
    before, handler = snapshot(results), signal.getsignal(signal.SIGTERM)
    assert main(["run", "fake", "--out", str(results)]) == 128 + signal.SIGTERM
    assert "interrupted by SIGTERM" in capsys.readouterr().err
    assert snapshot(results) == before and signal.getsignal(signal.SIGTERM) == handler


@in_main_thread
def test_a_signal_dropped_in_a_destructor_is_delivered_again(monkeypatch, results, capsys):
    """Python runs a handler at the next bytecode, which may be in a ``__del__`` or a gc
    callback (JAX's ``_xla_gc_callback`` is one): the exception raised there is dropped,
    and the study would go on to publish. The CLI delivers it again."""

    class SignalledWhileDeleted:
        def __del__(self):
            os.kill(os.getpid(), signal.SIGTERM)
            for _ in range(1000):  # a backward jump: the handler runs here, inside __del__
                pass

    def run(args, folder):
        write_study(folder)
        victim = SignalledWhileDeleted()
        del victim
        for _ in range(1000):
            time.sleep(0.01)
        pytest.fail("the dropped SIGTERM was not delivered again")

    fake_runner(monkeypatch, run)
    before = snapshot(results)
    assert main(["run", "fake", "--out", str(results)]) == 128 + signal.SIGTERM
    assert snapshot(results) == before


def test_interrupted_study_removes_the_folders_it_created(monkeypatch, tmp_path):
    fake_runner(monkeypatch, interrupt_with(KeyboardInterrupt()))
    before = snapshot(tmp_path)
    assert main(["run", "fake", "--out", str(tmp_path / "new" / "deeper")]) == 130
    assert snapshot(tmp_path) == before


def test_a_folder_in_the_way_fails_before_any_file_moves(monkeypatch, results):
    (results / "fake.json").unlink()
    (results / "fake.json").mkdir()
    fake_runner(monkeypatch, lambda args, folder: write_study(folder) or "wrote")
    before = snapshot(results)
    with pytest.raises(IsADirectoryError, match="fake.json"):
        main(["run", "fake", "--out", str(results)])
    assert snapshot(results) == before


def test_library_argument_error_is_one_line_exit_2_and_a_bug_a_traceback(
    monkeypatch, results, capsys
):
    """A ValueError from a jaxfdi check (here ``chi2_threshold``'s) is the user's: one
    line, exit 2; one from inside JAX is a bug: the traceback (so is any with --traceback)."""
    import jax.numpy as jnp

    from jaxfdi.detection import chi2_threshold

    fake_runner(monkeypatch, lambda args, folder: chi2_threshold(20, 1.5), "bad-argument")
    fake_runner(monkeypatch, lambda args, folder: jnp.ones(3) + jnp.ones(4), "bug")
    before = snapshot(results)
    assert main(["run", "bad-argument", "--out", str(results)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith(
        "jaxfdi: pfa: expected a probability in (0, 1), got 1.5"
    ), err
    with pytest.raises(ValueError, match="pfa"):
        main(["run", "bad-argument", "--traceback", "--out", str(results)])
    with pytest.raises(TypeError):
        main(["run", "bug", "--out", str(results)])
    assert snapshot(results) == before


def test_pfa_the_threshold_cannot_represent_exits_2_before_computing(monkeypatch, tmp_path, capsys):
    """The CLI passes any pfa in (0, 1) on; the library decides what it can represent."""
    import jaxfdi.scenarios.engine_chi2 as engine_chi2
    from jaxfdi.detection import chi2_threshold

    pfa = 5e-324  # the smallest float64
    try:
        threshold = float(chi2_threshold(4 * 5, pfa))
    except ValueError as e:
        refusal = str(e)
    else:
        pytest.skip(f"chi2_threshold(20, {pfa}) gives {threshold} rather than a ValueError")
    monkeypatch.setattr(engine_chi2, "run_study", lambda *a, **k: pytest.fail("the study ran"))
    out = tmp_path / "out"
    assert main(["run", "engine-chi2", "--pfa", str(pfa), "--out", str(out)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert (
        len(err) == 1
        and err[0].startswith(f"jaxfdi: {' '.join(refusal.split())}")
        and not out.exists()
    )


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_signal_mid_run_leaves_out_as_it_was(tmp_path, signum):
    """A real ``jaxfdi run engine-chi2``, signalled once its temporary folder exists (it is
    then importing the scenario and compiling): after one line on stderr the process ends
    killed by that signal (a shell shows 128 + signal), ``--out`` byte for byte as before,
    no temporary file or folder left."""
    if signal.getsignal(signum) == signal.SIG_IGN:
        pytest.skip(f"{signum.name} is ignored here, and so in the child (a background job)")
    out = tmp_path / "out"
    out.mkdir()
    (out / "engine-chi2.json").write_text('{"an": "older study"}\n')
    (out / "keep.txt").write_text("mine")
    before = snapshot(out)
    proc = subprocess.Popen(
        [sys.executable, "-m", "jaxfdi", "run", "engine-chi2", "--runs", "2", "--out", str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 120
        while not any(p.name.startswith(_io.TEMP_PREFIX) for p in out.iterdir()):
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, "the study never started"
            time.sleep(0.01)
        proc.send_signal(signum)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == -signum, err
    assert err.strip().splitlines()[-1].endswith(f"{out} left as it was"), err
    assert snapshot(out) == before
