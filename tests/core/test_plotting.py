"""jaxfdi.plotting draws on the caller's axes or a new Figure, returns the Figure, and
never changes matplotlib's backend (issue 28). The drawn data are read back from the
artists and compared with the inputs."""

import matplotlib
import numpy as np
import pytest
from matplotlib.figure import Figure

from jaxfdi import plotting

T = 50
t = np.arange(T) * 0.01
statistic = np.linspace(0.0, 30.0, T)


@pytest.fixture
def non_agg_backend():
    """A non-interactive backend other than Agg ("svg"), restored afterwards."""
    before = matplotlib.get_backend()
    matplotlib.use("svg", force=True)
    yield "svg"
    matplotlib.use(before, force=True)


def calls():
    prob = np.stack([np.linspace(1, 0, T), np.linspace(0, 1, T)], axis=1)
    return {
        "statistic": lambda ax=None: plotting.plot_statistic(
            statistic, 14.86, t=t, onset=0.2, ax=ax
        ),
        "statistic runs": lambda ax=None: plotting.plot_statistic(
            np.stack([statistic, statistic / 2]), ax=ax, log=True
        ),
        "mode probabilities": lambda ax=None: plotting.plot_mode_probabilities(
            prob, ["normal", "P2"], t=t, threshold=0.9, onset=0.2, ax=ax
        ),
        "estimate": lambda ax=None: plotting.plot_estimate(
            statistic, statistic + 0.1, np.ones(T), t=t, ax=ax
        ),
        "delays": lambda ax=None: plotting.plot_delays(
            {"RPM": [0.01, 0.02, np.nan], "P2": [0.03, 0.05]}, ax=ax
        ),
        "confusion": lambda ax=None: plotting.plot_confusion(
            [0, 0, 1, 1], [0, -1, 1, 0], ["normal", "P2"], ax=ax
        ),
    }


@pytest.mark.parametrize("name", sorted(calls()))
def test_returns_a_figure_and_leaves_the_backend(non_agg_backend, name):
    import matplotlib.pyplot as plt

    open_before = plt.get_fignums()
    fig = calls()[name]()
    assert isinstance(fig, Figure)
    assert matplotlib.get_backend() == non_agg_backend
    assert plt.get_fignums() == open_before  # not registered with pyplot
    fig.savefig(__import__("io").BytesIO(), format="png")  # draws with the figure's own canvas
    assert matplotlib.get_backend() == non_agg_backend


@pytest.mark.parametrize("name", sorted(calls()))
def test_draws_on_the_given_axes(non_agg_backend, name):
    fig = Figure()
    ax = fig.add_subplot(1, 2, 2)
    assert calls()[name](ax=ax) is fig
    assert len(ax.get_children()) > 0 and matplotlib.get_backend() == non_agg_backend


def test_statistic_lines_hold_the_data():
    fig = plotting.plot_statistic(statistic, 14.86, t=t, onset=0.2)
    lines = {line.get_label(): line for line in fig.axes[0].get_lines()}
    np.testing.assert_array_equal(lines["statistic"].get_xdata(), t)
    np.testing.assert_array_equal(lines["statistic"].get_ydata(), statistic)
    np.testing.assert_array_equal(lines["threshold"].get_ydata(), np.full(T, 14.86))
    assert list(lines["onset"].get_xdata()) == [0.2, 0.2]


def test_confusion_counts_the_runs_and_shows_row_shares():
    """10 fault-free runs (9 isolate nothing, 1 isolates P2) and 10 P2 runs (8 right, 1 wrong, 1 nothing),
    tabulated by hand."""
    true = [0] * 10 + [1] * 10
    isolated = [-1] * 9 + [1] + [1] * 8 + [0, -1]
    fig = plotting.plot_confusion(true, isolated, ["normal", "P2"])
    np.testing.assert_allclose(
        fig.axes[0].images[0].get_array(), [[0.0, 0.1, 0.9], [0.1, 0.8, 0.1]]
    )
    assert [tick.get_text() for tick in fig.axes[0].get_xticklabels()] == ["normal", "P2", "none"]
    counts = plotting.plot_confusion(true, isolated, ["normal", "P2"], normalize=False)
    assert sorted(text.get_text() for text in counts.axes[0].texts) == [
        "0",
        "1",
        "1",
        "1",
        "8",
        "9",
    ]


def test_delays_leave_out_and_count_the_missed():
    fig = plotting.plot_delays({"RPM": [0.01, 0.03, np.nan]})
    assert [tick.get_text() for tick in fig.axes[0].get_xticklabels()] == ["RPM\n(1 missed)"]
    median = [line for line in fig.axes[0].get_lines() if line.get_color() in ("C1", "#ff7f0e")][0]
    assert median.get_ydata()[0] == pytest.approx(0.02)


@pytest.mark.parametrize(
    "call,argument",
    [
        (lambda: plotting.plot_statistic(np.zeros((2, 2, 2))), "statistic"),
        (lambda: plotting.plot_mode_probabilities(np.zeros((5, 2)), ["a"]), "names"),
        (lambda: plotting.plot_confusion([0, 2], [0, 1], ["a", "b"]), "true_labels"),
        (lambda: plotting.plot_confusion([0, 1], [0, 1, 1], ["a", "b"]), "predicted_labels"),
        (lambda: plotting.plot_delays({}), "delays"),
    ],
)
def test_bad_input_names_the_argument(call, argument):
    with pytest.raises(ValueError, match=f"^{argument}:"):
        call()


