"""The paper's attitude design (synthesis/loops, design, robustness, baselines, export) against
independent answers: python-control interconnections, closed forms, scipy's Riccati solver
and the autopilot's schedule reader."""

from __future__ import annotations

import json
import math
import pickle
from pathlib import Path

import control as ct
import numpy as np
import pytest
import scipy.linalg

from vtolftc.firmware_sim.autopilot.schedule import GainSchedule
from vtolftc.synthesis.baselines import LQR_Q, LQR_R, lqr_design
from vtolftc.synthesis.design import R_MAX_RAD, design_point, moment_authority, weights_for
from vtolftc.synthesis.export import (
    LQR_FORMAT,
    jsonable,
    lqr_document,
    schedule_document,
    write_json,
)
from vtolftc.synthesis.hinfnorm import frequency_response, hinf_norm
from vtolftc.synthesis.loops import (
    PARAM_NAMES,
    CascadeChannel,
    ControlWeight,
    SensitivityWeight,
    closed_loop,
)
from vtolftc.synthesis.models import AXES, attitude_model
from vtolftc.synthesis.mu import mu_bounds
from vtolftc.synthesis.robustness import RP_BLOCKS, analyse, rp_matrix, square_rp
from vtolftc.synthesis.uncertainty import PAPER_DESIGN_POINTS

GAINS_DIR = Path(__file__).resolve().parents[1] / "firmware_sim" / "autopilot" / "gains"


def _resp(sys, w):
    return np.array([complex(np.squeeze(sys(1j * x))) for x in w])


def _reference_loops(G, th):
    """S, T_u, R of the cascade built with python-control's feedback (independent path)."""
    kpa, kp, ki, kd, tf = th
    K = ct.tf([kp * tf + kd, kp + ki * tf, ki], [tf, 1.0, 0.0])
    Gr = ct.ss(G.A, G.B, G.C[[0]], 0)
    Ga = ct.ss(G.A, G.B, G.C[[1]], 0)
    inner = ct.feedback(K, Gr)                       # rate_ref -> u with rate feedback
    R = ct.feedback(kpa * inner, Ga)                 # r -> u with the outer angle loop
    S = 1 - ct.feedback(kpa * Ga * inner, 1)         # e = r - angle
    Tu = ct.feedback(K * (kpa * Ga + Gr), 1)         # loop broken at the plant input
    return S, Tu, R


@pytest.mark.parametrize("axis,V", [("roll", 0.0), ("pitch", 7.0), ("yaw", 13.0),
                                    ("yaw", 4.0)])
def test_loop_builder_matches_python_control_feedback(ds1, axis, V):
    rng = np.random.default_rng(7)
    G = attitude_model(ds1, axis, V)
    for _ in range(3):
        th = [rng.uniform(0.5, 6), rng.uniform(0.5, 10), rng.uniform(0.1, 5),
              rng.uniform(0, 1), rng.uniform(0.01, 0.2)]
        cl = closed_loop(G, th)
        S, Tu, R = _reference_loops(G, th)
        w = 10 ** rng.uniform(-2, 2, 8)
        for mine, ref in ((cl.S(), S), (cl.T_u(), Tu), (cl.R(), R)):
            a = frequency_response(mine, w)[:, 0, 0]
            b = _resp(ref, w)
            np.testing.assert_allclose(a, b, rtol=1e-8, atol=1e-12)


def test_weights_state_space_equals_transfer_function():
    w = np.logspace(-3, 3, 13)
    for W in (SensitivityWeight(1.6, 1.1, 1e-3), ControlWeight(0.5, 90.0, 5.0)):
        a = frequency_response(W.ss(), w)[:, 0, 0]
        np.testing.assert_allclose(a, _resp(W.tf(), w), rtol=1e-10)
        np.testing.assert_allclose(a, W.response(w), rtol=1e-10)
    Ws = SensitivityWeight(2.0, 1.0, 1e-3)
    assert abs(Ws.response(np.array([1e-9]))[0]) == pytest.approx(1e3, rel=1e-5)
    assert abs(Ws.response(np.array([1e9]))[0]) == pytest.approx(0.5, rel=1e-5)
    with pytest.raises(ValueError, match="A"):
        SensitivityWeight(2.0, 1.0, 0.0)


