"""Figures of FDI results, for notebooks and scripts.

Each function draws on ``ax`` if given (returning ``ax.figure``), else on a new
``matplotlib.figure.Figure`` it returns; ``t``: (T,) sample times (default: step indices). No pyplot:
no backend change, no window, nothing kept in pyplot's registry (Jupyter shows a returned figure as the
cell's value or with ``display(fig)``; scripts ``fig.savefig(path)``; the CLI selects Agg itself).

Studies' figures keep a house style (``caption_figure``; ``save_figures`` writes them): one text
column wide at the docs' resolution, axes labelled with units, labelled curves in a legend, one colour
per hypothesis across panels and figures (``hypothesis_colors``), a caption giving the number of runs.
"""

from __future__ import annotations

import re
import textwrap
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from jaxfdi._io.files import save_figures
from jaxfdi._studies.metrics import confusion_matrix
from jaxfdi.gnss import integrity_outcomes

__all__ = [
    "plot_statistic",
    "plot_mode_probabilities",
    "plot_estimate",
    "plot_delays",
    "plot_confusion",
    "stanford_diagram",
    "stanford_regions",
    "caption_figure",
    "save_figure",
    "save_figures",
]


def new_axes(ax=None, figsize: tuple[float, float] = (7.0, 3.5)):
    """``(figure, ax)``: ``ax`` and its figure, else a new unregistered ``Figure`` of ``figsize`` inches."""
    if ax is not None:
        return ax.figure, ax
    fig = column_figure(figsize[1], figsize[0])
    return fig, fig.add_subplot()


def column_figure(height: float, width: float | None = None):
    """A house-style figure (``save_figure``): ``height`` inches tall, ``width`` wide (default one column,
    ``COLUMN_WIDTH_IN``), constrained layout, not registered with pyplot.

    Returns:
      The ``matplotlib.figure.Figure``.
    """
    from matplotlib.figure import Figure

    return Figure(
        figsize=(COLUMN_WIDTH_IN if width is None else width, height), layout="constrained"
    )


def column_subplots(height: float, nrows: int = 1, ncols: int = 1, **kwargs):
    """``column_figure(height)`` with a grid of axes, ``Figure.subplots(nrows, ncols, **kwargs)``.

    Returns:
      ``(figure, axes)``, as ``pyplot.subplots`` returns them.
    """
    fig = column_figure(height)
    return fig, fig.subplots(nrows, ncols, **kwargs)


def _time(t, n: int) -> np.ndarray:
    return np.arange(n) if t is None else np.asarray(t)


def plot_statistic(
    statistic,
    threshold=None,
    *,
    t=None,
    onset=None,
    label: str = "statistic",
    log: bool = False,
    ax=None,
):
    """A detection statistic over time with its threshold and the fault onset.

    Args:
      statistic: ``(T,)`` one run, or ``(R, T)`` several runs (drawn thin).
      threshold: scalar or ``(T,)`` alarm threshold (dashed), or ``None``.
      onset: time of the fault onset (dotted vertical line), or ``None``.
      label: the statistic's name (legend and y label).
      log: logarithmic y axis.

    Returns:
      The ``matplotlib.figure.Figure``.
    """
    values = np.asarray(statistic, dtype=float)
    if values.ndim not in (1, 2):
        raise ValueError(f"statistic: expected shape (T,) or (R, T), got {values.shape}")
    runs = values[None] if values.ndim == 1 else values
    time = _time(t, runs.shape[1])
    fig, ax = new_axes(ax)
    for i, run in enumerate(runs):
        ax.plot(
            time,
            run,
            color="C0",
            lw=1.2 if len(runs) == 1 else 0.6,
            alpha=1.0 if len(runs) == 1 else 0.5,
            label=label if i == 0 else None,
        )
    if threshold is not None:
        level = np.broadcast_to(np.asarray(threshold, dtype=float), time.shape)
        ax.plot(time, level, color="C3", ls="--", lw=1.0, label="threshold")
    if onset is not None:
        ax.axvline(onset, color="k", ls=":", lw=1.0, label="onset")
    if log:
        ax.set_yscale("log")
    ax.set(xlabel="time" if t is not None else "step", ylabel=label)
    ax.legend(loc="best", fontsize="small")
    return fig


