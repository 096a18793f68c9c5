"""Fitting human models to logged driving (``persuasive.fitting``, docs/method.md §13).

Layers: the transition is the LFG's own ``Pi``; the evidence replays the LFG human bit for bit;
the forward filter equals brute-force enumeration of role sequences (tolerance 1e-10,
relative, on log-likelihoods), and with constant roles it is the LFG's Bayes belief (1e-9);
the exact maximisation over ``pi0``; then fits of simulated datasets with known parameters
(the interval holds the truth and excludes the wrong answer; model selection names the kind);
the files a fit writes; bad logs refused in one line.
"""

from __future__ import annotations

import functools
import itertools
import math

import numpy as np
import pytest
from scipy.stats import chi2

from persuasive import Config, simulate
from persuasive.config import ConfigError
from persuasive.fitting import (evidence_of, fit_models, load_fitted_run, load_logs,
                                read_log, write_fit_parquet)
from persuasive.fitting.estimate import (DROP_ONE_SIDED, SIGMA_MAX, SIGMA_MIN, SIGMA_MIN_RANGE,
                                         bound_side, check_sigma_min, fit_role_model,
                                         profile_interval)
from persuasive.fitting.idm import fit_idm
from persuasive.fitting.evidence import Evidence, run_log_of
from persuasive.fitting.filter import (filter_loglik, filter_posterior, filter_start,
                                       filter_step, role_transition, smooth_roles)
from persuasive.fitting.models import (EMIT_LFG, EMIT_NOISY, IDM_NAMES, best_initial_role,
                                       path_loglik, path_loglik_serial,
                                       first_of_equal, hmm_loglik, hmm_loglik_serial,
                                       idm_groups, idm_sse, idm_sse_serial,
                                       step_log_emissions)
from persuasive.fitting.optimize import maximise_rows
from persuasive.game import full_prediction
from persuasive.policies.idm import idm_step
from persuasive.roles import gaussian_density, transition_matrix
from persuasive.record import static_setup


@functools.lru_cache(maxsize=None)
def dataset(kind: str = "lfg", p_a: float = 0.5, role: str = "leader", noise: float = 0.0,
            runs: int = 20, first_seed: int = 1, mode: str = "corrected"):
    """Runs of the recovery design: even runs against the persuasive AV, odd ones against the
    passive AV, both assuming p_a_hat = 1 (benchmarks/fit_recovery.py)."""
    extra = {}
    if kind == "idm":
        extra = {"hv.idm.critical_gap_s": 1.5, "hv.idm.time_gap_s": 1.2,
                 "hv.idm.desired_speed_mps": 9.0}
    cs = [Config(mode=mode).with_overrides({"hv.kind": kind, "roles.p_a": p_a, "hv.role": role,
                                            "simulation.accel_noise_mps2": noise,
                                            "mpc.p_a_hat": 1.0, "av.kind": av, **extra})
          for av in ("persuasive", "passive")]
    records = [simulate(cs[j % 2], first_seed + j) for j in range(runs)]
    return records, evidence_of([run_log_of(r, f"run{j}") for j, r in enumerate(records)])


# -- the transition -----------------------------------------------------------------------------


@pytest.mark.parametrize("p_a", [0.0, 0.3, 1.0])
@pytest.mark.parametrize("pl_l,pl_f", [(0.0, 0.0), (1.0, 1.0), (1.0, 0.0)])
def test_the_transition_is_the_lfgs_pi_per_own_role(p_a, pl_l, pl_f):
    T = np.empty((2, 2))
    role_transition(p_a, pl_l, pl_f, T)
    np.testing.assert_array_equal(T[:, 0], transition_matrix(pl_l, p_a)[:, 0])
    np.testing.assert_array_equal(T[:, 1], transition_matrix(pl_f, p_a)[:, 1])
    np.testing.assert_allclose(T.sum(axis=0), 1.0)
    if (pl_l, pl_f) == (1.0, 0.0):  # an exact belief tie: the plausible role is one's own
        np.testing.assert_array_equal(T, np.eye(2))


# -- the evidence -------------------------------------------------------------------------------


@pytest.mark.parametrize("mode,extra", [
    ("paper", {}),
    ("corrected", {"hv.role": "follower", "roles.p_a": 0.4}),
    ("corrected", {"simulation.measurement_noise": "gaussian", "simulation.noise_s_m": 0.05,
                   "simulation.noise_v_mps": 0.05, "roles.p_a": 0.6}),
    ("paper", {"av.kind": "lfg", "roles.p_a": 0.7}),
])
def test_the_evidence_replays_the_lfg_human_bit_for_bit(mode, extra):
    config = Config(mode=mode).with_overrides(extra)
    records = [simulate(config, seed) for seed in (3, 996)]
    ev = evidence_of([run_log_of(r) for r in records])
    for i, rec in enumerate(records):
        a, b = ev.starts[i], ev.starts[i + 1]
        role = (rec.log["hv_role"] != "leader").astype(int)
        steps = np.arange(b - a)
        # the acceleration of the role it acted in, the plausible role it used, its belief
        np.testing.assert_array_equal(ev.a_role[a:b][steps, role], rec.log["hv_accel_mps2"])
        np.testing.assert_array_equal(ev.pl[a:b][steps, role], rec.log["hv_plausible_leader"])
        np.testing.assert_array_equal(ev.belief[a + 1:b, 0],
                                      rec.log["hv_belief_other_leader"][:-1])
        np.testing.assert_array_equal(ev.belief[a, :], [0.5, 0.5])


