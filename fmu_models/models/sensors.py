"""Sensors and links as FMUs: noise, bias, sample-and-hold and transport delay.

One generic sampled-data model family, :func:`sensors_model`, with N
channels; its members (``docs/sensors.md``):

* ``Measurement12``: the measurement path, plant -> controller. Inputs the 12
  rigid-body states ``x y z u v w phi theta psi p q r``, outputs the measured
  ``x_m ... r_m`` (an OptiTrack-like pose/velocity feed);
* ``CommandLink4``: the command path, controller -> plant (the paper's Wi-Fi
  link). Inputs ``Omega_1..4``, outputs the received ``Omega_1_rx..4_rx``;
  a link: packets can be lost;
* ``VelocityLink3``: the velocity-command path, outer loop -> on-board
  velocity controller (the AR.Drone's Wi-Fi). Inputs ``v_ref_x, v_ref_y,
  v_ref_z``, the desired velocity v* of eq. 26 (m/s, world frame, z down),
  outputs ``v_ref_x_rx ..``; a link: packets can be lost;
* ``GNSS6``: a GNSS receiver, plant -> estimator. Inputs ``x y z u v w``,
  outputs ``x_m .. w_m``, ``fresh`` (1 on the step a new fix arrives,
  ``fresh=True`` below; docs/estimation.md);
* ``Mocap9``: a motion capture (OptiTrack), plant -> estimator. Inputs
  ``x y z u v w phi theta psi``, outputs ``x_m .. psi_m``, ``fresh`` and the
  frame's ``t_sample`` (``fresh=True``): the rigid body's pose and velocity
  in one frame (issue 29, docs/sensors.md);
* ``GNSS6GM``: ``GNSS6`` whose errors are also correlated in time, a
  first-order Gauss-Markov error per channel (``correlated=True`` below; E25
  of docs/estimation.md)::

    e_{n+1} = a e_n + sigma_gm sqrt(1 - a^2) w_n,  a = exp(-dt / gm_tau),  e_0 ~ N(0, sigma_gm^2)
    m_n     = u_n + sigma_i w_n + bias_i + e_n

Per communication step n (``t_n = n dt``), channel i, with ``u`` the input::

    w_n     = sqrt(-2 ln(1 - r1)) cos(2 pi r2)                 Box-Muller, r1, r2 ~ U[0, 1)
    m_n     = u_n + sigma_i w_n + bias_i                       noise, then bias
    s_n     = m_n if c_n = 0 else s_{n-1}                      sample-and-hold
    y_n     = s_{n - delay_steps}                              transport delay
    c_{n+1} = (c_n + 1) mod N_hold,  c_0 = 0
    N_hold  = max(1, floor(1 / (sample_rate dt) + 1/2))        (1 if sample_rate = 0)

``r1, r2`` are channel i's two of the ``2 N`` uniform numbers the FMU draws
per step from numpy's ``default_rng(seed)`` (channel order, r1 first); they are
drawn every step, sampled or not, so the stream never depends on the
parameters. Before the first ``delay_steps`` samples exist, the delay line
holds the first sample ``s_0`` (so ``y_n = s_0`` for ``n < delay_steps``).
Outputs have direct feedthrough: with ``delay_steps = 0`` and a sample due,
a get after setting the inputs of ``t_n`` returns ``y_n`` computed from them.

A link (``loss=True``: ``CommandLink4``, ``VelocityLink3``) also loses
packets. One packet per step carries all channels; with ``p_loss`` the
parameter ``loss_probability`` and ``y'_n`` the output above::

    L_n     = 1 if r_L < p_loss else 0                         packet lost, r_L ~ U[0, 1)
    y_n     = y_{n-1} if L_n = 1 else y'_n                     a lost packet never arrives
    y_{-1}  = s_0                                              the receiver starts with the first sample

``r_L`` is one more uniform number per step, drawn after the channels' 2N
(2N + 1 per step in all). A loss is decided at arrival and touches only the
receiver: the sampler and the delay line go on as without loss (the packet
that would have arrived at step n carried ``s_{n - delay_steps}``), so the
next delivered packet is the one sent ``delay_steps`` steps before it, not a
stale one. ``packets_lost`` counts the losses. A model without loss
(``Measurement12``) has neither the parameter nor the draw: its stream and
its FMU are those of a build before links could lose packets.
"""
from __future__ import annotations

