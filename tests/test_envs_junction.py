"""The junction as a PettingZoo ``ParallelEnv`` and as a gymnasium environment
(``persuasive.envs.junction``)."""

from __future__ import annotations

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test, parallel_seed_test  # the test extra has it

from persuasive.config import ConfigError
from persuasive.envs.junction import JunctionEnv, JunctionParallelEnv


@pytest.mark.parametrize("agents", ["all", ("vehicle_0",), ("vehicle_1", "vehicle_3")])
def test_parallel_api(agents):
    parallel_api_test(JunctionParallelEnv(n_vehicles=4, agents=agents), num_cycles=150)


def test_parallel_api_with_agents_still_to_arrive():
    from persuasive.many.junction import JunctionSpec

    spec = JunctionSpec(n_vehicles=4, arrival="poisson", flow_veh_h=1200.0, duration_s=15.0,
                        av_arrival_s=2.0)
    parallel_api_test(JunctionParallelEnv(spec=spec, agents="all"), num_cycles=200)


def test_seeded_like_gymnasium():
    parallel_seed_test(lambda: JunctionParallelEnv(n_vehicles=4, agents=(0, 2)))

    def roll(seed):
        env = JunctionParallelEnv(n_vehicles=5, agents="all")
        obs, _ = env.reset(seed=seed)
        trace = [np.concatenate([obs[a] for a in sorted(obs)])]
        while env.agents:
            obs, *_ = env.step({a: np.array([0.5], np.float32) for a in env.agents})
            trace.append(np.concatenate([obs[a] for a in sorted(obs)]) if obs else [])
        return trace

    a, b, c = roll(7), roll(7), roll(8)
    assert all(np.array_equal(x, y) for x, y in zip(a, b)) and len(a) == len(b)
    assert not all(np.array_equal(x, y) for x, y in zip(a, c))


def test_agents_are_shielded_by_default_and_not_when_asked():
    """Full throttle into the junction: the shield brakes the agent, without it the agent
    keeps full throttle (and the AV's planner is not asked)."""
    shielded, free = (JunctionParallelEnv(n_vehicles=6, agents="all", shield=s)
                      for s in (True, False))
    over = 0
    for seed in range(1, 6):
        for env in (shielded, free):
            env.reset(seed=seed)
        while shielded.agents and free.agents:
            act = {a: np.array([1.0], np.float32) for a in shielded.agents}
            _, _, _, _, info_s = shielded.step(act)
            _, _, _, _, info_f = free.step({a: np.array([1.0], np.float32)
                                            for a in free.agents})
            over += sum(i["accel_mps2"] < 1.0 for i in info_s.values())
            assert all(i["accel_mps2"] == 1.0 for i in info_f.values())
    assert over > 0


def test_bad_agents_are_refused_in_one_line():
    with pytest.raises(ConfigError, match="agents has vehicle 'vehicle_9'"):
        JunctionParallelEnv(n_vehicles=4, agents=("vehicle_9",))
    with pytest.raises(ConfigError, match="render_mode"):
        JunctionParallelEnv(render_mode="human")


def test_gymnasium_single_agent_view():
    from gymnasium.utils.env_checker import check_env

    env = JunctionEnv(n_vehicles=4)
    check_env(env, skip_render_check=True)
    obs, info = env.reset(seed=3)
    assert obs.shape == env.observation_space.shape and info["seed"] == 3
    assert env.world.n == 4
    img = JunctionEnv(n_vehicles=3, render_mode="rgb_array")
    img.reset(seed=1)
    frame = img.render()
    assert frame.ndim == 3 and frame.shape[2] == 3


def test_registered_id():
    import gymnasium

    env = gymnasium.make("persuasive.envs:persuasive/Junction-v0", n_vehicles=3)
    obs, _ = env.reset(seed=2)
    assert env.unwrapped.world.n == 3
    env.close()
