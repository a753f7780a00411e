"""Gradient-based tuning with optax: a jitted training step, mini-batches, a validation set, early stopping,
progress, and parameters saved with their parameterisation.

The loss is any ``loss(raw, batch) -> scalar`` of the *unconstrained* parameters ``raw`` (a dict; map them with
``parameterize.constrain`` inside). Batches come from ``train_batch(step)``: freshly simulated labelled runs (keys
``jax.random.fold_in(key, step)`` of a training seed, so validation and test data from other seeds are never
trained on) or slices of a fixed dataset (``fixed_batches``). Only ``trainable`` names move; the others reach the
loss unchanged.

Long runs: ``checkpointed(filter)`` wraps a filter's step in ``jax.checkpoint``: the reverse pass recomputes each
step's internals instead of storing them (memory per step falls to the carried state; ``benchmarks/bench_tuning.py``).
"""

from __future__ import annotations

import json
import time
import zipfile
from pathlib import Path
from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax

from jaxfdi import checks
from jaxfdi._io.files import atomic_write
from jaxfdi._io.progress import logger, progress_bar
from jaxfdi.filters import Filter
from jaxfdi.tuning._parameterize import (
    Transform,
    constrain,
    from_record,
    merge,
    partition,
    unconstrain,
)


class TrainHistory(NamedTuple):
    """Training history: evaluated steps, training and validation losses, best step, early stop.

    Attributes:
      step: (E,) training step of each evaluation
      train_loss: (E,) training mini-batch loss at that step
      val_loss: (E,) validation loss at that step
      best_step: the step whose parameters are returned
      stopped_early: training stopped before ``steps``: no improvement for ``patience`` evaluations, or a
        non-finite loss or gradient
    """

    step: np.ndarray
    train_loss: np.ndarray
    val_loss: np.ndarray
    best_step: int
    stopped_early: bool


class TrainResult(NamedTuple):
    """What ``fit`` returns: the best unconstrained parameters and the training history.

    Attributes:
      raw: best unconstrained parameters (trainable and frozen)
      history: the losses over training
    """

    raw: dict
    history: TrainHistory


def checkpointed(filt: Filter) -> Filter:
    """The same filter with its steps rematerialised in the reverse pass.

    Returns:
      ``Filter`` equal to ``filt`` but for ``step``, ``update`` and ``predict`` (the halves a multiple-model filter
      built on it mixes between) and ``batch.step`` wrapped in ``jax.checkpoint`` where present: the same values,
      less memory and more compute in the gradient.
    """
    if getattr(filt, "batch", None) is not None:
        filt = filt._replace(batch=filt.batch._replace(step=jax.checkpoint(filt.batch.step)))
    halves = {
        name: jax.checkpoint(getattr(filt, name))
        for name in ("update", "predict")
        if getattr(filt, name, None) is not None
    }
    return filt._replace(step=jax.checkpoint(filt.step), **halves)


def fixed_batches(dataset: Any, batch_size: int, key: jax.Array) -> Callable[[int], Any]:
    """``step -> batch_size`` runs of ``dataset`` (leading run axis), reshuffled each epoch.

    Returns:
      ``batch(step) -> pytree`` like ``dataset`` with leaves of leading axis ``batch_size``: slice
      ``step mod (R // batch_size)`` of epoch ``step // (R // batch_size)``'s permutation (keyed
      ``fold_in(key, epoch)``) of the R runs; the last ``R mod batch_size`` runs of each permutation are unused.
    """
    num = {np.shape(leaf)[0] for leaf in jax.tree.leaves(dataset)}
    if len(num) != 1:
        raise ValueError(
            f"dataset: expected every leaf to have the same leading run axis, got sizes {sorted(num)}"
        )
    (num,) = num
    batch_size = checks.check_int("batch_size", batch_size, 1, num, "a number of runs per batch")
    if not 1 <= batch_size <= num:
        raise ValueError(f"batch_size: expected 1..{num} (the dataset's runs), got {batch_size}")
    per_epoch = num // batch_size

    def batch(step: int):
        epoch, i = divmod(step, per_epoch)
        order = jax.random.permutation(jax.random.fold_in(key, epoch), num)[
            i * batch_size : (i + 1) * batch_size
        ]
        return jax.tree.map(lambda leaf: leaf[order], dataset)

    return batch