import math
from typing import Sequence

from fmu_models.lazy_casadi import ca

from ..export.model import FmuModel, Sampled
from ..export.variables import discrete, input_, output, parameter, seed_parameter
from .quadrotor import QUADROTOR, STATE_NAMES

__all__ = ["sensors_model", "MEASUREMENT_12", "COMMAND_LINK_4", "VELOCITY_LINK_3", "GNSS_6", "GNSS_6_GM", "MOCAP_9",
           "DELAY_MAX",
           "SAMPLE_RATE_MAX",
           "hold_period", "hold_steps", "gaussian"]

DELAY_MAX = 20            # samples: the length of the delay line, fixed at build
SAMPLE_RATE_MAX = 1.0e6   # Hz
DT_DEFAULT = 0.01         # s: the project's communication step


def hold_period(sample_rate, dt):
    """Communication steps per sample: ``max(1, floor(1 / (sample_rate dt) + 1/2))``,
    1 for ``sample_rate = 0``; numbers or CasADi expressions (the FMU's law)."""
    return ca.if_else(sample_rate > 0, ca.fmax(1.0, ca.floor(1.0 / (sample_rate * dt) + 0.5)), 1.0)


def hold_steps(sample_rate: float, dt: float) -> int:
    """:func:`hold_period` as a Python integer."""
    return int(hold_period(ca.DM(sample_rate), ca.DM(dt)))


def gaussian(r1, r2):
    """Box-Muller: a standard normal number from two uniform ones in [0, 1).
    ``1 - r1`` is in (0, 1], so the logarithm is finite (guards r1 = 0)."""
    return ca.sqrt(-2.0 * ca.log(1.0 - r1)) * ca.cos(2.0 * math.pi * r2)


def _tap(line, delay):
    """The tap of a delay line selected by the integer ``delay`` (0: the first)."""
    y = line[0]
    for j in range(1, len(line)):
        y = ca.if_else(delay == j, line[j], y)
    return y