def test_the_evidence_holds_the_noisy_humans_choice_probabilities():
    config = Config(mode="corrected").with_overrides({"hv.kind": "noisy", "roles.p_a": 0.5})
    rec = simulate(config, 11)
    ev = evidence_of([run_log_of(rec)])
    beta = config.hv.noisy.beta
    role = (rec.log["hv_role"] != "leader").astype(int)
    for k, c in enumerate(rec.log["hv_trajectory"]):
        q = ev.q[k, role[k]]
        first = int(np.argmax(q))
        w = np.where(q == q.max(), 0.0, np.exp(beta * (q - q.max())))
        w[first] = 1.0
        assert ev.a_first[k, c] == rec.log["hv_accel_mps2"][k]
        assert math.isclose(w[c] / w.sum(), rec.log["hv_choice_probability"][k], rel_tol=1e-12)


# -- the forward filter -------------------------------------------------------------------------


def _log_sum(values):
    values = np.asarray(values, float)
    m = values.max()
    return m + math.log(np.exp(values - m).sum()) if np.isfinite(m) else -math.inf


def _emissions(ev, kind, sigma, beta, rows):
    out = np.empty((len(rows), 2))
    e = np.empty(2)
    for j, k in enumerate(rows):
        step_log_emissions(kind, ev.accel[k], ev.a_role[k], ev.q[k], ev.a_first[k], sigma,
                           beta, e)
        out[j] = e
    return out


def _paths(ll, pl, p_a, pi0):
    """log p(path, data) of every role sequence, from the LFG's own Pi per step."""
    n = ll.shape[0]
    out = {}
    for path in itertools.product((0, 1), repeat=n):
        lp = math.log(pi0) if path[0] == 0 else math.log1p(-pi0) if pi0 < 1 else -math.inf
        for k in range(n):
            lp += ll[k, path[k]]
            if k + 1 < n:
                t = transition_matrix(pl[k, path[k]], p_a)[path[k + 1], path[k]]
                lp += math.log(t) if t > 0 else -math.inf
        out[path] = lp
    return out


def _pieces(ev, pieces):
    """Evidence made of row ranges ``[(a, b), ...]`` of ``ev``, each as a run."""
    rows = np.concatenate([np.arange(a, b) for a, b in pieces])
    starts = np.concatenate([[0], np.cumsum([b - a for a, b in pieces])]).astype(np.int64)
    n = len(pieces)
    return Evidence([ev.runs[0]] * n, starts, ev.accel[rows], ev.a_role[rows], ev.pl[rows],
                    ev.belief[rows], ev.q[rows], ev.a_first[rows], ev.states[rows],
                    ev.P_hv[:1].repeat(n, 0), ev.P_av[:1].repeat(n, 0), ev.dt[:1].repeat(n))


@pytest.mark.parametrize("kind", [EMIT_NOISY, EMIT_LFG])
def test_rows_sharing_sigma_and_beta_get_each_rows_own_likelihood(kind):
    """The noisy likelihood computes its Gaussian terms, choice weights and emissions once per
    distinct ``sigma``, ``beta`` and pair of them (a Newton stencil repeats them): every row
    of a stencil equals that row evaluated alone, bit for bit."""
    _, ev = dataset(p_a=0.5, runs=3, first_seed=2)
    p_a = np.array([0.5, 0.5, 0.5, 0.6, 0.4, 0.5, 0.5, 0.6, 0.45, 0.5])
    sigma = np.array([0.3, 0.33, 0.27, 0.3, 0.3, 0.3, 0.3, 0.33, 0.3, 0.27])
    beta = np.array([0.1, 0.1, 0.1, 0.1, 0.1, 0.15, 0.05, 0.15, 0.1, 0.05])
    out = np.empty((ev.n_runs, p_a.size, 2))
    hmm_loglik(kind, ev.starts, ev.accel, ev.a_role, ev.pl, ev.q, ev.a_first, p_a, sigma,
               beta, out)
    for g in range(p_a.size):
        alone = np.empty((ev.n_runs, 1, 2))
        hmm_loglik_serial(kind, ev.starts, ev.accel, ev.a_role, ev.pl, ev.q, ev.a_first,
                          p_a[g:g + 1], sigma[g:g + 1], beta[g:g + 1], alone)
        np.testing.assert_array_equal(out[:, g], alone[:, 0])
    if kind == EMIT_NOISY:  # the rows differ: a mix-up of rows would be seen
        assert len(set(out[0, :, 0])) == p_a.size
    idx = np.empty(5, np.int64)
    assert first_of_equal(np.array([0.3, 0.2, 0.3, np.nan, 0.2]), idx) == 3
    assert idx.tolist() == [0, 1, 0, 2, 1]


@pytest.mark.parametrize("kind,sigma,beta", [(EMIT_LFG, 0.4, math.inf),
                                             (EMIT_NOISY, 0.3, 0.2),
                                             (EMIT_LFG, 0.01, math.inf),
                                             (EMIT_NOISY, 0.002, 40.0)])