def strongly_typed(tree):
    """``tree`` with every leaf a JAX array of its own dtype, no weak type: a Python-number parameter (or one made
    from it, e.g. ``jnp.full(5, 0.1)``) is weakly typed until one optimiser step, and a jitted function called with
    both compiles twice (the tuning CLI compiled its step three times per design).

    Returns:
      pytree of ``tree``'s structure, each leaf a strongly typed JAX array of its result type (a Python float:
      the default float dtype).
    """
    return jax.tree.map(lambda leaf: jnp.asarray(leaf, dtype=jnp.result_type(leaf)), tree)


def fit(
    loss: Callable[[dict, Any], jax.Array],
    raw0: dict,
    optimizer: optax.GradientTransformation,
    train_batch: Callable[[int], Any],
    val_batch: Any,
    steps: int,
    trainable: list[str] | None = None,
    eval_every: int = 10,
    patience: int = 5,
    progress: bool = False,
) -> TrainResult:
    """Minimise ``loss`` over the ``trainable`` entries of ``raw0`` (default: all).

    The validation loss is computed every ``eval_every`` steps (and at step 0 and the end); the parameters with the
    lowest are returned; training stops after ``patience`` evaluations without improvement, or at a non-finite loss
    or gradient (best parameters so far kept).

    Returns:
      ``TrainResult``: ``raw`` with ``raw0``'s keys (trainable entries at the lowest validation loss, frozen ones
      unchanged); ``history`` of the E evaluations (step 0 first, ``train_loss`` NaN there).
    """
    checks.check_callable("loss", loss, "a function (raw params, batch) -> scalar loss")
    checks.check_callable("train_batch", train_batch, "a function step -> batch")
    steps = checks.check_int("steps", steps, 0, meaning="a number of optimiser steps >= 0")
    eval_every = checks.check_int("eval_every", eval_every, 1, meaning="a number of steps >= 1")
    patience = checks.check_int("patience", patience, 1, meaning="a number of evaluations >= 1")
    params, frozen = partition(strongly_typed(raw0), list(raw0) if trainable is None else trainable)
    if not params:
        raise ValueError("trainable: expected at least one parameter to train")

    def full_loss(p, batch):
        return loss(merge(p, frozen), batch)

    @jax.jit
    def update(p, opt_state, batch):
        value, grads = jax.value_and_grad(full_loss)(p, batch)
        updates, opt_state = optimizer.update(grads, opt_state, p)
        finite = jnp.isfinite(value) & jnp.all(
            jnp.asarray([jnp.all(jnp.isfinite(g)) for g in jax.tree.leaves(grads)])
        )
        return optax.apply_updates(p, updates), opt_state, value, finite

    val_loss_fn = jax.jit(full_loss)
    opt_state = optimizer.init(params)
    first = val_loss_fn(params, val_batch)
    if jnp.shape(first) != ():
        raise ValueError(
            f"loss: expected a scalar loss (raw params, batch) -> (), got shape {jnp.shape(first)}"
        )
    best, best_val, best_step, bad = params, float(first), 0, 0
    log = {"step": [0], "train": [float("nan")], "val": [best_val]}
    start, stopped = time.perf_counter(), False
    bar = progress_bar("tuning", "steps") if progress else None  # a tqdm bar, or log lines
    for step in range(1, steps + 1):
        new, new_state, value, finite = update(params, opt_state, train_batch(step - 1))
        if not bool(finite):
            stopped = True
            if progress:
                logger.warning(
                    "tuning: non-finite loss or gradient at step %d; keeping step %d",
                    step,
                    best_step,
                )
            break
        params, opt_state = new, new_state
        if step % eval_every == 0 or step == steps:
            val = float(val_loss_fn(params, val_batch))
            log["step"].append(step), log["train"].append(float(value)), log["val"].append(val)
            if val < best_val:
                best, best_val, best_step, bad = params, val, step, 0
            else:
                bad += 1
            if progress:
                bar(
                    step,
                    steps,
                    time.perf_counter() - start,
                    postfix=f"train {float(value):.4g}, val {val:.4g} (best {best_val:.4g} at {best_step})",
                )
            if bad >= patience:
                stopped = True
                break
    if progress:
        bar.close()
    history = TrainHistory(
        np.asarray(log["step"]),
        np.asarray(log["train"]),
        np.asarray(log["val"]),
        best_step,
        stopped,
    )
    return TrainResult(merge(best, frozen), history)


