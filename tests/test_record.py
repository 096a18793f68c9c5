"""The scenario geometry cache of ``persuasive.record`` (``geometry_key``, ``scenario_of``):
a scenario assembled from a kept geometry equals a build from scratch field for field, and its
parameter vectors bit for bit, whatever the vehicle limits and the run's length; a key that
leaves out what the geometry depends on is caught by the same comparison."""

from __future__ import annotations

import numpy as np
import pytest

import persuasive.record as record
from persuasive import Config, ConfigError
from persuasive.packing import pack
from persuasive.record import GeometryCache, geometry_key, scenario_of
from persuasive.scenarios import build_scenario

#: Every two-vehicle kind; the crossing at 90 deg is the intersection's geometry, at 60 deg
#: its own; the merge's and the left turn's occupancy intervals are numerical.
KINDS = ({"scenario.kind": "intersection"},
         {"scenario.kind": "crossing", "scenario.angle_deg": 90.0},
         {"scenario.kind": "crossing", "scenario.angle_deg": 60.0},
         {"scenario.kind": "left-turn"},
         {"scenario.kind": "merge", "scenario.angle_deg": 20.0})
#: Recorded sizes, as a held-out evaluation's views carry them [m].
SIZES = {"av.vehicle.length_m": 4.62, "av.vehicle.width_m": 1.93,
         "hv.vehicle.length_m": 11.4, "hv.vehicle.width_m": 2.48}
#: What a fold of the evaluation changes (its vehicle limits) and what differs per pair (the
#: run's length), none of it in the key.
LIMITS = ({"vehicle.v_max_mps": 17.0, "hv.vehicle.u_min_mps2": -4.1,
           "hv.vehicle.u_max_mps2": 2.3, "av.vehicle.u_min_mps2": -3.7,
           "av.vehicle.u_max_mps2": 1.9, "simulation.n_steps": 123},
          {"vehicle.v_max_mps": 14.0, "vehicle.u_min_mps2": -3.0, "vehicle.u_max_mps2": 1.5,
           "simulation.n_steps": 45},
          {"av.vehicle.v_max_mps": 12.0, "vehicle.v_min_mps": 0.5,
           "roles.p_a": 0.3})


def same_scenario(a, b) -> bool:
    """Field for field (the paths' lines, zones and occupancy intervals, the vehicles, the
    configuration) and the packed parameter vectors bit for bit."""
    if a != b:
        return False
    return all(np.array_equal(x, y) for x, y in zip(pack(a.config, a), pack(b.config, b)))


def outcome(build, config):
    """``build(config)``, or the message of the :class:`ConfigError` it raises (the starts'
    checks read the limits)."""
    try:
        return build(config)
    except ConfigError as exc:
        return str(exc)


def same_outcome(a, b) -> bool:
    if isinstance(a, str) or isinstance(b, str):
        return a == b
    return same_scenario(a, b)


@pytest.mark.parametrize("kind", KINDS, ids=lambda k: "-".join(map(str, k.values())))
def test_a_kept_geometry_gives_the_scenario_a_build_gives(kind):
    cache = GeometryCache(8)
    base = Config(mode="corrected").with_overrides({**kind, **SIZES})
    first = scenario_of(base, cache)  # builds and keeps
    assert same_scenario(first, build_scenario(base)) and len(cache) == 1
    for limits in LIMITS:
        config = base.with_overrides(limits)
        assert geometry_key(config) == geometry_key(base)
        kept = outcome(lambda c: scenario_of(c, cache), config)
        assert same_outcome(kept, outcome(build_scenario, config))
        assert len(cache) == 1  # read, not built again
    # other sizes are another geometry
    other = base.with_overrides({"hv.vehicle.length_m": 4.2})
    assert geometry_key(other) != geometry_key(base)
    assert same_scenario(scenario_of(other, cache), build_scenario(other)) and len(cache) == 2


def test_a_key_that_leaves_out_a_size_is_caught(monkeypatch):
    """The comparison above fails for a key without the HV's length: it would hand a
    scenario the geometry of another vehicle's size."""
    def wrong(config):
        return geometry_key(config)[:3] + geometry_key(config)[4:]  # no hv.length_m

    monkeypatch.setattr(record, "geometry_key", wrong)
    cache = GeometryCache(8)
    base = Config(mode="corrected").with_overrides({**KINDS[2], **SIZES})
    scenario_of(base, cache)
    config = base.with_overrides({"hv.vehicle.length_m": 4.2})
    assert len(cache) == 1 and wrong(config) == wrong(base)
    assert not same_scenario(scenario_of(config, cache), build_scenario(config))


def test_a_kept_geometry_still_checks_the_starts():
    """The starts depend on the limits: a kept geometry refuses what a build refuses, with
    its message."""
    cache = GeometryCache(8)
    base = Config(mode="corrected").with_overrides({**KINDS[2],
                                                    "simulation.accel_noise_mps2": 0.9})
    scenario_of(base, cache)
    weak = base.with_overrides({"av.vehicle.u_min_mps2": -1.0})  # brakes at 0.1 m/s^2
    with pytest.raises(ConfigError) as built:
        build_scenario(weak)
    with pytest.raises(ConfigError) as kept:
        scenario_of(weak, cache)
    assert str(kept.value) == str(built.value) and len(cache) == 1


def test_the_cache_keeps_the_last_used():
    cache = GeometryCache(2)
    configs = [Config(mode="corrected").with_overrides({**KINDS[2], "hv.vehicle.length_m": x})
               for x in (4.0, 4.5, 5.0)]
    scenario_of(configs[0], cache)
    scenario_of(configs[1], cache)
    scenario_of(configs[0], cache)  # used last: kept
    scenario_of(configs[2], cache)
    keys = [k for k, _ in cache.items()]
    assert keys == [geometry_key(configs[0]), geometry_key(configs[2])]
    assert scenario_of(configs[1], None) == build_scenario(configs[1])