def test_the_forward_pass_equals_brute_force_enumeration(kind, sigma, beta):
    records, ev_all = dataset(p_a=0.5, runs=4, first_seed=2)
    # two stretches of 9 steps: the first steps (with the belief ties of steps 0 and 1), and
    # the steps around the first role change
    changes = [(i, int(np.flatnonzero(r.log["hv_next_role"] != r.log["hv_role"])[0]))
               for i, r in enumerate(records) if r.outcome.hv_role_changes]
    assert changes
    i, k = changes[0]
    a = ev_all.starts[i] + max(0, k - 4)
    ev = _pieces(ev_all, [(0, 9), (a, a + 9)])
    p_a = np.array([0.0, 0.37, 1.0])
    out = np.empty((ev.n_runs, 3, 2))
    serial = np.empty_like(out)
    args = (kind, ev.starts, ev.accel, ev.a_role, ev.pl, ev.q, ev.a_first, p_a,
            np.full(3, sigma), np.full(3, beta))
    hmm_loglik(*args, out)
    hmm_loglik_serial(*args, serial)
    np.testing.assert_array_equal(out, serial)
    for i in range(ev.n_runs):
        rows = range(ev.starts[i], ev.starts[i + 1])
        ll = _emissions(ev, kind, sigma, beta, rows)
        pl = ev.pl[ev.starts[i]:ev.starts[i + 1]]
        for g, p in enumerate(p_a):
            paths = _paths(ll, pl, p, 0.5)
            for r0 in (0, 1):
                want = _log_sum([v for path, v in paths.items() if path[0] == r0]) \
                    - math.log(0.5)
                got = out[i, g, r0]
                if math.isinf(want):
                    assert got == want
                else:
                    assert math.isclose(got, want, rel_tol=1e-10, abs_tol=1e-9), (i, g, r0)
            # smoothing: P(r_k = L | all the data) by enumeration
            smoothed = np.empty(len(rows))
            total = smooth_roles(ll, pl, p, 0.6, smoothed)
            paths = _paths(ll, pl, p, 0.6)
            assert math.isclose(total, _log_sum(list(paths.values())), rel_tol=1e-10,
                                abs_tol=1e-9)
            for k in range(len(rows)):
                lead = _log_sum([v for path, v in paths.items() if path[k] == 0])
                assert math.isclose(smoothed[k], math.exp(lead - total), abs_tol=1e-9)


def test_the_filter_survives_emissions_thousands_of_nats_apart():
    # the role with all the mass is 3000 nats less likely than the other at every step
    n = 40
    ll = np.zeros((n, 2))
    ll[:, 0] = -3000.0
    pl = np.full((n, 2), 1.0)  # plausible leader: a follower may become leader
    alpha, logscale = np.empty((1, 2)), np.empty(1)
    filter_start(alpha, logscale, 1.0, ll[0:1])
    for k in range(1, n):
        filter_step(alpha, logscale, np.zeros(1), pl[k - 1, 0], pl[k - 1, 1], ll[k:k + 1])
    out = np.empty(1)
    filter_loglik(alpha, logscale, out)
    assert out[0] == pytest.approx(-3000.0 * n, rel=1e-12)  # the leader it stays, p_a = 0
    filter_posterior(alpha, out)
    assert out[0] == 1.0


def test_with_constant_roles_the_filter_is_the_lfgs_own_belief():
    """The human's belief about the AV (§5.5) is the same forward pass with p_a = 0 and the
    Gaussian residual emissions."""
    config = Config(mode="corrected").with_overrides({"roles.p_a": 0.5})
    rec = simulate(config, 7)
    _, P_av, P_hv, disc = static_setup(config)
    w_s, w_v = config.roles.w_s_m2, config.roles.w_v_m2ps2
    log = rec.log
    alpha, logscale = np.empty((1, 2)), np.empty(1)
    post = np.empty(1)
    pred = None
    for k in range(len(log["step"])):
        s_av, v_av = log["av_meas_s_m"][k], log["av_meas_v_mps"][k]
        if pred is None:
            pred = ((s_av, v_av), (s_av, v_av))
        dens = [gaussian_density(abs(s_av - ps), abs(v_av - pv), w_s, w_v) for ps, pv in pred]
        ll = np.log(np.array([dens]))
        if k == 0:
            filter_start(alpha, logscale, 0.5, ll)
        else:  # p_a = 0: the identity, whatever the plausible role
            filter_step(alpha, logscale, np.zeros(1), 1.0, 0.0, ll)
        filter_posterior(alpha, post)
        assert post[0] == pytest.approx(log["hv_belief_other_leader"][k], rel=1e-9, abs=1e-12)
        game = full_prediction((log["hv_meas_s_m"][k], log["hv_meas_v_mps"][k]), (s_av, v_av),
                               P_hv, P_av, disc)
        pred = (game.other_state("leader", 1), game.other_state("follower", 1))


def test_the_initial_role_is_maximised_exactly():
    rng = np.random.default_rng(5)
    table = rng.normal(-20.0, 3.0, size=(9, 3, 2))
    table[:, 1, 1] -= 50.0  # every run far likelier starting as leader: pi0 = 1
    table[0, 2, 0] = -np.inf  # run 0 cannot start as leader
    ell, pi0 = np.empty(3), np.empty(3)
    best_initial_role(table, np.full(3, np.nan), ell, pi0)
    grid = np.linspace(0.0, 1.0, 20001)
    for g in range(3):
        with np.errstate(divide="ignore"):
            dense = np.logaddexp(np.log(grid)[:, None] + table[None, :, g, 0],
                                 np.log1p(-grid)[:, None] + table[None, :, g, 1]).sum(axis=1)
        assert ell[g] >= dense.max() - 1e-9
        assert abs(pi0[g] - grid[np.argmax(dense)]) <= 1e-4
    assert pi0[1] == 1.0
    # a given pi0 is used as given
    best_initial_role(table, np.full(3, 0.25), ell, pi0)
    assert np.all(pi0 == 0.25)


