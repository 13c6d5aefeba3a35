"""GNSS6GM (issue 29, docs/estimation.md E25): the receiver's first-order
Gauss-Markov error has its stationary variance and its correlation time,
and with its size at 0 the receiver is GNSS6 plus nothing."""
from __future__ import annotations

import math

import numpy as np
from tests.fmu_validation import validate_fmu

from fmu_models.export.build import cached_fmu
from fmu_models.models.sensors import GNSS_6_GM

from tests.fmus.sensor_harness import DT, Sensor

OUT = [f"{a}_m" for a in "xyzuvw"]


def _errors(parameters, n):
    rows = Sensor(GNSS_6_GM, parameters=parameters).run(np.zeros((n, 6)), read_before=False)
    names = [v.name for v in GNSS_6_GM.outputs]
    return rows[:, [names.index(o) for o in OUT]]


def test_builds_and_validates():
    assert validate_fmu(str(cached_fmu(GNSS_6_GM, 2))) == []


def test_the_error_has_its_variance_and_correlation_time():
    """White noise off, a sample every step: the error's standard deviation
    is gm_sigma from the first step on (a stationary start), and its
    autocorrelation at lag k is exp(-k dt / tau): 1/e at lag tau. Averaged
    over many independent channels (seeds x 6 axes) of 2000 steps each."""
    tau, sigma, n = 0.5, 0.03, 2000  # tau = 50 steps: 40 correlation times a run
    lags = (1, 25, 50, 100)
    runs = np.concatenate([_errors({"gm_tau": tau, "seed": seed, "sample_rate": 0.0,
                                    **{f"gm_sigma_{a}": sigma for a in "xyzuvw"}}, n) for seed in range(5)], axis=1)
    z = runs / sigma
    assert abs(z.std() - 1.0) < 0.05
    assert abs(z[0].std() - 1.0) < 0.35 and abs(np.sqrt((z[:5] ** 2).mean()) - 1.0) < 0.2  # stationary start
    for k in lags:
        rho = np.mean(z[k:] * z[:-k]) / np.mean(z * z)
        assert abs(rho - math.exp(-k * DT / tau)) < 0.07, (k, rho)
    # the increments are those of the discrete law: e_{n+1} - a e_n has std sigma sqrt(1 - a^2)
    a = math.exp(-DT / tau)
    innovation = (runs[1:] - a * runs[:-1]) / (sigma * math.sqrt(1 - a * a))
    assert abs(innovation.std() - 1.0) < 0.02


def test_without_its_size_it_adds_nothing():
    rows = _errors({"gm_tau": 10.0, "seed": 3}, 50)
    assert np.all(rows == 0.0)
