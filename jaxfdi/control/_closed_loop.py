"""A reconfigurable PI controller for fault-tolerant control (Lee & Lyou, eqs. 22-29), fed a
``Reconfiguration`` by a ``jaxfdi._simulation.loop`` FDI stage (the VTOL loop: ``jaxfdi.scenarios.vtol_loop``).
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
from jax import Array

from jaxfdi._numerics import linalg as _linalg
from jaxfdi._simulation.stages import Controller
from jaxfdi.control._eigenstructure import GainSchedule, scheduled_gain


class Reconfiguration(NamedTuple):
    """What a reconfiguring FDI stage gives the controller at step ``k`` (e.g. the TSKF bank of
    Lee and Lyou, ``scenarios.vtol_loop.tskf_bank_fdi``).

    Attributes:
      estimate: (n,) x_hat[k|k] from the (compensated) measurement
      loss: () isolated effectiveness loss of ``component`` (0: none / FTC off)
      component: () int, the isolated input (meaningful when ``loss > 0`` or ``additive != 0``)
      additive: (nu,) estimate of an isolated additive actuator fault, to add to u
    """

    estimate: Array
    loss: Array
    component: Array
    additive: Array


def reconfigurable_pi(
    gain: Array, schedule: GainSchedule, H: Array, command: Array, Ts: float, dtype=None
) -> Controller:
    """PI state feedback of eq. 22, ``u = -K [x_hat; z]`` plus an isolated additive actuator fault's estimate;
    ``K`` the nominal ``gain`` (nu, n + g), or while an effectiveness loss ``b`` is isolated the
    eigenstructure gain for ``B_f = B (I - diag(b))`` (``scheduled_gain`` of the once-tabulated
    ``schedule``); ``z[k+1] = z[k] + Ts (command - H x_hat[k|k])``, tracked outputs ``H`` (g, n). View: a pair
    ``(Reconfiguration, anything)``; state ``z`` (g,) of ``dtype`` (default: the gain's).

    Returns:
      ``Controller(init, step)`` (not feed-forward): ``init()`` gives ``z = 0`` (g,);
      ``step(z, k, view, exogenous) -> (z[k+1], u[k])`` with ``u`` (nu,) and ``exogenous`` unused.
    """
    g = H.shape[0]
    dtype = dtype or gain.dtype
    mm = _linalg.matmul

    def step(z: Array, k: Array, observed, exogenous):
        view, _ = observed
        K = jnp.where(view.loss > 0, scheduled_gain(schedule, view.component, view.loss), gain)
        u = -mm(K, jnp.concatenate([view.estimate, z])) + view.additive
        return z + Ts * (command - mm(H, view.estimate)), u

    return Controller(lambda: jnp.zeros((g,), dtype), step)


__all__ = ["Reconfiguration", "reconfigurable_pi"]