def test_the_lockstep_newton_finds_bounded_maxima():
    def f(X):  # a concave quadratic, maximal at (0.3, -1.0)
        d = X - np.array([0.3, -1.0])
        return -4.0 * d[:, 0] ** 2 - d[:, 1] ** 2 - 0.5 * d[:, 0] * d[:, 1]

    h, scale = np.array([1e-4, 1e-4]), np.array([0.5, 0.5])
    starts = np.array([[0.0, 0.0], [0.9, 1.9], [-0.9, -1.9]])
    x, fx = maximise_rows(f, starts, [0, 1], np.array([-1.0, -2.0]), np.array([1.0, 2.0]), h,
                          scale)
    np.testing.assert_allclose(x, [[0.3, -1.0]] * 3, atol=1e-5)
    np.testing.assert_allclose(fx, 0.0, atol=1e-9)
    # the maximum outside the bounds: the bound, and the other coordinate's best there
    x, _ = maximise_rows(f, starts, [0, 1], np.array([0.5, -2.0]), np.array([1.0, 2.0]), h,
                         scale)
    np.testing.assert_allclose(x[:, 0], 0.5, atol=1e-9)
    np.testing.assert_allclose(x[:, 1], -1.0 - 0.25 * 0.2, atol=1e-5)
    # a coordinate left out stays where it is
    x, _ = maximise_rows(f, starts, [1], np.array([-1.0, -2.0]), np.array([1.0, 2.0]), h, scale)
    np.testing.assert_array_equal(x[:, 0], starts[:, 0])


def test_the_lazy_newton_takes_the_same_steps_and_scores_fewer_rows():
    """``lazy``: a rejected step's stencil is never scored; the iterates are the eager ones,
    bit for bit (the function scores a row the same in any batch)."""
    scored = []

    def f(X):  # a ridge with a kink: many steps are rejected near the maximum
        scored.append(len(X))
        d = X - np.array([0.3, -1.0])
        return -4.0 * d[:, 0] ** 2 - np.abs(d[:, 1]) - 0.5 * d[:, 0] * d[:, 1]

    lo, hi = np.array([-1.0, -2.0]), np.array([1.0, 2.0])
    h, scale = np.array([1e-4, 1e-4]), np.array([0.5, 0.5])
    starts = np.array([[0.0, 0.0], [0.9, 1.9], [-0.9, -1.9], [0.3, -1.0]])
    x, fx = maximise_rows(f, starts, [0, 1], lo, hi, h, scale)
    eager = sum(scored)
    scored.clear()
    x_l, fx_l = maximise_rows(f, starts, [0, 1], lo, hi, h, scale, lazy=True)
    np.testing.assert_array_equal(x_l, x)
    np.testing.assert_array_equal(fx_l, fx)
    assert sum(scored) < 0.85 * eager  # 348 of 439 rows


def test_the_newton_stops_where_a_steps_gain_is_within_rounding(monkeypatch):
    """A log-likelihood of a million carries rounding noise of about 1e-9: once a row's next
    step is predicted to gain less than ``GAIN_TOL`` of its value it stops, instead of
    shrinking its trust region one rejected step after another; a step onto a bound is
    still taken."""
    from persuasive.fitting import optimize

    calls = []

    def f(X):  # maximal at (0.3, -1.0); the noise: a fixed function of the point's bits
        calls.append(len(X))
        d = X - np.array([0.3, -1.0])
        noise = (np.frombuffer(X.tobytes(), np.uint64).reshape(X.shape).sum(axis=1)
                 % 1009) * 1e-12
        return 1e6 - 4.0 * d[:, 0] ** 2 - d[:, 1] ** 2 + noise

    lo, hi = np.array([-1.0, -2.0]), np.array([1.0, 2.0])
    h, scale = np.array([1e-4, 1e-4]), np.array([0.5, 0.5])
    starts = np.array([[0.0, 0.0], [0.9, 1.9]])
    x, fx = maximise_rows(f, starts, [0, 1], lo, hi, h, scale, lazy=True)
    stopped = sum(calls)
    calls.clear()
    monkeypatch.setattr(optimize, "GAIN_TOL", 0.0)
    x0, fx0 = maximise_rows(f, starts, [0, 1], lo, hi, h, scale, lazy=True)
    np.testing.assert_allclose(x, [[0.3, -1.0]] * 2, atol=1e-3)
    assert np.all(fx >= fx0 - 1e-5)  # the same maximum, to within what the rule gives up
    assert stopped < 0.8 * sum(calls)
    # a maximum on a bound is reached exactly, however small the step's gain (here 4e-13,
    # which the rule alone would call rounding)
    monkeypatch.undo()

    def flat(X):
        return 2e-12 * X[:, 0] - (X[:, 1] + 1.0) ** 2

    x, _ = maximise_rows(flat, np.array([[0.3, -1.0]]), [0, 1], lo, np.array([0.5, 2.0]), h,
                         scale, lazy=True)
    assert x[0, 0] == 0.5