def sensors_model(identifier: str, description: str, channels: Sequence[tuple[str, str, str, float]],
                  suffix: str, delay_max: int = DELAY_MAX, loss: bool = False, fresh: bool = False,
                  correlated: bool = False) -> FmuModel:
    """A sensor/link model with one channel per ``(name, unit, description,
    input start)``: input ``name``, output ``name + suffix``, parameters
    ``sigma_<name>``, ``bias_<name>`` and the shared ``sample_rate``,
    ``delay_steps`` (0..``delay_max``), ``seed``, ``dt``.

    ``loss=True`` makes it a link that loses packets (the module docstring's
    law): the parameter ``loss_probability`` (1, in [0, 1]), one more uniform
    number per step after the channels' 2N, and the discrete states
    ``delivered_<name>`` (the receiver's last value) and ``packets_lost``.
    ``loss=False`` builds exactly the model it built before links existed.

    ``fresh=True`` adds the output ``fresh``: 1 at the steps where a new
    sample reaches the output (the sample flag ``c_n = 0`` through the same
    delay line, 0 where the line is still filled with ``s_0``), 0 while the
    output holds an old one; an estimator corrects only on it; and the output
    ``t_sample``, the time the delivered sample was taken (through the same
    hold and delay line), at which an estimator fuses it. The model without
    it is exactly the one before.

    ``correlated=True`` (with ``fresh``) adds to each channel a first-order
    Gauss-Markov error (docs/estimation.md, E25): the parameters ``gm_tau``
    and ``gm_sigma_<name>``, 2N more uniform numbers per step after the
    channels' 2N; the model without it is exactly the one before."""
    if correlated and not fresh:
        raise ValueError(f"sensors_model {identifier}: correlated=True needs fresh=True (a receiver's model)")
    names = [c[0] for c in channels]
    units = {c[0]: c[1] for c in channels}
    delivered = "noise, bias, hold, delay, loss" if loss else "noise, bias, hold, delay"
    variables = [
        *(input_(name, unit, f"true value: {text}", start) for name, unit, text, start in channels),
        *(output(name + suffix, unit, f"as delivered ({delivered}): {text}")
          for name, unit, text, _ in channels),
        *(parameter(f"sigma_{name}", units[name], f"standard deviation of the Gaussian noise on {name}",
                    0.0, min=0.0) for name in names),
        *(parameter(f"bias_{name}", units[name], f"constant bias added to {name} (after the noise)", 0.0)
          for name in names),
        parameter("sample_rate", "1/s",
                  "sample rate (Hz); a new sample every max(1, round(1 / (sample_rate dt))) steps, "
                  "held in between; 0: a sample every step", 0.0, min=0.0, max=SAMPLE_RATE_MAX),
        parameter("delay_steps", "1",
                  f"transport delay in whole communication steps (an integer 0..{delay_max})",
                  0.0, min=0.0, max=float(delay_max), integer=True),
        seed_parameter("seed", "seed of numpy's default_rng that draws the noise (2 numbers per channel "
                       "and step)" + (", then the packet loss (1 number per step)" if loss else "")),
        parameter("dt", "s", "communication step = sample period of the FMU (every doStep must be dt)",
                  DT_DEFAULT, min=1e-6, max=10.0),
        discrete("sample_counter", "1", "steps since the last sample (0: a sample is taken this step)"),
        discrete("started", "1", "0 before the first step, 1 after (the delay line is filled)"),
        *(discrete(f"held_{name}", units[name], f"last sample of {name} (noise and bias included)")
          for name in names),
        *(discrete(f"{name}_delay_{j}", units[name], f"sample of {name} {j} step(s) ago")
          for j in range(1, delay_max + 1) for name in names),
    ]
    if loss:  # appended, so that the variables above keep their value references
        variables += [
            parameter("loss_probability", "1",
                      "probability that a step's packet (all channels) is lost; the receiver then holds "
                      "the last delivered value", 0.0, min=0.0, max=1.0),
            *(discrete(f"delivered_{name}", units[name], f"last value of {name} the receiver got")
              for name in names),
            discrete("packets_lost", "1", "packets lost since the start"),
        ]
    if fresh:  # appended, as the loss' variables
        variables += [
            output("fresh", "1", "1 when a new sample reaches the output this step (after the delay), else 0"),
            *(discrete(f"fresh_delay_{j}", "1", f"sample flag {j} step(s) ago") for j in range(1, delay_max + 1)),
            output("t_sample", "s", "time the delivered sample was taken (the FMU's time when it sampled its "
                                    "inputs): an estimator fuses it at that time (docs/estimation.md, \"Timing\")"),
            discrete("held_t_sample", "s", "time of the last sample"),
            *(discrete(f"t_sample_delay_{j}", "s", f"time of the sample {j} step(s) ago")
              for j in range(1, delay_max + 1)),
        ]
    if correlated:  # appended, as the fresh flag's: the errors correlated in time (issue 29), E25
        variables += [
            parameter("gm_tau", "s", "correlation time of the Gauss-Markov error (E25)", 60.0, min=1e-6),
            *(parameter(f"gm_sigma_{name}", units[name], f"stationary standard deviation of the Gauss-Markov "
                        f"error on {name} (E25); 0: none", 0.0, min=0.0) for name in names),
            *(discrete(f"gm_{name}", units[name], f"the Gauss-Markov error on {name} this step") for name in names),
        ]
    n_channel_random = 2 * len(names)  # the noise's numbers per step; the loss draw, if any, comes after
    # a correlated model draws 2N more after the channels' (the Gauss-Markov errors', E25)

    def update(t, v, rs):
        n_hold = hold_period(v["sample_rate"], v["dt"])
        counter, started, delay = v["sample_counter"], v["started"], v["delay_steps"]
        sample = counter == 0
        out, nxt = {}, {"sample_counter": ca.if_else(counter + 1 >= n_hold, 0.0, counter + 1), "started": 1.0}
        if loss:
            lost = rs[n_channel_random] < v["loss_probability"]  # r_L < p_loss: p_loss = 0 never, 1 always
            nxt["packets_lost"] = v["packets_lost"] + ca.if_else(lost, 1.0, 0.0)
        if fresh:
            flags = [ca.if_else(sample, 1.0, 0.0)] + [ca.if_else(started > 0, v[f"fresh_delay_{j}"], 0.0)
                                                      for j in range(1, delay_max + 1)]
            flag = flags[0]
            for j in range(1, delay_max + 1):
                flag = ca.if_else(delay == j, flags[j], flag)
            out["fresh"] = flag
            nxt.update({f"fresh_delay_{j}": flags[j - 1] for j in range(1, delay_max + 1)})
            # the sample's own time through the same hold and delay line: the delivered value's age
            stamp = ca.if_else(sample, t, v["held_t_sample"])
            stamps = [stamp] + [ca.if_else(started > 0, v[f"t_sample_delay_{j}"], stamp)
                                for j in range(1, delay_max + 1)]
            out["t_sample"] = _tap(stamps, delay)
            nxt["held_t_sample"] = stamp
            nxt.update({f"t_sample_delay_{j}": stamps[j - 1] for j in range(1, delay_max + 1)})
        if correlated:
            # E25: e_{n+1} = a e_n + sigma_gm sqrt(1 - a^2) w_n, a = exp(-dt / tau); e_0 = sigma_gm w'_0, stationary,
            # w'_0 the Box-Muller pair's other (sine) normal of the first step's numbers, independent of w_0
            decay = ca.exp(-v["dt"] / v["gm_tau"])
            gm = {}
            for i, name in enumerate(names):
                r1, r2 = rs[n_channel_random + 2 * i], rs[n_channel_random + 2 * i + 1]
                w = gaussian(r1, r2)
                w_start = ca.sqrt(-2.0 * ca.log(1.0 - r1)) * ca.sin(2.0 * math.pi * r2)
                gm[name] = ca.if_else(started > 0, v[f"gm_{name}"], v[f"gm_sigma_{name}"] * w_start)
                nxt[f"gm_{name}"] = decay * gm[name] + v[f"gm_sigma_{name}"] * ca.sqrt(1 - decay ** 2) * w
        for i, name in enumerate(names):
            measured = v[name] + v[f"sigma_{name}"] * gaussian(rs[2 * i], rs[2 * i + 1]) + v[f"bias_{name}"]
            if correlated:
                measured = measured + gm[name]
            s = ca.if_else(sample, measured, v[f"held_{name}"])
            line = [s] + [ca.if_else(started > 0, v[f"{name}_delay_{j}"], s) for j in range(1, delay_max + 1)]
            y = line[0]  # one tap selected by the integer delay_steps
            for j in range(1, delay_max + 1):
                y = ca.if_else(delay == j, line[j], y)
            if loss:
                # before the first step the receiver holds s_0, as the delay line does: y_{-1} = s_0
                previous = ca.if_else(started > 0, v[f"delivered_{name}"], s)
                y = ca.if_else(lost, previous, y)
                nxt[f"delivered_{name}"] = y
            out[name + suffix] = y
            nxt[f"held_{name}"] = s
            for j in range(1, delay_max + 1):
                nxt[f"{name}_delay_{j}"] = line[j - 1]
        return out, nxt

    def initial(v, r):
        z0 = {"sample_counter": 0.0, "started": 0.0}
        z0.update({f"held_{name}": 0.0 for name in names})
        z0.update({f"{name}_delay_{j}": 0.0 for j in range(1, delay_max + 1) for name in names})
        if loss:
            z0.update({f"delivered_{name}": 0.0 for name in names})
            z0["packets_lost"] = 0.0
        if fresh:
            z0.update({f"fresh_delay_{j}": 0.0 for j in range(1, delay_max + 1)})
            z0.update({"held_t_sample": 0.0, **{f"t_sample_delay_{j}": 0.0 for j in range(1, delay_max + 1)}})
        if correlated:
            z0.update({f"gm_{name}": 0.0 for name in names})
        return z0

    return FmuModel(
        identifier=identifier,
        description=description,
        variables=tuple(variables),
        sampled=Sampled(update=update, initial=initial, n_random=0, seed="seed", sample_period="dt",
                        n_random_step=n_channel_random + (1 if loss else 0) + (n_channel_random if correlated else 0)),
    )


