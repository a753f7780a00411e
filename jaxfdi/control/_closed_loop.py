"""A reconfigurable PI controller for fault-tolerant control (Lee & Lyou, eqs. 22-29): the
LQR-PI state feedback ``u = -K [x_hat; z]`` on an estimate, switched to the
eigenstructure-assignment gain for ``B_f = B (I - diag(b))`` (a ``GainSchedule``
tabulated once, ``control.eigenstructure``) while an actuator effectiveness loss ``b`` is
isolated, with an isolated additive actuator fault compensated by adding its estimate to
``u``. It reads a ``Reconfiguration`` from the FDI stage of a ``jaxfdi._loop`` closed loop;
the VTOL loop of Lee & Lyou that feeds it is ``jaxfdi.scenarios.vtol_loop``.
"""
from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
from jax import Array

from jaxfdi import _linalg
from jaxfdi.control._eigenstructure import GainSchedule, scheduled_gain
from jaxfdi._stages import Controller


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


def reconfigurable_pi(gain: Array, schedule: GainSchedule, H: Array, command: Array, Ts: float,
                      dtype=None) -> Controller:
    """The PI state feedback of eq. 22, ``u = -K [x_hat; z] (+ additive fix)``, with the
    nominal ``gain`` K (nu, n + g), or the eigenstructure-assignment gain ``scheduled_gain``
    of ``schedule`` while an effectiveness loss is isolated; integrator
    ``z[k+1] = z[k] + Ts (command - H x_hat[k|k])`` on the tracked outputs ``H`` (g, n).
    It reads the FDI's view as a pair ``(Reconfiguration, anything)``; its state is ``z``
    (g,), of ``dtype`` (default: the gain's).

    Returns:
      ``Controller(init, step)`` (not feed-forward): ``init()`` gives ``z = 0`` (g,);
      ``step(z, k, view, exogenous) -> (z[k+1], u[k])`` with ``u`` (nu,) and
      ``exogenous`` unused.
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