def test_library_never_selects_a_backend():
    """No ``matplotlib.use`` outside the CLI (which selects Agg to write files)."""
    from pathlib import Path

    import jaxfdi

    offenders = [
        str(p)
        for p in Path(jaxfdi.__file__).parent.rglob("*.py")
        if "matplotlib.use(" in p.read_text() and p.name != "cli.py"
    ]
    assert offenders == []


def test_library_never_imports_pyplot():
    """Studies' figures are ``plotting.column_figure``s, like the plot functions' (never registered with pyplot:
    a notebook's or script's open figures and backend are left alone)."""
    import re
    from pathlib import Path

    import jaxfdi

    pyplot = re.compile(
        r"^\s*(import matplotlib\.pyplot|from matplotlib import pyplot|from matplotlib\.pyplot import)",
        re.MULTILINE,
    )
    files = list(Path(jaxfdi.__file__).parent.rglob("*.py"))
    assert any("column_figure(" in p.read_text() for p in files if "scenarios" in p.parts)
    assert [str(p) for p in files if pyplot.search(p.read_text())] == []


def test_cli_selects_agg_unless_a_backend_is_named(non_agg_backend, monkeypatch):
    from jaxfdi import cli

    monkeypatch.setenv("MPLBACKEND", "svg")
    cli._select_agg_backend()
    assert matplotlib.get_backend() == "svg"
    monkeypatch.delenv("MPLBACKEND")
    cli._select_agg_backend()
    assert matplotlib.get_backend().lower() == "agg"


@pytest.mark.parametrize("layout", [None, "constrained"])
def test_save_figure_writes_the_caption_under_the_axes(tmp_path, layout):
    """The caption is a text of the figure, wrapped, below every axes (tight and
    constrained layouts); the PNG is written; a figure without a caption is refused."""
    fig = Figure(figsize=(6, 3), layout=layout)
    ax = fig.add_subplot()
    ax.plot([0, 1], [0, 1])
    ax.set(xlabel="x [m]", ylabel="y [m]")
    caption = "What the figure shows over 10 runs and where it differs from the paper's. " * 4
    path = plotting.save_figure(fig, tmp_path / "f.png", caption)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    (text,) = [t for t in fig.texts if "What the figure shows" in t.get_text()]
    assert (
        " ".join(text.get_text().split()) == " ".join(caption.split()) and "\n" in text.get_text()
    )
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    renderer = FigureCanvasAgg(fig).get_renderer()
    top_of_caption = text.get_window_extent(renderer).y1
    assert ax.get_tightbbox(renderer).y0 > top_of_caption
    with pytest.raises(ValueError, match="caption"):
        plotting.save_figure(Figure(), tmp_path / "g.png", " ")


def _two_panels(**legend):
    fig = Figure(figsize=(18, 4), layout="constrained")
    left, right = fig.subplots(1, 2)
    left.plot(t, statistic, label="statistic")
    left.plot(t, statistic / 2, label="half")
    right.plot(t, statistic)
    left.set(xlabel="time [s]", ylabel="statistic")
    right.set(xlabel="time [s]")
    if legend.get("legend", True):
        left.legend()
    return fig


def test_saved_figures_are_a_column_wide_with_the_house_fonts(tmp_path):
    """The house style: whatever size a study draws at, the PNG is COLUMN_WIDTH_IN at DPI
    (about the 800 px the docs show) and its text at the house sizes."""
    from PIL import Image

    fig = _two_panels()
    path = plotting.save_figure(fig, tmp_path / "f.png", "One run of the statistic, 2 runs in all.")
    width, _ = Image.open(path).size
    assert width == round(plotting.COLUMN_WIDTH_IN * plotting.DPI)
    left = fig.axes[0]
    assert left.xaxis.label.get_fontsize() == plotting.FONT_PT
    assert {text.get_fontsize() for text in left.get_legend().get_texts()} == {
        plotting.SMALL_FONT_PT
    }


@pytest.mark.parametrize(
    "case,match",
    [
        ("caption without a run count", "number of runs"),
        ("panel without labels", "y label"),
        ("curve in no legend", "in no legend"),
    ],
)
def test_save_figure_refuses_a_figure_a_reader_cannot_read(tmp_path, case, match):
    fig, caption = _two_panels(), "One run of the statistic."
    if case == "caption without a run count":
        caption = "The statistic against time."
    elif case == "panel without labels":
        fig.axes[0].set_ylabel("")
    else:
        fig.axes[1].plot(t, statistic, label="unlisted")
    with pytest.raises(ValueError, match=match):
        plotting.save_figure(fig, tmp_path / "f.png", caption)
    assert not (tmp_path / "f.png").exists()


def test_a_hypothesis_keeps_its_colour():
    names = ["normal", "actuator", "RPM", "P2"]
    colors = plotting.hypothesis_colors(names)
    assert colors["normal"] == plotting.NO_FAULT_COLOR
    assert len({colors[n] for n in names[1:]}) == 3
    assert (
        plotting.hypothesis_colors(["none", *names[1:]])["P2"] == colors["P2"]
    )  # the same order, the same colour