def plot_mode_probabilities(
    mode_prob, names: Sequence[str] | None = None, *, t=None, onset=None, threshold=None, ax=None
):
    """Mode probabilities over time (an IMM's or a multiple-model filter's ``mode_prob``).

    Args:
      mode_prob: ``(T, M)`` probabilities of M modes.
      names: M mode names (default ``mode 0`` ...).
      onset: fault onset (dotted vertical line), or ``None``.
      threshold: the decision threshold ``mu_T`` (dashed), or ``None``.

    Returns:
      The ``matplotlib.figure.Figure``.
    """
    prob = np.asarray(mode_prob, dtype=float)
    if prob.ndim != 2:
        raise ValueError(f"mode_prob: expected shape (T, M), got {prob.shape}")
    names = list(names) if names is not None else [f"mode {j}" for j in range(prob.shape[1])]
    if len(names) != prob.shape[1]:
        raise ValueError(f"names: expected {prob.shape[1]} names (one per mode), got {len(names)}")
    time = _time(t, prob.shape[0])
    fig, ax = new_axes(ax)
    for j, name in enumerate(names):
        ax.plot(time, prob[:, j], lw=1.2, label=name)
    if threshold is not None:
        ax.axhline(float(threshold), color="k", ls="--", lw=0.8, label="threshold")
    if onset is not None:
        ax.axvline(onset, color="k", ls=":", lw=1.0)
    ax.set(
        xlabel="time" if t is not None else "step", ylabel="mode probability", ylim=(-0.02, 1.02)
    )
    ax.legend(loc="best", fontsize="small", ncol=2)
    return fig


def plot_estimate(estimate, truth=None, std=None, *, t=None, label: str = "estimate", ax=None):
    """One estimated quantity with its +-2 standard-deviation band and the truth.

    Args:
      estimate: ``(T,)`` estimates.
      truth: ``(T,)`` true values, or ``None``.
      std: ``(T,)`` standard deviations (e.g. ``sqrt(cov[:, i, i])``), or ``None``.
      label: the quantity's name.

    Returns:
      The ``matplotlib.figure.Figure``.
    """
    est = np.asarray(estimate, dtype=float)
    if est.ndim != 1:
        raise ValueError(f"estimate: expected shape (T,), got {est.shape}")
    time = _time(t, est.shape[0])
    fig, ax = new_axes(ax)
    if truth is not None:
        ax.plot(time, np.asarray(truth, dtype=float), color="k", lw=1.0, label="truth")
    ax.plot(time, est, color="C0", lw=1.2, label=label)
    if std is not None:
        s = np.asarray(std, dtype=float)
        ax.fill_between(time, est - 2 * s, est + 2 * s, color="C0", alpha=0.2, label="+-2 sigma")
    ax.set(xlabel="time" if t is not None else "step", ylabel=label)
    ax.legend(loc="best", fontsize="small")
    return fig


def plot_delays(delays: Mapping[str, Sequence[float]], *, unit: str = "s", ax=None):
    """Detection delays per fault (or per method) as box plots; NaN (not detected) left out and counted in the label.

    Args:
      delays: name -> delays of the runs (NaN for a run never detected).
      unit: the delays' unit (axis label).

    Returns:
      The ``matplotlib.figure.Figure``.
    """
    if not delays:
        raise ValueError("delays: expected at least one name -> delays entry, got none")
    fig, ax = new_axes(ax, figsize=(max(4.0, 1.1 * len(delays) + 2), 3.5))
    data, labels = [], []
    for name, values in delays.items():
        v = np.asarray(values, dtype=float).ravel()
        finite = v[np.isfinite(v)]
        data.append(finite)
        missed = v.size - finite.size
        labels.append(f"{name}\n({missed} missed)" if missed else str(name))
    ax.boxplot(data, tick_labels=labels, showfliers=True)
    ax.set(ylabel=f"detection delay [{unit}]")
    ax.tick_params(axis="x", labelsize="small")
    return fig


