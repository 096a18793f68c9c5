"""The AV's one plan against every human at the junction (``persuasive.many.joint``, issue 41
item 1): the expectation over the product of the humans' branches and the joint chance
constraint against a brute force over every joint branch; the candidates shifted into each
human's frame against that human's own library; with one human the joint AV is the pairwise
one bit for bit; the joint decisions in closed loop choose as stated.

Tolerances: expectations to 1e-9 relative (sums of up to 4^4 products in another order);
shifted trajectories to 1e-9 m (the library's OVM law rounds with the frame's offset; the
measured differences are below 1e-13 m)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from persuasive.config import Config, ConfigError, JunctionSpec
from persuasive.game import build_buffers, shifted_into
from persuasive.library import lib_buffers
from persuasive.many.joint import (JointPlanner, combine, joint_expectation, joint_p_safe)
from persuasive.many.world import JunctionWorld
from persuasive.packing import discounts, pack
from persuasive.scenarios import build_scenario

CONFIG = Config(mode="corrected")
W_C = 7.0


def _branches(draw, n_humans: int, n_traj: int, n: int):
    """Random per-human branch data: probabilities ``(H, n_traj, 4)`` on the simplex,
    collision weights ``(H, n_traj, 4)`` and safety ``(H, n_traj, 4, n)``."""
    probs = np.array(draw(st.lists(st.floats(0.0, 1.0), min_size=n_humans * n_traj * 4,
                                   max_size=n_humans * n_traj * 4))).reshape(n_humans, n_traj, 4)
    probs = probs + 1e-3
    probs /= probs.sum(axis=2, keepdims=True)
    cost = np.array(draw(st.lists(st.floats(0.0, 50.0), min_size=probs.size,
                                  max_size=probs.size))).reshape(probs.shape)
    safe = np.array(draw(st.lists(st.booleans(), min_size=probs.size * n,
                                  max_size=probs.size * n))).reshape(*probs.shape, n)
    return probs, cost, safe


@settings(max_examples=60, deadline=None)
@given(st.data(), st.integers(2, 4))
def test_the_joint_expectation_and_chance_constraint_are_the_product_of_branches(data, H):
    n_traj, n = 3, 4
    probs, cost, safe = _branches(data.draw, H, n_traj, n)
    base = np.array(data.draw(st.lists(st.floats(-20.0, 60.0), min_size=n_traj,
                                       max_size=n_traj)))
    # what each human's decision reports (persuasive.mpc.decide's J_h and min_k P(safe))
    expected_each = np.einsum("hcb,hcb->hc", probs, base[None, :, None] - W_C * cost)
    p_each = np.einsum("hcb,hcbk->hck", probs, safe.astype(float)).min(axis=2)
    base_each = np.repeat(base[None], H, axis=0)
    # brute force over all 4^H joint branches
    brute_e = np.zeros(n_traj)
    brute_p = np.zeros((n_traj, n))
    for branch in itertools.product(range(4), repeat=H):
        p = np.prod([probs[h, :, b] for h, b in enumerate(branch)], axis=0)
        c = np.sum([cost[h, :, b] for h, b in enumerate(branch)], axis=0)
        ok = np.all([safe[h, :, b] for h, b in enumerate(branch)], axis=0)
        brute_e += p * (base - W_C * c)
        brute_p += p[:, None] * ok
    exact = brute_p.min(axis=1)  # the joint P(safe) at the worst sample
    got = joint_expectation(base, expected_each, base_each)
    np.testing.assert_allclose(got, brute_e, rtol=1e-9, atol=1e-9)
    product, union = joint_p_safe(p_each, "product"), joint_p_safe(p_each, "union")
    assert np.all(product <= exact + 1e-12)  # sufficient: never above the exact probability
    assert np.all(union <= product + 1e-12)  # Boole's inequality is the more conservative
    # tight where every human's P(safe) is its lowest at the same sample for all
    flat = np.einsum("hcb,hcb->hc", probs, safe[..., 0].astype(float))
    np.testing.assert_allclose(joint_p_safe(flat, "product"),
                               np.prod(flat, axis=0), rtol=0, atol=0)


def test_the_choice_is_the_best_feasible_candidate_or_none():
    expected = np.array([3.0, 5.0, 5.0, 9.0])
    # candidate 0: each human's P(safe) above 0.98, not both at once (0.975); 3 has the best
    # reward but one human's 0.97; 1 and 2 tie on reward: the first
    p_each = np.array([[0.985, 0.99, 0.999, 0.97], [0.99, 0.9899, 0.999, 1.0]])
    allowed = np.array([True, True, True, True])
    c, p, feasible = combine(expected, p_each, allowed, 0.98, "product")
    assert feasible.tolist() == [False, True, True, False] and c == 1
    np.testing.assert_allclose(p, np.prod(p_each, axis=0))
    c, _, feasible = combine(expected, p_each, np.array([True, False, True, True]), 0.98,
                             "product")
    assert c == 2
    c, _, feasible = combine(expected, p_each, allowed, 0.98, "union")  # 1: 0.9799
    assert feasible.tolist() == [False, False, True, False] and c == 2
    c, _, feasible = combine(expected, p_each, allowed, 0.999, "product")
    assert c == -1 and not feasible.any()


def test_candidates_shifted_into_a_frame_are_that_frames_library():
    P_av, _ = pack(CONFIG, build_scenario(CONFIG))
    disc = discounts(CONFIG)
    n, n_traj = CONFIG.library.n_samples, CONFIG.library.n_traj
    v = 4.0
    for s_f, s_h in ((-30.0, -37.5), (-12.0, -20.25), (-45.0, -45.0)):
        ref, own, shifted = (lib_buffers(n, n_traj) for _ in range(3))
        build_buffers(s_f, v, P_av, disc, *ref)
        build_buffers(s_h, v, P_av, disc, *own)
        buf = ref[0]
        shifted_into(buf[0:n], buf[n:2 * n], buf[2 * n:3 * n], s_h - s_f, s_h, P_av, disc,
                     *shifted)
        keep = [c for c in range(n_traj) if c != 1]  # the stop is at each frame's own line
        # S, V, A, the collision weights to 1e-9 m (m/s, ...); s^2 to 1e-9 m^2 relative
        for rows, tol in ((slice(0, 4 * n), 1e-9), (slice(4 * n, 5 * n), 1e-9 * s_h ** 2)):
            np.testing.assert_allclose(shifted[0][rows][:, keep], own[0][rows][:, keep],
                                       rtol=0, atol=tol)
        np.testing.assert_allclose(shifted[0][6 * n, keep], own[0][6 * n, keep], atol=1e-9)
        assert np.array_equal(shifted[1][keep], own[1][keep])  # the zone windows


def _run(n_vehicles: int, seed: int, plan: str, kind: str = "lfg", watch=None):
    spec = JunctionSpec(n_vehicles=n_vehicles, av_plan=plan, hv_kinds=((kind, 1.0),))
    world = JunctionWorld(CONFIG, spec, seed)
    while True:
        info = world.step()
        if watch is not None:
            watch(world)
        if info.done:
            return world


@pytest.mark.parametrize("kind", ["lfg", "aggressive", "idm"])
def test_with_one_human_the_joint_av_is_the_pairwise_one(kind):
    for seed in range(1, 5):
        a, b = _run(2, seed, "pairwise", kind), _run(2, seed, "joint", kind)
        assert np.array_equal(a.S, b.S, equal_nan=True)
        assert np.array_equal(a.A, b.A, equal_nan=True)
        assert a.verdicts == b.verdicts


def test_joint_decisions_choose_as_stated_and_change_runs():
    seen = []

    def check(world):
        last = world.planner.last
        if last is None:
            return
        seen.append(last)
        assert len(last.keys) >= 2
        assert last.p_safe_each.shape == (len(last.keys), last.expected.shape[0])
        np.testing.assert_array_equal(last.p_safe, np.prod(last.p_safe_each, axis=0))
        if last.fallback:
            assert not last.feasible.any() and last.chosen == -1
        else:
            c = last.chosen
            assert last.feasible[c] and last.allowed[c]
            assert last.p_safe[c] > 1.0 - CONFIG.mpc.epsilon
            assert last.expected[c] == last.expected[last.feasible].max()

    differ = 0
    for seed in (3, 6, 7):
        joint = _run(6, seed, "joint", watch=check)
        pair = _run(6, seed, "pairwise")
        differ += not np.array_equal(joint.S, pair.S, equal_nan=True)
        assert not any(caused for *_, caused in joint.collisions)
    assert len(seen) > 100 and any(not s.fallback for s in seen)
    assert differ >= 2  # the joint plan is not the pairwise rule under another name


def test_the_plan_and_bound_are_configuration_choices():
    cfg = Config.from_dict({"scenario": {"kind": "junction"},
                            "junction": {"av_plan": "joint", "joint_bound": "union"}})
    spec = cfg.junction_spec
    assert (spec.av_plan, spec.joint_bound) == ("joint", "union")
    world = JunctionWorld.of(cfg, 1)
    assert isinstance(world.planner, JointPlanner) and world.planner.bound == "union"
    with pytest.raises(ConfigError, match=r"junction\.av_plan = 'both' is out of range; "
                                          r"allowed: pairwise \| joint"):
        JunctionSpec(av_plan="both")
    with pytest.raises(ConfigError, match=r"junction\.joint_bound = 'max' is out of range"):
        Config.from_dict({"scenario": {"kind": "junction"}, "junction": {"joint_bound": "max"}})
    # unset, the section and the digest are those of before
    plain = Config.from_dict({"scenario": {"kind": "junction"}})
    assert "av_plan" not in plain.to_toml()
