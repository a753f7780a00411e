"""Progress: a tqdm.auto bar when tqdm is installed, log lines otherwise, the callable hook
unchanged, and --quiet silencing the logger (issue 28)."""

import io
import logging
import time

import jax
import jax.numpy as jnp
import pytest

import jaxfdi
from jaxfdi._io import progress


def run_one(key, scale):
    return scale * jax.random.normal(key, ())


def test_callable_hook_sees_every_chunk():
    seen = []
    out = jaxfdi.monte_carlo(
        run_one,
        jax.random.key(0),
        10,
        jnp.ones(10),
        chunk_size=4,
        progress=lambda done, total, seconds: seen.append((done, total)),
    )
    assert seen == [(4, 10), (8, 10), (10, 10)] and out.shape == (10,)


def test_tqdm_bar_counts_to_the_total():
    pytest.importorskip("tqdm")
    stream = io.StringIO()
    bar = progress.progress_bar("monte carlo", "runs", use_tqdm=True, file=stream)
    for done in (4, 8, 10):
        bar(done, 10, 0.1 * done)
    assert bar.bar is None  # closed at the total
    text = stream.getvalue()
    assert "monte carlo" in text and "10/10" in text


def test_default_progress_uses_tqdm_when_installed(monkeypatch):
    created = []
    monkeypatch.setattr(progress, "tqdm_available", lambda: True)
    real = progress._Bar.__call__

    def spy(self, *args, **kwargs):
        created.append(args[:2])
        self.options.setdefault("file", io.StringIO())
        return real(self, *args, **kwargs)

    monkeypatch.setattr(progress._Bar, "__call__", spy)
    pytest.importorskip("tqdm")
    jaxfdi.monte_carlo(run_one, jax.random.key(0), 6, jnp.ones(6), chunk_size=3, progress=True)
    assert created == [(3, 6), (6, 6)]


def test_log_lines_without_tqdm(caplog):
    caplog.set_level(logging.INFO, logger="jaxfdi")
    hook = progress.progress_bar("tuning", "steps", use_tqdm=False, interval=3600.0)
    for done in range(1, 6):
        hook(done, 5, float(done))
    messages = [r.getMessage() for r in caplog.records if r.name == "jaxfdi"]
    assert messages == [
        "tuning: 1/5 steps, 1.0 s, 1 steps/s",
        "tuning: 5/5 steps, 5.0 s, 1 steps/s",
    ]


def test_quiet_logging_drops_info_keeps_warnings():
    stream = io.StringIO()
    handler = progress.configure_logging(quiet=True, stream=stream)
    try:
        progress.logger.info("progress line")
        progress.logger.warning("a warning")
        assert stream.getvalue() == "a warning\n"
        progress.configure_logging(quiet=False, stream=stream)
        progress.logger.info("now shown")
        assert stream.getvalue().endswith("now shown\n")
        assert sum(getattr(h, "_jaxfdi_cli", False) for h in progress.logger.handlers) == 1
    finally:
        for h in list(progress.logger.handlers):
            if getattr(h, "_jaxfdi_cli", False):
                progress.logger.removeHandler(h)
        progress.logger.setLevel(logging.NOTSET)
        del handler


def test_without_tqdm_or_logging_setup_plain_lines_on_stderr(monkeypatch, capfd):
    """monte_carlo(progress=True) with no tqdm and no handler on the jaxfdi logger: whole
    lines on stderr (no carriage returns, which Jupyter renders badly)."""
    monkeypatch.setattr(progress, "tqdm_available", lambda: False)
    monkeypatch.setattr(progress.logger, "handlers", [])
    monkeypatch.setattr(progress.logger, "propagate", False)
    jaxfdi.monte_carlo(run_one, jax.random.key(0), 6, jnp.ones(6), chunk_size=3, progress=True)
    err = capfd.readouterr().err
    assert (
        "\r" not in err
        and err.startswith("monte carlo: 3/6 runs")
        and "monte carlo: 6/6 runs" in err
    )


