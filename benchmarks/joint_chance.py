"""How conservative the joint chance constraint is (docs/method.md §15.8, results §16.3).

    python benchmarks/joint_chance.py [--vehicles 6] [--seeds 20] [--every 5] [--draws 4000]

Runs the junction with the joint AV (``junction.av_plan = "joint"``, corrected mode, the
worst-case shield, ``lfg`` humans), seeds ``1..--seeds``. At every ``--every``-th decision that
plans against two humans or more it recomputes, with the plain NumPy reference
(``persuasive.reference.mpc`` on the same candidates, from each human planner's belief before
the decision), every human's branch probabilities and per-sample safety per candidate, and
from them, per candidate:

- ``exact``: the joint P(safe) at the worst sample with the humans' branches independent,
  ``min_k prod_h p_h(k)`` (what the model says);
- ``product``: the planner's default bound, ``prod_h min_k p_h(k)``;
- ``union``: Boole's inequality, ``1 - sum_h (1 - min_k p_h(k))``;
- ``monte carlo``: ``--draws`` joint branches drawn from the product of the humans' branch
  probabilities, the share safe with every human at each sample, its worst sample.

Prints how far each bound lies below ``exact``, how many candidates each declares infeasible
that ``exact`` finds feasible, in how many decisions the choice would differ, and how far the
Monte Carlo estimate lies from ``exact`` (against three standard errors). It also checks that
the reference's per-human lowest P(safe) is the planner's (``JointChoice.p_safe_each``).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from persuasive import packing as slot
from persuasive.config import Config, JunctionSpec
from persuasive.many.world import JunctionWorld
from persuasive.packing import discounts, pack
from persuasive.reference import mpc as reference_mpc
from persuasive.scenarios import build_scenario
from persuasive.tables import ACTIVE


def choice(expected: np.ndarray, ok: np.ndarray) -> int:
    return int(np.argmax(np.where(ok, expected, -np.inf))) if ok.any() else -1


def measure(n_vehicles: int, seeds: int, every: int, draws: int) -> dict:
    config = Config(mode="corrected")
    spec = JunctionSpec(n_vehicles=n_vehicles, av_plan="joint")
    rng = np.random.Generator(np.random.PCG64(12345))
    gaps = {"product": [], "union": []}
    lost = {"product": 0, "union": 0}
    changed = {"product": 0, "union": 0}
    mc_err, mc_se = [], []
    agree, decisions, candidates, humans = 0, 0, 0, []
    threshold = None
    for seed in range(1, seeds + 1):
        world = JunctionWorld(config, spec, seed)
        joint = world.planner
        P_av = P_hv = disc = None
        seen = 0
        while True:
            v = float(world.v[0])
            planned = []
            if world.status[0] == ACTIVE:
                v_c = min(max(v, joint.ego.v_min_mps), joint.ego.v_max_mps)
                planned, _ = joint._planned(v_c, world.conflicts_of(0))
            beliefs = {}
            for key, _, _ in planned:
                p = joint._planners.get(key)
                beliefs[key] = None if p is None else (float(p._state[0]), float(p._state[1]))
            info = world.step()
            last = joint.last
            if last is not None and len(planned) >= 2:
                seen += 1
                if seen % every == 0:
                    f = last.frame
                    ref = joint.planner_for(planned[f][0])
                    if P_av is None:
                        P_av, P_hv = pack(ref.config, build_scenario(ref.config))
                        disc = discounts(ref.config)
                        threshold = 1.0 - float(ref.config.mpc.epsilon)
                    view = ref.candidate_view()
                    S, V, A = view.S.copy(), view.V.copy(), view.A.copy()
                    s_f = planned[f][1][0]
                    per = []
                    for h, (key, ego, other) in enumerate(planned):
                        q = beliefs[key] or (float(P_av[slot.PRIOR_L]),
                                             1.0 - float(P_av[slot.PRIOR_L]))
                        rows: list = []
                        _, _, diag = reference_mpc(
                            ego, other, q, q[0] >= q[1], float(ref.config.p_a_hat), P_av,
                            P_hv, disc, candidates=((S + (ego[0] - s_f)).T, V.T, A.T),
                            branches=rows)
                        agree += bool(np.allclose(diag[:, 1], last.p_safe_each[h],
                                                  rtol=0, atol=1e-12))
                        per.append(rows)
                    decisions += 1
                    humans.append(len(planned))
                    n_traj = S.shape[1]
                    ex = np.empty(n_traj)
                    for c in range(n_traj):
                        probs = [per[h][c][0] for h in range(len(planned))]
                        safe = [per[h][c][1] for h in range(len(planned))]
                        p_k = np.prod([p @ s for p, s in zip(probs, safe)], axis=0)
                        ex[c] = p_k.min()
                        # Monte Carlo over the joint branches
                        ok = np.ones((draws, safe[0].shape[1]), bool)
                        for p, s in zip(probs, safe):
                            b = rng.choice(4, size=draws, p=p / p.sum())
                            ok &= s[b] > 0.5
                        est = ok.mean(axis=0)
                        k = int(np.argmin(p_k))
                        mc_err.append(abs(est.min() - ex[c]))
                        mc_se.append(np.sqrt(max(p_k[k] * (1 - p_k[k]), 1e-12) / draws))
                        candidates += 1
                    p_min = np.array([[per[h][c][0] @ per[h][c][1] for c in range(n_traj)]
                                      for h in range(len(planned))]).min(axis=2)
                    bounds = {"product": np.prod(p_min, axis=0),
                              "union": 1.0 - np.sum(1.0 - p_min, axis=0)}
                    ok_exact = last.allowed & (ex > threshold)
                    for name, b in bounds.items():
                        gaps[name].extend((ex - b).tolist())
                        ok_b = last.allowed & (b > threshold)
                        lost[name] += int(np.sum(ok_exact & ~ok_b))
                        changed[name] += choice(last.expected, ok_exact) != \
                            choice(last.expected, ok_b)
            if info.done:
                break
    out = {"decisions": decisions, "candidates": candidates,
           "humans (median, max)": (float(np.median(humans)) if humans else 0,
                                    max(humans, default=0)),
           "reference agrees with the planner": f"{agree} of {sum(humans)}"}
    for name in ("product", "union"):
        g = np.array(gaps[name])
        out[name] = {"below exact: mean": float(g.mean()), "p99": float(np.quantile(g, 0.99)),
                     "max": float(g.max()), "exactly equal": f"{int(np.sum(g == 0))} of {g.size}",
                     "feasible candidates lost": lost[name],
                     "decisions whose choice changes": changed[name]}
    err, se = np.array(mc_err), np.array(mc_se)
    out["monte carlo"] = {"draws": draws, "max |MC - exact|": float(err.max()),
                          "within 3 SE": f"{int(np.sum(err <= 3 * se + 1e-12))} of {err.size}"}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--vehicles", type=int, default=6)
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--every", type=int, default=5)
    ap.add_argument("--draws", type=int, default=4000)
    args = ap.parse_args()
    t = time.perf_counter()
    out = measure(args.vehicles, args.seeds, args.every, args.draws)
    for key, value in out.items():
        print(f"{key}: {value}")
    print(f"({time.perf_counter() - t:.0f} s)")


if __name__ == "__main__":
    main()