def test_the_idm_fit_scores_every_row_as_the_simulators_step_does():
    """``idm_sse`` evaluates the car following once per group of rows that differ only in
    the gap parameters (a scan): every row's sum equals the step-by-step replay with
    ``idm_step``, bit for bit, in the parallel and the serial kernel."""
    ev = _fast_idm_human()
    p = ev.runs[0].config.hv.idm
    base = np.array([getattr(p, n) for n in IDM_NAMES], float)
    rng = np.random.default_rng(3)
    gap, imp = IDM_NAMES.index("critical_gap_s"), IDM_NAMES.index("impatience_per_s")
    rows = [base]
    for v0, b in ((30.0, 1.0), (8.0, 3.0)):  # two groups, their gap parameters scanned
        for _ in range(4):
            r = base.copy()
            r[0], r[3] = v0, b
            r[gap], r[imp] = rng.uniform(0.0, 6.0), rng.choice([0.0, 0.3, 2.0])
            rows.append(r)
    prm = np.array(rows)
    lead = idm_groups(prm)
    assert lead.tolist() == [0, 1, 1, 1, 1, 5, 5, 5, 5]
    out = np.empty((ev.n_runs, len(prm)))
    serial = np.empty_like(out)
    idm_sse(ev.starts, ev.states, ev.accel, ev.P_hv, ev.P_av, ev.dt, prm, lead, out)
    idm_sse_serial(ev.starts, ev.states, ev.accel, ev.P_hv, ev.P_av, ev.dt, prm, lead, serial)
    np.testing.assert_array_equal(out, serial)
    log = np.zeros(16)
    for i in range(ev.n_runs):
        a, b = ev.starts[i], ev.starts[i + 1]
        for g in range(len(prm)):
            st, total = np.zeros(8), 0.0
            for k in range(a, b):
                s_o, v_o, s, v = ev.states[k]
                r = ev.accel[k] - idm_step(st, prm[g], s, v, s_o, v_o, ev.dt[i], ev.P_hv[i],
                                           ev.P_av[i], log)
                total += r * r
            assert out[i, g] == total, (i, g)
    assert len(set(out[0])) > 3  # the gap parameters change the decisions


# -- fits of simulated data ---------------------------------------------------------------------


def test_p_a_of_a_reluctant_human_is_recovered_and_p_a_1_excluded():
    _, ev = dataset(p_a=0.3, role="leader", runs=20)
    fit = fit_role_model(ev, "lfg")
    e = fit.params["p_a"]
    assert e.low <= 0.3 <= e.high and e.high < 1.0
    assert abs(e.value - 0.3) < 0.15
    assert e.method == "profile"
    assert fit.exact and fit.theta["sigma"] == pytest.approx(SIGMA_MIN)
    assert any("exact data" in note for note in fit.notes)
    assert fit.params["pi0"].value == 1.0 and fit.params["pi0"].high == 1.0
    assert fit.params["pi0"].method == "profile, one-sided: on the upper bound"


def test_a_willing_human_gets_a_one_sided_interval_at_p_a_1():
    _, ev = dataset(p_a=1.0, role="leader", runs=20)
    e = fit_role_model(ev, "lfg").params["p_a"]
    assert e.value == 1.0 and e.high == 1.0
    assert e.method == "profile, one-sided: on the upper bound"
    assert 0.6 < e.low < 1.0


def test_acceleration_noise_is_estimated_and_p_a_still_recovered():
    _, ev = dataset(p_a=0.5, role="follower", noise=0.1, runs=20)
    fit = fit_role_model(ev, "lfg")
    # uniform noise of half-width 0.1 has standard deviation 0.1 / sqrt(3)
    assert fit.theta["sigma"] == pytest.approx(0.1 / math.sqrt(3), rel=0.1)
    assert not fit.exact
    s = fit.params["sigma"]
    assert s.low < fit.theta["sigma"] < s.high
    e = fit.params["p_a"]
    assert e.low <= 0.5 <= e.high and e.high - e.low < 0.6


@pytest.mark.parametrize("kind,noise", [("stubborn", 0.0), ("noisy", 0.1), ("idm", 0.1),
                                        ("lfg", 0.1)])
def test_model_selection_names_the_generating_kind(kind, noise):
    _, ev = dataset(kind=kind, p_a=0.7 if kind != "stubborn" else 1.0, noise=noise, runs=16)
    report = fit_models(ev, intervals=False)
    assert report.selected == kind
    rows = report.comparison()
    assert rows[0]["model"] == kind and rows[1]["delta_bic"] > 0
    assert report.fits["noisy"].loglik >= report.fits["lfg"].loglik - 1e-6  # nested


def test_stubborn_data_select_the_stubborn_human():
    _, ev = dataset(kind="stubborn", runs=12)
    report = fit_models(ev, ["lfg", "stubborn"], intervals=False)
    assert report.selected == "stubborn"
    # the stubborn model is the LFG at p_a = 0: the same likelihood, one parameter fewer
    assert report.fits["lfg"].theta["p_a"] == pytest.approx(0.0, abs=1e-6)
    assert report.fits["lfg"].loglik == pytest.approx(report.fits["stubborn"].loglik, abs=1e-6)


def test_smoothed_roles_follow_the_true_roles_where_the_roles_act_differently():
    records, ev = dataset(p_a=0.5, role="leader", runs=12)
    report = fit_models(ev, ["lfg"], intervals=False)
    assert report.role_model == "lfg"
    for i, rec in enumerate(records):
        a, b = ev.starts[i], ev.starts[i + 1]
        truth = rec.log["hv_role"] == "leader"
        differ = ev.a_role[a:b, 0] != ev.a_role[a:b, 1]
        p = report.p_leader[a:b]
        np.testing.assert_array_equal(p[differ] > 0.5, truth[differ])
        assert np.all((p[differ] < 1e-6) | (p[differ] > 1 - 1e-6))