def _plant_channels(names) -> list[tuple[str, str, str, float]]:
    """The channels of a sensor of the plant's states: each state's name, unit and description, starting at 0."""
    return [(name, QUADROTOR.variable(name).unit, QUADROTOR.variable(name).description, 0.0) for name in names]


MEASUREMENT_12 = sensors_model(
    "Measurement12",
    "measurement path (plant states -> controller): per-state Gaussian noise, bias, sample-and-hold at "
    "sample_rate and a transport delay of delay_steps communication steps; seeded; z axis down",
    _plant_channels(STATE_NAMES),
    suffix="_m",
)

COMMAND_LINK_4 = sensors_model(
    "CommandLink4",
    "command path (controller -> plant rotor speeds, a radio link): per-rotor Gaussian noise, bias, "
    "sample-and-hold at sample_rate, a transport delay of delay_steps communication steps and packet loss "
    "with loss_probability per step (the last delivered command held); seeded",
    [(f"Omega_{i}", "rad/s", f"commanded speed of rotor {i}", QUADROTOR.variable(f"Omega_{i}").start)
     for i in range(1, 5)],
    suffix="_rx",
    loss=True,
)

VELOCITY_LINK_3 = sensors_model(
    "VelocityLink3",
    "velocity-command path (outer loop -> on-board velocity controller, the AR.Drone's Wi-Fi): per-axis "
    "Gaussian noise, bias, sample-and-hold at sample_rate, a transport delay of delay_steps communication "
    "steps and packet loss with loss_probability per step (the last delivered command held); seeded",
    [(f"v_ref_{a}", "m/s", f"desired velocity v* along {a} (eq. 26; world frame, z down)", 0.0) for a in "xyz"],
    suffix="_rx",
    loss=True,
)