def test_cascade_channel_rows_and_pickle(ds1):
    G = attitude_model(ds1, "pitch", 10.0)
    w = weights_for(ds1, "pitch", PAPER_DESIGN_POINTS[4])
    ch = CascadeChannel(G, w.Ws, w.Wt.tf(), w.Wr)
    th = np.array([3.0, 4.0, 5.0, 0.2, 0.03])
    om = np.logspace(-2, 2, 9)
    cl = closed_loop(G, th)
    rows = ch.rows(th)
    expect = {"Ws*S": w.Ws.response(om) * frequency_response(cl.S(), om)[:, 0, 0],
              "Wt*T": w.Wt.magnitude(om) * np.abs(frequency_response(cl.T_u(), om)[:, 0, 0]),
              "Wr*R": w.Wr.response(om) * frequency_response(cl.R(), om)[:, 0, 0]}
    for k, v in expect.items():
        np.testing.assert_allclose(np.abs(frequency_response(rows[k], om)[:, 0, 0]), np.abs(v),
                                   rtol=1e-8)
    stack = hinf_norm(ch(th)).value
    parts = [hinf_norm(r).value for r in rows.values()]
    assert max(parts) <= stack + 1e-9 <= math.sqrt(sum(p * p for p in parts)) + 1e-6
    fast, slow = ch(th), ch.reference(th)   # direct assembly == series + stack
    np.testing.assert_allclose(frequency_response(fast, om), frequency_response(slow, om),
                               rtol=1e-9, atol=1e-12)
    ch2 = pickle.loads(pickle.dumps(ch))
    for a, b in zip(ch(th), ch2(th), strict=True):
        np.testing.assert_array_equal(a, b)


def test_cascade_channel_assembly_is_the_obvious_one_bit_for_bit(ds1):
    """The channel's fast assembly (shared closed loops, precomputed slices) gives the same
    bits as building the loop anew and placing np.outer products, as the tuner did before:
    the shipped gains depend on it."""
    from vtolftc.synthesis.loops import _closed, _plant
    from vtolftc.synthesis.robust import delay_weight

    G = attitude_model(ds1, "roll", 6.0)
    w = weights_for(ds1, "roll", PAPER_DESIGN_POINTS[2])
    Wd = (np.array([[-0.004]]), np.array([[1.0]]), np.array([[0.3]]), np.array([[0.7]]))
    chans = [CascadeChannel(G, w.Ws, w.Wt.tf(), w.Wr), CascadeChannel(G, Wd=Wd),
             CascadeChannel(G, Wt=delay_weight(0.05)), CascadeChannel(G, w.Ws, Wd=Wd)]
    rng = np.random.default_rng(3)
    for _ in range(20):
        th = np.array([rng.uniform(0.3, 8), rng.uniform(0.1, 30), rng.uniform(0.1, 90),
                       rng.uniform(0, 2), rng.uniform(0.01, 1)])
        cl = _closed(_plant(G), th)
        for ch in chans:
            A, B, C, D = ch(th)
            Ws, Wt, Wr = ch._W
            off, n = ch._off, ch._ncl
            A2, C2 = ch._A0.copy(), ch._C0.copy()
            B2, D2 = np.zeros_like(B), np.zeros_like(D)
            A2[:n, :n], B2[:n, 0] = cl.A, cl.B[:, 0]
            for W, k, o, name in ((Ws, 1, 0, "Ws*S"), (Wr, 2, 1, "Wr*R")):
                if W is not None:
                    sl, r = slice(off[k], off[k + 1]), ch._rows[name]
                    A2[sl, :n] = np.outer(W[1][:, 0], cl.C[o])
                    B2[sl, 0] = W[1][:, 0] * cl.D[o, 0]
                    C2[r, :n] = W[3][0, 0] * cl.C[o]
                    D2[r, 0] = W[3][0, 0] * cl.D[o, 0]
            for W, k, name, Cx in ((Wt, 3, "Wt*T", -cl.C[1]), (ch._Wd, 5, "Wd*Sd", cl.C[0])):
                if W is not None:
                    c2, sl = slice(off[k], off[k + 1]), slice(off[k + 1], off[k + 2])
                    A2[c2, c2], B2[c2, 0] = cl.A, cl.B[:, 1]
                    A2[sl, c2] = np.outer(W[1][:, 0], Cx)
                    C2[ch._rows[name], c2] = W[3][0, 0] * Cx
            for x, y in zip((A, B, C, D), (A2, B2, C2, D2), strict=True):
                assert x.tobytes() == y.tobytes()