# -- files ----------------------------------------------------------------------------------------


def test_a_fits_parquet_gives_back_each_run_with_its_smoothed_role(tmp_path):
    from persuasive.plots import profile_single

    records, _ = dataset(p_a=0.5, runs=4)
    paths = []
    for j, rec in enumerate(records):
        path = tmp_path / f"run{j}.parquet"
        rec.save(path)
        paths.append(str(path))
    ev = evidence_of(load_logs(paths))
    report = fit_models(ev, ["lfg", "stubborn"], intervals=False)
    out = tmp_path / "fit.parquet"
    write_fit_parquet(out, [report], {"selected": report.selected})
    for j, rec in enumerate(records):
        run = load_fitted_run(out, j)
        np.testing.assert_array_equal(run.states, rec.states)
        assert run.outcome == rec.outcome and run.seed == rec.seed
        a, b = ev.starts[j], ev.starts[j + 1]
        np.testing.assert_array_equal(run.log["hv_fit_p_leader"], report.p_leader[a:b])
        for name, col in rec.log.items():
            np.testing.assert_array_equal(run.log[name], col)
    fig = profile_single(load_fitted_run(out, 1))
    assert any(line.get_gid() == "hv-role-fit" for ax in fig.axes for line in ax.lines)
    with pytest.raises(ConfigError, match="out of range"):
        load_fitted_run(out, 4)


def _bad(tmp_path, name, frame=None, meta=True):
    import pyarrow as pa
    import pyarrow.parquet as pq

    rec = simulate(Config(), 1)
    path = tmp_path / name
    if frame is None:
        frame = rec.frame()
    table = pa.Table.from_pandas(frame, preserve_index=False)
    if meta:
        rec_meta = read_log_meta(rec)
        table = table.replace_schema_metadata({b"persuasive.run": rec_meta})
    pq.write_table(table, path)
    return str(path)


def read_log_meta(rec):
    import json

    return json.dumps({"config_toml": rec.config.to_toml(), "seed": rec.seed,
                       "streams": rec.streams, "final_state": [float(x) for x in rec.states[-1]],
                       "version": rec.version})


def test_bad_logs_are_refused_in_one_line_naming_the_file(tmp_path):
    rec = simulate(Config(), 1)
    frame = rec.frame()
    csv = tmp_path / "run.csv"
    frame.to_csv(csv, index=False)
    cases = {
        str(csv): "CSV log",
        str(tmp_path / "missing.parquet"): "cannot be read",
        _bad(tmp_path, "nometa.parquet", meta=False): "holds no run record",
        _bad(tmp_path, "cols.parquet", frame.drop(columns=["hv_accel_mps2"])): "lacks the columns",
        _bad(tmp_path, "empty.parquet", frame.iloc[:0]): "empty",
        _bad(tmp_path, "nan.parquet", frame.assign(
            av_meas_v_mps=np.where(frame["step"] == 7, np.nan, frame["av_meas_v_mps"]))):
            "non-finite value (nan) in av_meas_v_mps at step 7",
    }
    for path, words in cases.items():
        with pytest.raises(ConfigError) as info:
            read_log(path)
        text = str(info.value)
        assert words in text and path in text and "\n" not in text
    # scenarios: another than the first log's, or than the one asked for
    good = tmp_path / "good.parquet"
    rec.save(good)
    merge = tmp_path / "merge.parquet"
    simulate(Config().with_overrides({"scenario.kind": "merge"}), 1).save(merge)
    with pytest.raises(ConfigError, match="is of scenario 'merge', not the model's"):
        load_logs([str(good), str(merge)])
    with pytest.raises(ConfigError, match="not the model's 'merge'"):
        load_logs([str(good)], scenario="merge")
    with pytest.raises(ConfigError, match="no log"):
        load_logs([])


# -- sigma_min and the intervals' bounds (issue 23) -----------------------------------------------


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf, 1e308, 1e200, 1.5, 1e-320,
                                   1e-10, 0.0, -1e-3, True, "0.1", None])
def test_sigma_min_outside_its_range_is_refused_by_every_fit(value):
    _, ev = dataset(p_a=0.3, role="leader", runs=2)
    calls = [lambda: check_sigma_min(value), lambda: fit_models(ev, ["lfg"], value),
             lambda: fit_role_model(ev, "lfg", value), lambda: fit_idm(ev, value),
             lambda: fit_models(ev, ["idm"], value, intervals=False)]
    for call in calls:
        with pytest.raises(ConfigError) as info:
            call()
        text = str(info.value)
        assert text.startswith("sigma_min = ") and "allowed: [1e-09, 1] m/s^2" in text
        assert "\n" not in text


def test_sigma_min_at_the_ends_of_its_range():
    assert check_sigma_min(1e-9) == 1e-9 and check_sigma_min(1) == 1.0
    assert SIGMA_MIN_RANGE == (1e-9, 1.0)
    # exact data (no noise): every role model that reproduces them gains exactly
    # n log(1e-3 / 1e-9) from the lower floor, the shared constant of docs/method.md §13.4
    _, ev = dataset(p_a=0.3, role="leader", runs=20)
    at = {s: fit_role_model(ev, "lfg", s, intervals=False) for s in (SIGMA_MIN, 1e-9)}
    assert all(f.exact and math.isfinite(f.loglik) for f in at.values())
    assert at[1e-9].loglik - at[SIGMA_MIN].loglik == pytest.approx(
        ev.n_steps * math.log(1e6), rel=1e-9)
    assert at[1e-9].theta["p_a"] == pytest.approx(at[SIGMA_MIN].theta["p_a"], abs=1e-6)
    # the top of the range: sigma keeps room below its own bound, and its interval runs forwards
    fit = fit_role_model(ev, "lfg", 1.0)
    s = fit.params["sigma"]
    assert 1.0 <= s.low <= s.value <= s.high <= SIGMA_MAX