def plot_confusion(
    true_labels, predicted_labels, names: Sequence[str], *, normalize: bool = True, ax=None
):
    """Isolation outcomes as an annotated confusion matrix: rows the true fault, columns the one isolated, and a last
    column "none" for runs that isolated nothing.

    Args:
      true_labels: (R,) int in [0, K), each run's true label (its fault's label; 0 fault-free).
      predicted_labels: (R,) int < K, the label each run isolated (``DetectionRecord.isolated``; negative: none).
      names: K class names.
      normalize: show each row as shares of its runs.

    Returns:
      The ``matplotlib.figure.Figure``.
    """
    m = np.asarray(
        confusion_matrix(true_labels, predicted_labels, len(names)), dtype=float
    )  # (K, K + 1)
    shown = m / np.maximum(m.sum(axis=1, keepdims=True), 1) if normalize else m
    size = 1.0 + 0.6 * m.shape[0]
    fig, ax = new_axes(ax, figsize=(size + 1.6, size))
    image = ax.imshow(shown, cmap="Blues", vmin=0.0, vmax=1.0 if normalize else None)
    for i in range(m.shape[0]):
        for j in range(m.shape[1]):
            ax.text(
                j,
                i,
                f"{shown[i, j]:.2f}" if normalize else f"{m[i, j]:.0f}",
                ha="center",
                va="center",
                fontsize="small",
                color="white" if shown[i, j] > 0.6 * np.nanmax(shown) else "black",
            )
    ax.set_xticks(range(m.shape[1]), [*names, "none"], rotation=45, ha="right")
    ax.set_yticks(range(m.shape[0]), names)
    ax.set(xlabel="isolated", ylabel="true")
    fig.colorbar(image, ax=ax, shrink=0.8)
    return fig


def stanford_regions(
    ax, alert_limit: float | None = None, limits: tuple[float, float] = (0.05, 1e3)
):
    """The Stanford diagram's background on log axes ``ax`` over ``limits`` [m] (both axes): the diagonal
    ``error = PL`` and the misleading region under it, and with an ``alert_limit`` its two lines, the hazardous
    region (``PL < AL <= error``) and the unavailable one (``PL >= AL``); regions as ``gnss.integrity_outcomes``.

    Returns:
      ``ax``.
    """
    lo, hi = limits
    if not 0 < lo < hi:
        raise ValueError(f"limits: expected (low, high) with 0 < low < high [m], got {limits}")
    x = np.array([lo, hi])
    ax.fill_between(x, lo, x, color="r", alpha=0.1, lw=0, label="misleading (error > PL)")
    ax.plot(x, x, "k-", lw=0.8, label="error = PL")
    if alert_limit is not None and lo < alert_limit < hi:
        ax.fill_between(
            [alert_limit, hi],
            lo,
            alert_limit,
            color="r",
            alpha=0.25,
            lw=0,
            label="hazardous (error >= AL)",
        )
        ax.fill_between(
            x, alert_limit, hi, color="0.5", alpha=0.15, lw=0, label="unavailable (PL >= AL)"
        )
        ax.axvline(alert_limit, color="k", ls="--", lw=0.6)
        ax.axhline(alert_limit, color="k", ls="--", lw=0.6)
    ax.set(xscale="log", yscale="log", xlim=limits, ylim=limits)
    return ax