def test_batched_realisations_and_derivatives_are_the_per_point_ones_bit_for_bit(ds1):
    """The tuner's finite differences realise a channel at its 2p perturbed points in one
    call (CascadeChannel.realize_batch) and its gradients take stacked products: every
    slice must be the per-point channel, and every derivative and gradient the one-point-
    at-a-time computation, to the last bit (the shipped gains depend on it)."""
    from vtolftc.synthesis.robust import RobustSpec, _robust_problem, robust_weights
    from vtolftc.synthesis.structured import _Evaluator, _sample_start

    spec = RobustSpec()
    rng = np.random.default_rng(7)
    for ax in AXES:
        ws = [robust_weights(ds1, ax, p, spec) for p in PAPER_DESIGN_POINTS[1:3]]
        pb = _robust_problem(ds1, ax, ws, spec)[0]
        ev, ev_loop = _Evaluator(pb), _Evaluator(pb)
        ev_loop._derivatives_batch = lambda th: None   # the one-point-at-a-time path
        for t in range(6):
            th = pb.initial if t == 0 else _sample_start(pb, rng, 1.0)
            pts = th + rng.standard_normal((4, th.size)) * 1e-3 * np.abs(th)
            for ch in pb.channels:
                for X, Xs in zip(zip(*[ch(q) for q in pts], strict=True),
                                 ch.realize_batch(pts), strict=True):
                    assert np.stack(X).tobytes() == Xs.tobytes()
            for di, dj in zip(ev.derivatives(th), ev_loop.derivatives(th), strict=True):
                for a, b in zip(di, dj, strict=True):
                    assert all(x.tobytes() == y.tobytes() for x, y in zip(a, b, strict=True))
            om = [np.r_[np.geomspace(0.01, 100, 7 + i % 5), np.inf] for i in
                  range(len(pb.channels))]
            for grad in (True, False):
                sa, ga = ev.sigma_and_grad(th, om, grad)
                sb, gb = ev_loop.sigma_and_grad(th, om, grad)
                assert sa.tobytes() == sb.tobytes()
                assert (ga is None and gb is None) or ga.tobytes() == gb.tobytes()
            (va, ga), (vb, gb) = ev.abscissa_and_grad(th), ev_loop.abscissa_and_grad(th)
            assert va.tobytes() == vb.tobytes() and ga.tobytes() == gb.tobytes()


def test_moment_authority_by_hand(ds1):
    th = ds1.weight_N / 8
    dT = min(th, 35.0 - th)
    assert moment_authority(ds1, "roll", 0.0) == pytest.approx((4 * 1.05 + 4 * 0.40) * dT)
    assert moment_authority(ds1, "pitch", 0.0) == pytest.approx((4 * 0.65 + 4 * 0.60) * dT)
    assert moment_authority(ds1, "yaw", 0.0) == pytest.approx(8 * 0.016 * dT)
    q = 0.5 * 1.225 * 13.0**2
    surf = q * 0.95 * 2.9 * 0.069 * math.radians(25.0)
    assert moment_authority(ds1, "yaw", 13.0) == pytest.approx(8 * 0.016 * dT + surf)


def test_design_point_deterministic_stable_and_in_bounds(ds1):
    pt = PAPER_DESIGN_POINTS[5]
    a = design_point(ds1, "roll", pt, n_starts=1, seed=3, max_iter=15)
    b = design_point(ds1, "roll", pt, n_starts=1, seed=3, max_iter=15)
    assert a.gains == b.gains
    assert a.stable and math.isfinite(a.norms["gamma"])
    assert a.gains["tf_rate_s"] >= 0.01 - 1e-12
    assert all(a.gains[k] >= 0 for k in PARAM_NAMES)
    # the stacked norm is at least each requirement and at least the Wt T floor |Wt(0)|
    assert a.norms["gamma"] >= max(a.norms["Ws*S"], a.norms["Wt*T"], a.norms["Wr*R"]) - 1e-9
    wt0 = float(a.weights[0].Wt.magnitude(np.array([1e-8]))[0])
    assert a.norms["Wt*T"] >= wt0 * (1 - 1e-6)
    # the reported norms are those of the returned gains
    G = attitude_model(ds1, "roll", pt.airspeed_m_s)
    w = a.weights[0]
    assert hinf_norm(CascadeChannel(G, w.Ws, w.Wt.tf(), w.Wr)(a.theta)).value == \
        pytest.approx(a.norms["gamma"], rel=1e-6)