def _quadratic(x0: float, scale: float, ell_hat: float):
    """A profile log-likelihood with its maximum ell_hat at x0 and curvature 1 / scale^2."""
    return lambda x: ell_hat - 0.5 * ((np.asarray(x) - x0) / scale) ** 2


@pytest.mark.parametrize("x0,bound_side_", [(1.0, "upper"), (0.0, "lower")])
def test_an_estimate_on_a_bound_gets_the_boundary_corrected_cutoff(x0, bound_side_):
    # profile quadratic: the limit where 2 (ell_hat - prof) = c is x0 -+ scale sqrt(c), and
    # the interpolation in the signed root is exact for it
    scale, ell_hat = 0.1, -50.0
    low, high, one = profile_interval(_quadratic(x0, scale, ell_hat), x0, ell_hat, 0.0, 1.0,
                                      width=1.96 * scale)
    assert one and bound_side(x0, 0.0, 1.0) == bound_side_
    c271, c384 = chi2.ppf(0.90, 1), chi2.ppf(0.95, 1)
    assert 2 * DROP_ONE_SIDED == pytest.approx(c271, rel=1e-12)  # 1/2 chi2(0) + 1/2 chi2(1)
    if bound_side_ == "upper":
        assert high == 1.0 and low == pytest.approx(1.0 - scale * math.sqrt(c271), abs=1e-9)
        assert abs(low - (1.0 - scale * math.sqrt(c384))) > 0.01  # not the two-sided cutoff
    else:
        assert low == 0.0 and high == pytest.approx(scale * math.sqrt(c271), abs=1e-9)


def test_an_interior_estimate_gets_the_two_sided_cutoff_and_stops_at_the_bounds():
    ell_hat = 10.0
    low, high, one = profile_interval(_quadratic(0.5, 0.1, ell_hat), 0.5, ell_hat, 0.0, 1.0,
                                      width=0.196)
    z = math.sqrt(chi2.ppf(0.95, 1))
    assert not one and low == pytest.approx(0.5 - 0.1 * z, abs=1e-9)
    assert high == pytest.approx(0.5 + 0.1 * z, abs=1e-9)
    # near a bound the profile is searched up to it, never past it: a limit not reached before
    # the bound is the bound (whatever the quadratic approximation's width says)
    for width in (0.196, 5.0, None):
        low, high, one = profile_interval(_quadratic(0.9, 0.1, ell_hat), 0.9, ell_hat, 0.0, 1.0,
                                          width=width)
        assert not one and high == 1.0 and low == pytest.approx(0.9 - 0.1 * z, abs=1e-9)


@functools.lru_cache(maxsize=None)
def _fast_idm_human():
    """An IDM human whose desired speed (45 m/s) is above the fit's bound (30 m/s), on a road
    where it reaches 20 m/s: the IDM's fit ends on the bound."""
    cs = [Config(mode="corrected").with_overrides({
        "hv.kind": "idm", "hv.idm.desired_speed_mps": 45.0, "hv.vehicle.v_max_mps": 20.0,
        "simulation.accel_noise_mps2": 0.05, "mpc.p_a_hat": 1.0, "av.kind": av})
        for av in ("persuasive", "passive")]
    records = [simulate(cs[j % 2], 1 + j) for j in range(8)]
    return evidence_of([run_log_of(r, f"run{j}") for j, r in enumerate(records)])


def test_an_idm_estimate_on_its_bound_gets_a_profile_interval_inside_the_range():
    from scipy.optimize import brentq, minimize

    from persuasive.fitting.idm import FITTED, IDMObjective
    from persuasive.fitting.models import IDM_NAMES

    ev = _fast_idm_human()
    fit = fit_idm(ev)
    e = fit.params["desired_speed_mps"]
    assert e.value == 30.0 and e.high == 30.0
    assert e.method == "profile, one-sided: on the upper bound"
    # the hand-computed profile: at each desired speed, Nelder-Mead over the other three
    # smooth parameters (log scale), the gap parameters held as the fit holds them
    p = ev.runs[0].config.hv.idm
    obj = IDMObjective(ev, np.array([getattr(p, n) for n in IDM_NAMES], float), SIGMA_MIN)
    y_hat = np.array([math.log(fit.theta[n]) if log else fit.theta[n]
                      for n, _, _, log in FITTED])

    def drop2(v0):
        def neg(z):
            y = y_hat.copy()
            y[0], y[1:4] = math.log(v0), z
            return -obj.loglik(y[None])[0]
        res = minimize(neg, y_hat[1:4], method="Nelder-Mead",
                       options={"xatol": 1e-6, "fatol": 1e-9, "maxfev": 800})
        return 2.0 * (fit.loglik + res.fun)

    c271 = brentq(lambda v: drop2(v) - chi2.ppf(0.90, 1), 15.0, 30.0, xtol=1e-3)
    c384 = brentq(lambda v: drop2(v) - chi2.ppf(0.95, 1), 15.0, 30.0, xtol=1e-3)
    assert c384 < c271 - 0.3  # the two cutoffs are told apart
    # 0.1 %: the fit maximises each profile point by 8 Newton steps, the hand one by
    # Nelder-Mead (they agree to 3e-5 here; the two cutoffs' limits differ by 2.6 %)
    assert e.low == pytest.approx(c271, rel=1e-3)
    # every interval within its parameter's range, and the gap scans reach the bounds
    for name, lo, hi, _ in FITTED:
        est = fit.params[name]
        assert lo <= est.low <= est.value <= est.high <= hi, name
    imp = fit.params["impatience_per_s"]
    assert (imp.low, imp.high) == (0.0, 2.0) and "whole range" in imp.note


