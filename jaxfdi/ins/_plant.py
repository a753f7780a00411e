"""A UAV's GPS receiver and IMU as one loop plant, one step per GPS epoch.

Step ``k`` (``t_k = t0 + k`` s) measures:

- ``gnss.receiver_plant``'s pseudoranges at ``t_k`` (light time, Earth rotation, clocks,
  elevation-dependent noise, satellite faults per slot);
- the velocity solution: true NED velocity + white noise ``velocity_sigma`` per axis (simulated in the
  solution domain, no Doppler: satellite faults do not reach it);
- the ``n`` IMU samples of ``[t_k, t_k+1)`` (``imu.measure``: turn-on biases, white noise, scale
  factors), IMU faults applied to each.

IMU faults: ``jaxfdi.fault(kind, "sensor", component, onset, magnitude, ...)`` on the sample
``[f_x, f_y, f_z (m/s^2), w_x, w_y, w_z (rad/s)]`` (roll-gyro bias 30 deg/h from 800 s:
``fault("bias", "sensor", 3, 800, radians(30) / 3600)``); onset, end and ramp slope count epochs (s); a fault acts on
every sample of an active epoch. STUCK holds the onset epoch's first (live) sample from the second on; DEAD is NaN from
the onset epoch's first sample. Truth (``GpsInsTruth``) comes back in ``Sensed.state``.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from jaxfdi import checks
from jaxfdi._simulation.faults import (
    Fault,
    FaultKind,
    Target,
    active_label,
    apply_faults,
    as_stack,
    is_active,
    no_fault,
)
from jaxfdi._simulation.simulate import SimState
from jaxfdi._simulation.stages import Plant
from jaxfdi.gnss import ClockModel, OrbitTable, geodetic_to_ecef, receiver_plant
from jaxfdi.ins import _imu as imu
from jaxfdi.ins._imu import ImuErrors, ImuModel
from jaxfdi.ins._mechanization import NavState
from jaxfdi.ins._trajectory import Trajectory

IMU_CHANNELS = 6


class GpsInsMeasurement(NamedTuple):
    """What the GPS/INS plant measures at one epoch.

    Attributes:
      pseudoranges: (S,) m, NaN where not measured
      velocity: (3,) receiver velocity solution, NED [m/s]
      imu: (n, 6) samples of [t_k, t_k+1)
    """

    pseudoranges: Array
    velocity: Array
    imu: Array


class GpsInsTruth(NamedTuple):
    """The true state of the GPS/INS plant at one epoch.

    Attributes:
      nav: the true navigation state at t_k
      accel_bias: (3,) accelerometer bias [m/s^2]
      gyro_bias: (3,) gyro bias [rad/s]
      clock: (2,) receiver clock bias [m], drift [m/s]
    """

    nav: NavState
    accel_bias: Array
    gyro_bias: Array
    clock: Array


class GpsInsPlantState(NamedTuple):
    """The GPS/INS plant's carry.

    Attributes:
      receiver: the receiver's simulator state (clock)
      imu: the IMU's current systematic errors
      held: (F_imu,) the value a STUCK IMU fault holds (apply_faults)
    """

    receiver: SimState
    imu: ImuErrors
    held: Array


class GpsInsSensed(NamedTuple):
    """One epoch of the GPS/INS plant: the truth, the measurement and the active faults.

    Attributes:
      state: the truth at t_k
      measurement: what the receiver and the IMU measure
      fault_active: (F_sat + F_imu,) bool, the faults active at this epoch
      mode: () int, label of the first active fault (satellite faults first)
    """

    state: GpsInsTruth
    measurement: GpsInsMeasurement
    fault_active: Array
    mode: Array


class FlightTables(NamedTuple):
    """A flight as the plant reads it, per GPS epoch (T epochs, n IMU samples each).

    Attributes:
      position: (T, 3) lat, lon [rad], h [m] at t_k
      velocity: (T, 3) NED [m/s]
      attitude: (T, 4) body-to-NED quaternion
      imu: (T, n, 6) error-free samples of [t_k, t_k+1)
    """

    position: Array
    velocity: Array
    attitude: Array
    imu: Array


def flight_tables(trajectory: Trajectory, epochs: int) -> FlightTables:
    """The first ``epochs`` GPS epochs (1 Hz) of a flight sampled at an integer IMU rate.

    Returns:
      ``FlightTables``: the truth at each whole second ``t_k = k`` s, (T, 3), (T, 3), (T, 4), and the error-free
      IMU samples of each second, (T, n, 6), ``n = 1 / trajectory.dt``; ``T = epochs``.
    """
    epochs = checks.check_int("epochs", epochs, 1, meaning="a positive number of GPS epochs")
    rate = 1.0 / trajectory.dt
    per_epoch = int(round(rate))
    if abs(rate - per_epoch) > 1e-9 or trajectory.imu.shape[0] < epochs * per_epoch:
        raise ValueError(
            f"trajectory: expected an integer IMU rate and at least {epochs} s of samples, got "
            f"{rate} Hz and {trajectory.imu.shape[0] / rate} s"
        )
    index = np.arange(epochs) * per_epoch
    return FlightTables(
        trajectory.position[index],
        trajectory.velocity[index],
        trajectory.attitude[index],
        trajectory.imu[: epochs * per_epoch].reshape(epochs, per_epoch, IMU_CHANNELS),
    )


def gps_ins_plant(
    table: OrbitTable,
    t0: float,
    flight: FlightTables,
    visible: Array,
    sigma: Array,
    model: ImuModel,
    velocity_sigma: float = 0.1,
    clock: ClockModel = ClockModel(),
    satellite_fault: Fault | None = None,
    imu_fault: Fault | None = None,
) -> Plant:
    """The plant of the module doc.

    Args:
      table, t0: orbits and the time tag of epoch 0 [s of the table's week].
      flight: the truth per epoch and the error-free IMU samples (``flight_tables``):
        T epochs of n samples, ``1 / n`` s apart.
      visible, sigma: (T, S) slots measured and their pseudorange sigmas [m].
      model: the IMU's error model (``imu.hg1900()``).
      velocity_sigma: 1-sigma of the velocity solution per axis [m/s].
      clock: the receiver oscillator.
      satellite_fault: sensor faults on satellite slots (``receiver_plant``).
      imu_fault: sensor faults on the IMU's 6 channels (module doc).

    Returns:
      ``Plant(init, measure, advance, horizon = T)``, one step per GPS epoch: ``init((clock0 (2,), ImuErrors))``
      (``imu.draw_errors``) -> ``GpsInsPlantState``; ``measure(state, k, u, step_key) -> (state,
      GpsInsSensed)``; ``advance(state, k, u, step_key) -> (state, Actuated)`` moves the receiver clock
      and walks the IMU biases one epoch (``u`` passed through, no actuator fault).
    """
    checks.check_shape(
        "flight.imu", flight.imu, (None, None, IMU_CHANNELS), "T epochs x n samples x 6"
    )
    per_epoch = flight.imu.shape[1]
    checks.check_positive("velocity_sigma", velocity_sigma, "a velocity sigma in m/s")
    imu_faults = as_stack(no_fault() if imu_fault is None else imu_fault)
    kinds, targets, components = (
        checks.concrete(leaf) for leaf in (imu_faults.kind, imu_faults.target, imu_faults.component)
    )
    if (
        kinds is not None
        and targets is not None
        and components is not None
        and np.any(
            (kinds != FaultKind.NONE) & ((targets != Target.SENSOR) | (components >= IMU_CHANNELS))
        )
    ):
        raise ValueError(
            f"imu_fault: expected sensor faults on components 0..5 of [f_x, f_y, f_z, w_x, w_y, w_z], "
            f"got targets {targets.tolist()} and components {components.tolist()}"
        )
    positions, velocities, attitudes, true_samples = flight
    path_ecef = geodetic_to_ecef(positions[:, 0], positions[:, 1], positions[:, 2])
    receiver = receiver_plant(table, t0, 1.0, path_ecef, visible, sigma, clock, satellite_fault)
    num_imu_faults = imu_faults.kind.shape[0]
    dt = 1.0 / per_epoch

    def init(x0) -> GpsInsPlantState:
        clock0, errors = x0
        state = receiver.init(clock0)
        errors = jax.tree_util.tree_map(lambda a: jnp.asarray(a, state.state.dtype), errors)
        return GpsInsPlantState(state, errors, jnp.zeros((num_imu_faults,), state.state.dtype))

    def faulty_samples(samples, k, held):
        """The epoch's samples with IMU faults, and held values: STUCK holds the onset epoch's first sample
        on every later sample (``apply_faults`` alone would hold per epoch)."""
        first, held = apply_faults(imu_faults, k, samples[0], Target.SENSOR, held)
        rest = jax.vmap(lambda sample: apply_faults(imu_faults, k, sample, Target.SENSOR, held)[0])(
            samples[1:]
        )
        stuck = (imu_faults.kind == FaultKind.STUCK) & jax.vmap(is_active, in_axes=(0, None))(
            imu_faults, k
        )
        on_channel = stuck[:, None] & (
            imu_faults.component[:, None] == jnp.arange(IMU_CHANNELS)
        )  # (F, 6)
        value = held[jnp.argmax(on_channel, axis=0)]  # (6,)
        rest = jnp.where(jnp.any(on_channel, axis=0), value, rest)
        return jnp.concatenate([first[None], rest]), held

    def measure(state: GpsInsPlantState, k: Array, u: Array, step_key: Array):
        receiver_state, sensed = receiver.measure(state.receiver, k, u, step_key)
        key_imu, key_velocity = jax.random.fold_in(step_key, 7), jax.random.fold_in(step_key, 8)
        samples = imu.measure(true_samples[k], state.imu, key_imu, model, dt)
        samples, held = faulty_samples(samples, k, state.held)
        velocity = velocities[k] + velocity_sigma * jax.random.normal(
            key_velocity, (3,), velocities.dtype
        )
        imu_active = jax.vmap(is_active, in_axes=(0, None))(imu_faults, k)
        imu_mode = active_label(imu_faults, k, 0)
        mode = jnp.where(sensed.mode > 0, sensed.mode, imu_mode)
        truth = GpsInsTruth(
            NavState(positions[k], velocities[k], attitudes[k]),
            state.imu.accel_bias,
            state.imu.gyro_bias,
            receiver_state.state,
        )
        measurement = GpsInsMeasurement(sensed.measurement, velocity, samples)
        return (
            state._replace(receiver=receiver_state, held=held),
            GpsInsSensed(
                truth, measurement, jnp.concatenate([sensed.fault_active, imu_active]), mode
            ),
        )

    def advance(state: GpsInsPlantState, k: Array, u: Array, step_key: Array):
        receiver_state, moved = receiver.advance(state.receiver, k, u, step_key)
        errors = imu.walk_biases(state.imu, jax.random.fold_in(step_key, 9), model, per_epoch * dt)
        return GpsInsPlantState(receiver_state, errors, state.held), moved

    return Plant(init, measure, advance, flight.imu.shape[0])