def test_compilation_is_announced_and_never_silent(caplog, monkeypatch):
    """A study's first chunk logs 'compiling', a heartbeat while XLA works (every 5 s;
    here 0.05 s), then 'compiled in'; a second study of the same function compiles
    nothing and says nothing of it."""
    from jaxfdi._studies import montecarlo

    monkeypatch.setattr(montecarlo._Heartbeat.__init__, "__defaults__", (0.05,))
    caplog.set_level(logging.INFO, logger="jaxfdi")

    def slow_to_compile(
        key, scale
    ):  # 300 unrolled steps: a compilation of a good fraction of a second
        x = scale * jax.random.normal(key, (4,))
        for i in range(300):
            x = jnp.sin(x + i) * jnp.cos(x)
        return x

    jaxfdi.monte_carlo(
        slow_to_compile, jax.random.key(0), 8, jnp.ones(8), progress=lambda *a: None, label="toy"
    )
    messages = [
        r.getMessage()
        for r in caplog.records
        if r.name == "jaxfdi" and "running" not in r.getMessage()
    ]
    assert messages[0] == "toy: compiling" and messages[-1].startswith("toy: compiled in ")
    assert any(m.startswith("toy: still compiling") for m in messages[1:-1]), messages
    caplog.clear()
    jaxfdi.monte_carlo(
        slow_to_compile, jax.random.key(1), 8, jnp.ones(8), progress=lambda *a: None, label="toy"
    )
    assert not [r for r in caplog.records if "compil" in r.getMessage()]


def test_a_long_chunk_is_never_silent(caplog, monkeypatch):
    """While a chunk runs longer than the heartbeat's interval (5 s; here 0.05 s) with no
    progress report, the runs done so far are logged; the display's own reports reset
    the silence."""
    from jaxfdi._studies import montecarlo

    monkeypatch.setattr(montecarlo._Heartbeat.__init__, "__defaults__", (0.05,))
    caplog.set_level(logging.INFO, logger="jaxfdi")

    def slow_run(key, x):  # 0.4 s a chunk, on the host
        wait = lambda v: (time.sleep(0.4), v)[1]
        return jax.pure_callback(
            wait, jax.ShapeDtypeStruct((), x.dtype), x, vmap_method="broadcast_all"
        )

    reports = []
    jaxfdi.monte_carlo(
        slow_run,
        jax.random.key(0),
        8,
        jnp.ones(8),
        chunk_size=4,
        label="slow",
        progress=lambda done, total, seconds: reports.append(done),
    )
    running = [r.getMessage() for r in caplog.records if "running" in r.getMessage()]
    assert reports == [4, 8]
    assert any(m.startswith("slow: running, 0/8 runs done (") for m in running), running
    assert all(m.startswith(("slow: running, 0/8", "slow: running, 4/8")) for m in running), running


def test_status_after_basic_config_at_warning_prints_its_line(monkeypatch, capfd):
    """``logging.basicConfig()`` gives the root a WARNING handler, which drops INFO: ``status`` then prints its
    line on stderr (a long run is never silent); a handler that takes INFO gets it as a log record."""
    root = logging.getLogger()
    handler = logging.StreamHandler(io.StringIO())
    monkeypatch.setattr(root, "handlers", [handler])
    monkeypatch.setattr(progress.logger, "level", logging.NOTSET)
    level = root.level
    try:
        root.setLevel(
            logging.WARNING
        )  # setLevel, not the attribute: it clears the loggers' level caches
        progress.status("compiling the engine study")
        assert "compiling the engine study" in capfd.readouterr().err
        assert handler.stream.getvalue() == ""
        root.setLevel(logging.INFO)
        progress.status("compiled")
        assert "compiled" in handler.stream.getvalue() and capfd.readouterr().err == ""
    finally:
        root.setLevel(level)


def test_without_ipywidgets_the_bar_is_a_text_line_and_warns_nothing(monkeypatch):
    """``tqdm.auto`` in a notebook without ipywidgets picks ``tqdm.notebook``, which warns ("IProgress not found")
    and cannot draw; the library's bar is then tqdm's text line, with no warning."""
    import sys
    import warnings

    import tqdm.std

    monkeypatch.setitem(sys.modules, "ipywidgets", None)  # import ipywidgets -> ImportError
    for name in ("tqdm.auto", "tqdm.autonotebook"):  # importing them in a notebook is what warns
        monkeypatch.delitem(sys.modules, name, raising=False)
    assert progress.tqdm_available() and "tqdm.autonotebook" not in sys.modules
    assert progress._tqdm_class() is tqdm.std.tqdm
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        bar = progress.progress_bar("runs", "run", use_tqdm=True, file=io.StringIO())
        bar(3, 3, 0.1)