# -- the measurement model over role paths ---------------------------------------------------


@pytest.mark.parametrize("sigma", [0.05, 0.3])
def test_the_path_likelihood_equals_brute_force_enumeration(sigma):
    """A filtered run (``persuasive.fitting.models.path_loglik_run``): the recorded value of a
    step is a band over the neighbours' accelerations, each in the role it held then; the
    forward pass over role paths equals the sum over every role sequence of the run (9 steps
    around a role change; a band of 4 taps, its weights different on every row)."""
    records, ev_all = dataset(p_a=0.5, runs=4, first_seed=2)
    i, k = next((i, int(np.flatnonzero(r.log["hv_next_role"] != r.log["hv_role"])[0]))
                for i, r in enumerate(records) if r.outcome.hv_role_changes)
    a = ev_all.starts[i] + max(0, k - 4)
    n = 9
    a_raw = ev_all.a_role[a:a + n].copy()
    pl = ev_all.pl[a:a + n].copy()
    rng = np.random.default_rng(3)
    off = np.array([-2, -1, 0, 1])
    W = rng.uniform(0.1, 1.0, (n, off.size))
    W /= W.sum(axis=1, keepdims=True)
    # what the band records of the true roles' accelerations, plus noise
    accel = ev_all.accel[a:a + n] + rng.normal(0.0, 0.02, n)
    p_a = np.array([0.0, 0.37, 1.0])
    sig = np.full(3, sigma)
    out = np.empty((1, 3, 2))
    path_loglik_serial(np.array([0]), np.array([0, n]), accel, a_raw, pl, off, W, p_a, sig, out)
    both = np.empty_like(out)
    path_loglik(np.array([0]), np.array([0, n]), accel, a_raw, pl, off, W, p_a, sig, both)
    np.testing.assert_array_equal(out, both)
    for g, p in enumerate(p_a):
        for r0 in (0, 1):
            terms = []
            for path in itertools.product((0, 1), repeat=n):
                if path[0] != r0:
                    continue
                lp = 0.0
                for t in range(n - 1):
                    tr = transition_matrix(pl[t, path[t]], p)[path[t + 1], path[t]]
                    lp += math.log(tr) if tr > 0 else -math.inf
                for t in range(n):
                    c = np.clip(t + off, 0, n - 1)
                    mu = float(np.sum(W[t] * a_raw[c, np.array(path)[c]]))
                    z = (accel[t] - mu) / sigma
                    lp += -0.5 * z * z - math.log(sigma) - 0.5 * math.log(2.0 * math.pi)
                terms.append(lp)
            want = _log_sum(terms)
            assert math.isclose(out[0, g, r0], want, rel_tol=1e-10, abs_tol=1e-9), (g, r0)


def test_exactly_filtered_runs_recover_the_unfiltered_fit():
    """Runs whose recorded accelerations are exactly the tracks' filter of the applied ones
    (window 7, each run a whole track): the fit over role paths gives the ``lfg`` the ``p_a``
    and ``sigma`` of the unfiltered runs; holding the role over the window (the approximation
    :attr:`Evidence.a_role` keeps) biases ``p_a`` low and reads the role changes as noise."""
    from dataclasses import replace

    from persuasive.fitting.evidence import RunLog
    from persuasive.recordings.tracks import SmoothingParams, acceleration_band

    records, plain = dataset(p_a=0.7, runs=12, first_seed=40)
    smoothing = SmoothingParams()
    logs = []
    for j, r in enumerate(records):
        log = run_log_of(r, f"run{j}")
        n = log.n_steps
        off, w = acceleration_band(smoothing, n + 1, 0, n)
        idx = np.arange(n)[:, None] + off[None, :]
        inside = (idx >= 0) & (idx < n)
        accel = np.sum(w * log.accel[np.clip(idx, 0, n - 1)] * inside, axis=1)
        meta = {"recording": {"smoothing": {"window": 7, "order": 3, "min_track_s": 2.0,
                                            "speed": "file"},
                              "human": 2, "track_k0_2": 0, "track_n_2": n + 1}}
        logs.append(RunLog(log.source, log.config, log.seed, None, log.states, accel, meta))
    ev = evidence_of(logs)
    assert ev.filtered.all() and set(range(-3, 3)) <= set(ev.band_off.tolist())
    truth = fit_models(plain, ["lfg"], intervals=False).fits["lfg"].theta
    paths = fit_models(ev, ["lfg"], intervals=False).fits["lfg"].theta
    held = fit_models(replace(ev, filtered=None), ["lfg"], intervals=False).fits["lfg"].theta
    # 0.7028 and sigma at its floor both ways; held over the window: 0.53, sigma 0.15
    assert paths["p_a"] == pytest.approx(truth["p_a"], abs=1e-6)
    assert paths["sigma"] == pytest.approx(truth["sigma"], abs=1e-9)
    assert abs(held["p_a"] - truth["p_a"]) > 0.1 and held["sigma"] > 0.1