def stanford_diagram(
    error,
    level,
    *,
    alert_limit: float | None = None,
    alarm=None,
    label: str = "epochs",
    axis: str = "",
    ax=None,
    limits: tuple[float, float] | None = None,
):
    """Each epoch's error (x) against its protection level (y) on the Stanford diagram's regions
    (``stanford_regions``), alarmed epochs circled, and the counts of ``gnss.integrity_outcomes`` in the title.

    Args:
      error: (E,) absolute position errors [m] on one axis.
      level: (E,) protection levels [m] on the same axis.
      alert_limit: the operation's alert limit [m] on that axis (``gnss.ALERT_LIMITS``), or ``None``.
      alarm: (E,) bool, epochs whose test alarmed, or ``None``.
      label: the points' legend entry; axis: ``"horizontal"`` or ``"vertical"`` (the axis labels).
      limits: (low, high) [m] of both axes (points beyond them drawn on the edge); ``None``: the decades of the
        finite data, from 1 cm at least.

    Returns:
      The ``matplotlib.figure.Figure``.
    """
    error, level = np.asarray(error, float), np.asarray(level, float)
    counts = integrity_outcomes(error, level, np.inf if alert_limit is None else alert_limit, alarm)
    finite = np.isfinite(error) & np.isfinite(level) & (error > 0) & (level > 0)
    if limits is None:
        values = np.concatenate(
            [error[finite], level[finite], [] if alert_limit is None else [alert_limit]]
        )
        values = values if values.size else np.array([1.0])
        low = max(values.min(), 1e-2)
        limits = (10 ** np.floor(np.log10(low)), 10 ** np.ceil(np.log10(values.max())))
    x, y = np.clip(error, *limits), np.clip(level, *limits)  # beyond the limits: on the edge
    fig, ax = new_axes(ax, figsize=(4.0, 3.6))
    stanford_regions(ax, alert_limit, limits)
    ax.plot(x, y, ".", ms=3, label=f"{label} ({counts.epochs})")
    if alarm is not None and np.any(alarm):
        alarm = np.asarray(alarm, bool)
        ax.plot(
            x[alarm],
            y[alarm],
            "o",
            ms=6,
            mfc="none",
            mec="k",
            lw=0.5,
            label=f"alarm ({counts.alarms})",
        )
    name = f"{axis} " if axis else ""
    ax.set(xlabel=f"{name}error [m]", ylabel=f"{name}protection level [m]")
    ax.set_title(
        f"nominal {counts.nominal}, MI {counts.misleading + counts.unavailable_misleading}, HMI {counts.hazardous}, "
        f"unavailable {counts.unavailable + counts.unavailable_misleading}",
        fontsize="small",
    )
    ax.legend(fontsize="x-small", loc="upper left")
    return fig


#: house style: ``COLUMN_WIDTH_IN`` wide at ``DPI`` (~800 px, as notebooks and docs show it); text in
#: ``FONT_PT`` (titles, axis labels) and ``SMALL_FONT_PT`` (ticks, legends, caption)
COLUMN_WIDTH_IN = 7.5
DPI = 110
FONT_PT = 9.0
SMALL_FONT_PT = 8.0
#: the colour of a hypothesis (mode, fault, method) that is no fault
NO_FAULT_COLOR = "0.25"
_NO_FAULT = {"none", "normal", "fault-free", "no fault", "nominal"}
_RUN_COUNT = re.compile(
    r"\b(\d[\d,]*|one|two|three|four|five|ten)\s+(\w+\s+){0,2}"
    r"(runs?|flights?|epochs?|trials?|realisations?|realizations?)\b",
    re.IGNORECASE,
)


def hypothesis_colors(names: Sequence[str]) -> dict[str, str]:
    """One colour per hypothesis across a study's panels and figures: fault-free (``none``, ``normal``, ...)
    dark grey, the others ``tab10`` in the order given (pass the study's full list, not a panel's).

    Returns:
      ``{name: colour}`` for every name.
    """
    from matplotlib import colormaps

    palette = colormaps["tab10"].colors
    colors, k = {}, 0
    for name in names:
        if str(name).lower() in _NO_FAULT:
            colors[name] = NO_FAULT_COLOR
        else:
            colors[name] = palette[k % len(palette)]
            k += 1
    return colors


