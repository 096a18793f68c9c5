"""highway-env's intersection as the tests of its adapter open it."""


def intersection_after_reset(sized: bool):
    """highway-env's intersection after ``reset(seed=1)``: ``(env, env.unwrapped, projector)``,
    the ego's :class:`persuasive.envs.highway.Projector` along its route (with the ego's
    length and width when ``sized``). The caller closes ``env``."""
    from persuasive.envs.highway import Projector, ego_route, make_highway_env, planner_config

    env = make_highway_env(planner_config())
    env.reset(seed=1)
    u = env.unwrapped
    network, lanes, veh = u.road.network, ego_route(u), u.vehicle
    projector = (Projector(network, lanes, (float(veh.LENGTH), float(veh.WIDTH))) if sized
                 else Projector(network, lanes))
    return env, u, projector