def save_params(
    path: str | Path, raw: dict, parameterization: dict[str, Transform], meta: dict | None = None
) -> Path:
    """Write the constrained parameters, the parameterisation (transform names, options) and ``meta`` to ``.npz``
    or ``.json``, completely or not at all.

    Returns:
      the ``Path`` of the file written (``path``; its folder is created if missing).
    """
    path = Path(path)
    params = {
        k: np.asarray(v).tolist() if path.suffix == ".json" else np.asarray(v)
        for k, v in constrain(parameterization, raw).items()
    }
    record = {
        k: {"transform": t.name, "options": t.options}
        for k, t in parameterization.items()
        if k in raw
    }
    if path.suffix == ".json":

        def write(tmp):
            with open(tmp, "w") as fh:
                json.dump(
                    {"params": params, "parameterization": record, "meta": meta or {}}, fh, indent=1
                )
    elif path.suffix == ".npz":

        def write(tmp):
            with open(tmp, "wb") as fh:
                np.savez(
                    fh,
                    **{f"param/{k}": v for k, v in params.items()},
                    __record__=json.dumps({"parameterization": record, "meta": meta or {}}),
                )
    else:
        raise ValueError(f"path: expected a .json or .npz file name, got {path.name!r}")
    return atomic_write(path, write)


def load_params(path: str | Path) -> tuple[dict, dict[str, Transform], dict]:
    """Read a file written by ``save_params``; any other file (truncated, another format, a field missing) raises
    a ``ValueError`` naming the file and the problem.

    Returns:
      ``(raw, parameterization, meta)``: unconstrained parameters (dict of JAX arrays, ``unconstrain`` of the saved
      values), ``name -> Transform`` rebuilt from the recorded names and options, and the saved ``meta`` dict.
    """
    path = Path(path)
    if path.suffix not in (".json", ".npz"):
        raise ValueError(f"path: expected a .json or .npz file name, got {path.name!r}")
    try:
        if path.suffix == ".json":
            data = json.loads(path.read_text())
            params, record, meta = data["params"], data["parameterization"], data["meta"]
        else:
            with np.load(path) as data:
                extra = json.loads(str(data["__record__"]))
                params = {k[len("param/") :]: data[k] for k in data.files if k.startswith("param/")}
            record, meta = extra["parameterization"], extra["meta"]
        parameterization = {k: from_record(v["transform"], v["options"]) for k, v in record.items()}
        params = {k: jnp.asarray(v) for k, v in params.items()}
    except FileNotFoundError:
        raise
    except (OSError, ValueError, KeyError, TypeError, AttributeError, zipfile.BadZipFile) as error:
        what = (
            f"missing field {error}"
            if isinstance(error, KeyError)
            else f"{type(error).__name__}: {error}"
        )
        raise ValueError(f"{path}: not a parameter file written by save_params ({what})") from None
    return unconstrain(parameterization, params), parameterization, meta