def _check_figure(fig, caption: str) -> None:
    """House rules: every panel's axes labelled (or sharing a row/column neighbour's label), every labelled
    curve in a legend, the caption giving the number of runs (flights, epochs)."""
    if not _RUN_COUNT.search(caption):
        raise ValueError(
            f"caption: expected the number of runs (flights, epochs) the figure shows, got {caption!r}"
        )
    # a polar panel's angle and radius are named by its title
    panels = [
        ax
        for ax in fig.axes
        if ax.get_label() != "<colorbar>"
        and ax.get_subplotspec() is not None
        and ax.name != "polar"
    ]
    for axis in ("x", "y"):
        groups: dict = {}
        for ax in panels:
            spec = ax.get_subplotspec()
            key = tuple(spec.colspan) if axis == "x" else tuple(spec.rowspan)
            label = ax.get_xlabel() if axis == "x" else ax.get_ylabel()
            groups.setdefault(key, []).append(bool(label.strip()) or not ax.axison)
        if not all(any(labelled) for labelled in groups.values()):
            raise ValueError(f"fig: a panel without an {axis} label (what it shows, with its unit)")
    legends = [
        legend
        for legend in [*(ax.get_legend() for ax in panels), *fig.legends]
        if legend is not None
    ]
    shown = {text.get_text() for legend in legends for text in legend.get_texts()}
    labels = {label for ax in panels for label in ax.get_legend_handles_labels()[1]}
    if legends and labels - shown:
        raise ValueError(f"fig: curves {sorted(labels - shown)} are labelled but in no legend")


def _house_style(fig) -> None:
    """The figure one column wide (its aspect kept) and its text at the house sizes."""
    width, height = fig.get_size_inches()
    fig.set_size_inches(COLUMN_WIDTH_IN, height * COLUMN_WIDTH_IN / width)
    for ax in fig.axes:
        ax.title.set_fontsize(FONT_PT)
        ax.xaxis.label.set_fontsize(FONT_PT)
        ax.yaxis.label.set_fontsize(FONT_PT)
        ax.tick_params(labelsize=SMALL_FONT_PT)
        legend = ax.get_legend()
        if legend is not None:
            for text in legend.get_texts():
                text.set_fontsize(SMALL_FONT_PT)
    for legend in fig.legends:
        for text in legend.get_texts():
            text.set_fontsize(SMALL_FONT_PT)


def save_figure(fig, path, caption: str):
    """Write ``fig`` as a PNG at ``path`` (atomically) with ``caption`` under it (``caption_figure``).

    Returns:
      The ``pathlib.Path`` written.
    """
    return save_figures({Path(path).name: caption_figure(fig, caption)}, Path(path).parent)[0]


def caption_figure(fig, caption: str):
    """``fig`` in the house style at the house resolution (``DPI``) with ``caption`` under it (what it
    shows, over how many runs, how it differs from the paper's), wrapped to the figure's width;
    ``ValueError`` if the house rules (``_check_figure``) fail.

    Returns:
      ``fig``, ready to show in a notebook or to write (``save_figures``).
    """
    if not isinstance(caption, str) or not caption.strip():
        raise ValueError(
            f"caption: expected a sentence saying what the figure shows, got {caption!r}"
        )
    _check_figure(fig, caption)
    _house_style(fig)
    fig.set_dpi(DPI)
    width, height = fig.get_size_inches()
    lines = textwrap.wrap(
        " ".join(caption.split()), width=max(int(width * 72 / (0.55 * SMALL_FONT_PT)), 40)
    )
    bottom = min((len(lines) * SMALL_FONT_PT * 1.25 / 72 + 0.1) / height, 0.4)
    fig.text(
        0.01, 0.01, "\n".join(lines), ha="left", va="bottom", fontsize=SMALL_FONT_PT, wrap=False
    )
    engine = fig.get_layout_engine()
    if engine is not None and type(engine).__name__ == "ConstrainedLayoutEngine":
        engine.set(rect=(0.0, bottom, 1.0, 1.0 - bottom))
    else:
        fig.tight_layout(rect=(0.0, bottom, 1.0, 1.0))
    return fig