GNSS_6 = sensors_model(
    "GNSS6",
    "GNSS receiver (plant -> estimator): position and velocity with Gaussian noise, sampled at sample_rate "
    "(5-10 Hz), held, delivered delay_steps communication steps late (the receiver's latency), with a fresh "
    "flag set when a new fix arrives; seeded; z axis down",
    _plant_channels(STATE_NAMES[:6]),
    suffix="_m",
    fresh=True,
)

GNSS_6_GM = sensors_model(
    "GNSS6GM",
    "GNSS receiver (plant -> estimator) whose errors are correlated in time: GNSS6's white noise, hold, "
    "latency and fresh flag, plus a first-order Gauss-Markov error per channel (gm_tau, gm_sigma_*); seeded; "
    "z axis down",
    _plant_channels(STATE_NAMES[:6]),
    suffix="_m",
    fresh=True,
    correlated=True,
)

MOCAP_9 = sensors_model(
    "Mocap9",
    "motion capture (plant -> estimator; OptiTrack): the rigid body's pose and velocity, position, velocity and "
    "Euler angles with Gaussian noise, sampled at sample_rate, with a fresh flag and the frame's time; seeded; "
    "z axis down",
    _plant_channels(STATE_NAMES[:9]),
    suffix="_m",
    fresh=True,
)
