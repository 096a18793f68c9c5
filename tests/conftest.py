"""Shared fixtures and the hypothesis profile.

The profile drops hypothesis' per-example deadline: the first call of a Numba kernel loads it
from the on-disk cache (or compiles it), which takes longer than any sensible deadline.
"""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, settings

from persuasive.packing import discounts, pack
from persuasive.scenarios import build_scenario
from persuasive.config import Config

settings.register_profile(
    "persuasive", deadline=None, suppress_health_check=[HealthCheck.too_slow]
)
settings.load_profile("persuasive")


class Packed:
    """A configuration with its kernel parameter vectors and discounts ``disc``.

    ``P`` is the AV's vector and ``P_hv`` the HV's; at the paper's intersection they differ
    only in the path's direction, which the perpendicular kernels never read, so tests of one
    vehicle's library may use either.
    """

    def __init__(self, config: Config):
        self.config = config
        self.P, self.P_hv = pack(config, build_scenario(config))
        self.P_av = self.P
        self.disc = discounts(config)


@pytest.fixture(scope="session")
def paper() -> Packed:
    """The paper-mode defaults (quirks Q1..Q7 on)."""
    return Packed(Config(mode="paper"))


@pytest.fixture(scope="session")
def corrected() -> Packed:
    """The corrected-mode defaults (Q1, Q2, Q3, Q5 off)."""
    return Packed(Config(mode="corrected"))


@pytest.fixture(scope="session")
def unequal() -> Packed:
    """Paper mode with vehicles of different size and limits: the HV 4 m long with
    ``v_max = 8 m/s`` and ``u_min = -3 m/s^2`` (crossing line -6 m, h_go = 5 + 8 / 0.6 m),
    the AV with the defaults; the pair's safety distance is 1.5 (5 + 4) / 2 = 6.75 m."""
    return Packed(Config().with_overrides({"hv.vehicle.length_m": 4.0,
                                           "hv.vehicle.v_max_mps": 8.0,
                                           "hv.vehicle.u_min_mps2": -3.0}))


@pytest.fixture(scope="session", params=["paper", "corrected"])
def packed(request) -> Packed:
    """Both modes, one after the other."""
    return Packed(Config(mode=request.param))