def test_robust_stability_mu_equals_closed_form(ds1):
    pt = PAPER_DESIGN_POINTS[3]
    w = weights_for(ds1, "pitch", pt)
    G = attitude_model(ds1, "pitch", pt.airspeed_m_s)
    th = [3.0, 4.0, 6.0, 0.2, 0.03]
    r = analyse(G, th, w.Ws, w.Wt, w.Wr, np.logspace(-3, 3, 41))
    Tu = frequency_response(closed_loop(G, th).T_u(), r.omegas)[:, 0, 0]
    np.testing.assert_allclose(r.rs.upper, w.Wt.magnitude(r.omegas) * np.abs(Tu), rtol=1e-6)
    assert r.rs_check < 1e-6
    assert np.all(r.rp.lower <= r.rp.upper * (1 + 1e-9))
    assert r.mu_rp >= r.mu_rs - 1e-9  # the RP structure contains the RS one


def test_robust_performance_siso_equals_sum_of_weighted_functions():
    """Plain unity-feedback SISO loop (no rate output): mu_hat = |Ws S| + |Wt T|."""
    # plant 1/(s (s + 1)) seen through the angle output only: rate row of C is zero
    A = np.array([[0.0, 1.0], [0.0, -1.0]])
    B = np.array([[0.0], [1.0]])
    C = np.array([[0.0, 0.0], [1.0, 0.0]])
    G = ct.ss(A, B, C, np.zeros((2, 1)))
    th = [1.0, 1.0, 0.2, 0.5, 0.05]        # K = kp_angle K_rate acting on e
    Ws = SensitivityWeight(2.0, 0.5, 1e-2)
    Wt = ct.tf([0.5, 0.2], [0.02, 1.0])
    om = np.logspace(-2, 2, 15)
    N = rp_matrix(G, th, Ws, Wt, None, om)
    cl = closed_loop(G, th)
    S = frequency_response(cl.S(), om)[:, 0, 0]
    Tu = frequency_response(cl.T_u(), om)[:, 0, 0]
    expect = np.abs(Ws.response(om) * S) + np.abs(_resp(Wt, om) * Tu)
    blocks = (RP_BLOCKS[0], RP_BLOCKS[0])
    for k in range(om.size):
        b = mu_bounds(N[k], blocks)
        assert b.lower <= b.upper * (1 + 1e-9)
        assert b.upper == pytest.approx(expect[k], rel=1e-4)
        assert b.lower == pytest.approx(expect[k], rel=1e-3)
    # padding for the 2-output performance block leaves mu unchanged
    N3 = rp_matrix(G, th, Ws, Wt, ControlWeight(0.5, 10.0), om[:3])
    assert square_rp(N3).shape == (3, 3, 3)


def test_lqr_matches_riccati_and_law_signs(ds1):
    des = lqr_design(ds1)
    for ax in AXES:
        d = des[ax]
        P = scipy.linalg.solve_continuous_are(d.A, d.B, np.diag(LQR_Q), np.array([[LQR_R]]))
        K = (d.B.T @ P / LQR_R).ravel()
        assert (d.k_int, d.k_angle, d.k_rate) == pytest.approx((-K[0], K[1], K[2]), rel=1e-6)
        assert d.k_int > 0 and d.k_angle > 0 and d.k_rate > 0
        # the law tau = k_int xi + k_angle (0 - angle) - k_rate rate closes a stable loop
        Kl = np.array([[d.k_int, -d.k_angle, -d.k_rate]])
        eig = np.linalg.eigvals(d.A + d.B @ Kl)
        assert np.max(eig.real) < 0
        np.testing.assert_allclose(np.sort_complex(eig), np.sort_complex(np.array(d.poles)),
                                   rtol=1e-6)


