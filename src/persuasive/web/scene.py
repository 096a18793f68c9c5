"""What the page draws, as plain JSON values: the scene at trial start, the vehicles per step.

The page draws the scenario to scale from these alone (``static/drive.js``), as
``persuasive.plots.topview`` does from the same geometry: each vehicle's road is a strip
``lane_width_m`` wide along its path's polyline (``Path.polyline``), each crossing line (whose
first arrival decides who went first) and yield line (where the stop trajectory stops, dashed
when it differs) a segment across the road, the safety circle of radius ``min_dist_m`` around
the conflict point (``av.xy(0)``), and each vehicle an oriented rectangle of its length and
width centred on ``xy(s)`` with the path's heading. Coordinates are metres, ``x`` east and
``y`` north (the page flips ``y``), headings radians from ``+x``; numbers are rounded to
millimetres (positions) and 1e-4 rad (headings), well below a pixel.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

#: Spacing of the path polylines sent to the page [m].
POLYLINE_STEP_M = 0.5
#: Road drawn before the start and after the farthest reachable position [m].
ROAD_MARGIN_M = 40.0
#: Free space around the view box [m].
VIEW_MARGIN_M = 4.0


def _r(x: float, digits: int = 3) -> float:
    return round(float(x), digits)


def _line(path, s: float, kind: str) -> dict[str, Any]:
    x, y = path.xy(s)
    ux, uy = path.direction(s)
    return {"kind": kind, "s_m": _r(s), "x": _r(x), "y": _r(y), "nx": _r(-float(uy), 6),
            "ny": _r(float(ux), 6)}


def scene_of(scenario, x0: np.ndarray, n_steps: int) -> dict[str, Any]:
    """The scene of a trial: roads, lines, safety circle, vehicle sizes and the view box.

    ``x0``: the initial state ``(s_AV, v_AV, s_HV, v_HV)``; the roads reach past the farthest
    position a vehicle can get to in ``n_steps`` steps at ``v_max``.
    """
    config = scenario.config
    dt = config.simulation.dt_s
    vehicles: dict[str, Any] = {}
    view_pts = []
    cx, cy = (float(v) for v in scenario.av.xy(0.0))
    for who, j in (("av", 0), ("hv", 2)):
        path = getattr(scenario, who)
        veh = path.vehicle
        s0 = float(x0[j])
        lines = [_line(path, path.first_s, "crossing")]
        if math.isfinite(path.yield_s) and path.yield_s != path.first_s:
            lines.append(_line(path, path.yield_s, "yield"))
        first = min([s0] + [ln["s_m"] for ln in lines])
        reach = s0 + veh.v_max_mps * n_steps * dt
        lo, hi = first - ROAD_MARGIN_M, max(reach, path.clear_s if math.isfinite(path.clear_s)
                                           else 0.0, 0.0) + ROAD_MARGIN_M
        pts = path.polyline(lo, hi, POLYLINE_STEP_M)
        vehicles[who] = {
            "length_m": veh.length_m, "width_m": veh.width_m, "v_max_mps": veh.v_max_mps,
            "u_min_mps2": veh.u_min_mps2, "u_max_mps2": veh.u_max_mps2,
            "path": np.round(pts, 3).tolist(), "lines": lines,
        }
        # the view: from behind the start to a little past the conflict
        near = path.polyline(s0 - veh.length_m, max(0.0, min(path.clear_s, 30.0)) + 12.0, 1.0)
        view_pts.append(near)
    view_pts.append(np.array([[cx - scenario.min_dist_m, cy - scenario.min_dist_m],
                              [cx + scenario.min_dist_m, cy + scenario.min_dist_m]]))
    pts = np.concatenate(view_pts)
    (x_lo, y_lo), (x_hi, y_hi) = pts.min(axis=0), pts.max(axis=0)
    m = VIEW_MARGIN_M
    return {
        "kind": scenario.kind,
        "lane_width_m": scenario.lane_width_m,
        "min_dist_m": scenario.min_dist_m,
        "conflict": [_r(cx), _r(cy)],
        "vehicles": vehicles,
        "view": [_r(x_lo - m), _r(y_lo - m), _r(x_hi + m), _r(y_hi + m)],
    }


def poses(scenario, state: np.ndarray) -> dict[str, list[float]]:
    """Each vehicle's ``[x, y, heading, speed]`` at the true state ``(s_AV, v_AV, s_HV,
    v_HV)``."""
    out = {}
    for who, j in (("av", 0), ("hv", 2)):
        path = getattr(scenario, who)
        s = np.array([state[j]])
        x, y = path.xy(s)
        h = path.heading(s)
        out[who] = [_r(x[0]), _r(y[0]), _r(h[0], 4), _r(state[j + 1], 3)]
    return out


__all__ = ["poses", "scene_of"]