def test_export_documents_load_with_the_autopilot_reader(ds1, tmp_path):
    g = {"kp_angle": 4.0, "kp_rate": 3.0, "ki_rate": 1.0, "kd_rate": 0.1, "tf_rate_s": 0.02}
    doc = schedule_document(ds1, "gs-shif", [0.0, 4.0], {ax: [g, g] for ax in AXES},
                            {ax: {"norm": math.inf} for ax in AXES}, {"x": np.float64(1.5)})
    p = write_json(tmp_path / "s.json", doc)
    s = GainSchedule.load(p)
    s.verify_airframe(ds1.name, ds1.sha256)
    assert s.gains_at(2.0)["pitch"].kp_rate == pytest.approx(3.0)
    # the project's one JSON convention (vtolftc.jsonio): a non-finite number is null
    assert json.loads(p.read_text())["axes"]["roll"]["metadata"]["norm"] is None
    assert not list(tmp_path.glob(".*.tmp"))  # atomic write left no temp file
    lq = lqr_document(ds1, {ax: {"k_int": 1, "k_angle": 2, "k_rate": 3} for ax in AXES})
    assert lq["format"] == LQR_FORMAT and lq["airspeed_breakpoints_m_s"] == [0.0]
    assert jsonable(complex(1, 2)) == [1.0, 2.0]


def test_shipped_default_gains_match_the_shipped_airframe(ds1):
    for name in ("gs-shif", "shif"):
        s = GainSchedule.load(GAINS_DIR / f"{name}.json")
        assert s.controller == name
        s.verify_airframe(ds1.name, ds1.sha256)  # re-run the synthesis if the airframe changed
    # the robust design (default) schedules over 0..18 m/s; the paper's over 0..13 m/s
    assert GainSchedule.load(GAINS_DIR / "gs-shif.json").breakpoints_m_s[-1] == 18.0
    assert len(GainSchedule.load(GAINS_DIR / "gs-shif.json").breakpoints_m_s) == 7
    assert len(GainSchedule.load(GAINS_DIR / "paper" / "gs-shif.json").breakpoints_m_s) == 6
    assert GainSchedule.load(GAINS_DIR / "shif.json").is_constant
    for name in ("gs-shif", "shif"):
        GainSchedule.load(GAINS_DIR / "paper" / f"{name}.json").verify_airframe(ds1.name,
                                                                              ds1.sha256)
    lq = json.loads((GAINS_DIR / "lqr.json").read_text())
    assert lq["format"] == LQR_FORMAT and lq["controller"] == "lqr"
    assert lq["airframe"]["sha256"] == ds1.sha256
    assert lq["airspeed_breakpoints_m_s"] == [0.0]
    for ax in AXES:
        for k in ("k_int", "k_angle", "k_rate"):
            v = lq["axes"][ax][k]
            assert len(v) == 1 and math.isfinite(v[0]) and v[0] > 0


def test_shipped_gains_are_physically_sensible(ds1):
    # paper design: the bounds of synthesis/design.py
    s = GainSchedule.load(GAINS_DIR / "paper" / "gs-shif.json")
    J = np.diag(ds1.inertia_kg_m2)
    for i, ax in enumerate(AXES):
        t = s.table[ax]
        assert min(t["tf_rate_s"]) >= 0.01 - 1e-9       # derivative filter vs 250 Hz
        assert max(t["kp_angle"]) <= 8.0 + 1e-9         # outer loop a few rad/s at most
        assert min(t["ki_rate"]) >= 2.0 * J[i] * (1 - 1e-5)   # integral action everywhere
        assert max(t["kp_rate"]) <= 40.0 * J[i] * (1 + 1e-5)  # rate crossover < 40 rad/s
    assert s.metadata["design_points"][2]["airspeed_m_s"] == 4.0
    assert s.metadata["weights"]["r_max_rad"] == R_MAX_RAD
    assert len(s.metadata["axes_metadata"]["roll"]["mu"]) == 6
    # robust design (shipped default): the physical bounds of synthesis/robust.py
    s = GainSchedule.load(GAINS_DIR / "gs-shif.json")
    w_act = 1.0 / 0.05                                  # DS-1 actuators: 50 ms lag
    for i, ax in enumerate(AXES):
        t = s.table[ax]
        assert min(t["tf_rate_s"]) >= 0.01 - 1e-9
        assert max(t["kp_angle"]) <= w_act / 2 + 1e-9   # outer loop <= omega_act / 2
        assert min(t["ki_rate"]) >= 0.1 * J[i] * (1 - 1e-5)   # integral action everywhere
        assert max(t["kp_rate"]) <= w_act * J[i] * (1 + 1e-5)  # rate crossover <= omega_act
    md = s.metadata["axes_metadata"]
    assert len(md["roll"]["mu"]) == 7
    for ax in AXES:   # the delay-margin requirement at every design point
        assert min(m["delay_margin_s"] for m in md[ax]["loop_margins"]) >= 0.05


def test_cli_rejects_bad_input(tmp_path, capsys):
    from vtolftc.cli import run

    assert run(["synth", "--starts", "-1", "--out", str(tmp_path)]) == 2
    assert "--starts" in capsys.readouterr().err
    assert run(["synth", "--airframe", str(tmp_path / "nope.toml"), "--out",
                str(tmp_path)]) == 2
    assert "no such file" in capsys.readouterr().err
    (tmp_path / "f").write_text("x")
    assert run(["synth", "--out", str(tmp_path / "f")]) == 2


@pytest.mark.slow
def test_full_synthesis_end_to_end(ds1, tmp_path):
    from vtolftc.synthesis.pipeline import run_synthesis

    res = run_synthesis(ds1, tmp_path, n_starts=1, jobs=2, seed=0, report=True,
                        method="paper")
    for name in ("gs-shif.json", "shif.json", "lqr.json", "report/README.md",
                 "report/mu_yaw.png", "report/wt_pitch.png", "report/poles_roll.png"):
        assert (tmp_path / name).is_file(), name
    s = GainSchedule.load(tmp_path / "gs-shif.json")
    s.verify_airframe(ds1.name, ds1.sha256)
    assert s.metadata["axes_metadata"]["yaw"]["mu"][0]["mu_rs"] > 0
    # must-show: nominal stability at all six points, three axes
    assert all(all(v) for v in res.nominal_stable().values())
    for ax in AXES:
        for d, m in zip(res.gs[ax], res.mu_gs[ax], strict=True):
            wt0 = float(d.weights[0].Wt.magnitude(np.array([1e-8]))[0])
            assert m.mu_rs >= wt0 * (1 - 1e-4)   # integral action: T_u(0) = 1 (grid from 1e-3)
            assert m.rs_check < 1e-6
    # what holds for DS-1 with the paper's weights: roll robustly stable at points 3-6
    assert all(m.mu_rs < 1.0 for m in res.mu_gs["roll"][2:])


def test_atomic_write_gives_ordinary_permissions(tmp_path):
    """Gain files are read by other users and processes (containers): not owner-only."""
    import os
    import stat

    from vtolftc.synthesis.export import atomic_write_text

    umask = os.umask(0o022)
    try:
        p = atomic_write_text(tmp_path / "sub" / "gains.json", "{}\n")
    finally:
        os.umask(umask)
    assert p.read_text() == "{}\n"
    assert stat.S_IMODE(p.stat().st_mode) == 0o644
    assert [q.name for q in p.parent.iterdir()] == ["gains.json"]   # no temp file left


@pytest.mark.slow
@pytest.mark.parametrize("sub", ["paper", "."])
def test_shipped_gains_are_what_the_synthesis_gives(ds1, tmp_path, sub):
    """The gains the autopilot ships are the output of `vtolftc synth` with the settings they
    record: same achieved norms at every point (the gains themselves may differ where a
    tie-break within 0.1 % picks another start on another machine's round-off). Fails when
    the synthesis code or the airframe changed without regenerating the gain files. ``paper``:
    ``--method paper`` still gives the paper design's numbers (gains/paper/, the shipped
    gains before the robust design); ``.``: the shipped robust design."""
    from vtolftc.firmware_sim.autopilot.attitude import default_gains_dir
    from vtolftc.synthesis.pipeline import run_synthesis

    shipped = json.loads((default_gains_dir() / sub / "gs-shif.json").read_text())
    st = shipped["settings"]
    run_synthesis(ds1, tmp_path, n_starts=st["n_starts"], jobs=2, seed=st["seed"],
                  report=False, mu=False, method=st.get("method", "paper"))
    fresh = json.loads((tmp_path / "gs-shif.json").read_text())
    for ax in AXES:
        want = [n["gamma"] for n in shipped["axes"][ax]["metadata"]["achieved_norms"]]
        got = [n["gamma"] for n in fresh["axes"][ax]["metadata"]["achieved_norms"]]
        assert np.allclose(got, want, rtol=2e-3), (
            f"{ax}: synthesis gives gamma {got}, shipped gains have {want}: regenerate "
            "firmware_sim/autopilot/gains with `vtolftc synth --out DIR` and copy the JSON files")
