"""pytest tests of the odomcov Python module (run by ctest as `python_tests`)."""
import os

import numpy as np
import pytest

import odomcov

ROOT = os.environ.get("ODOMCOV_SOURCE_DIR", os.path.join(os.path.dirname(__file__), "..", ".."))
FIG7 = os.path.join(ROOT, "configs", "kleeman95", "fig7.yaml")
FIG9 = os.path.join(ROOT, "configs", "kleeman95", "fig9.yaml")


def per_sample_travel(path, rate_hz):
    """Cumulative wheel travel sampled at rate_hz, with every keyframe time among the samples;
    returns (left, right, index of each keyframe)."""
    t_all, left, right, index = [], [], [], [0]
    for (t0, l0, r0), (t1, l1, r1) in zip(path[:-1], path[1:]):
        n = max(1, int(round((t1 - t0) * rate_hz)))
        for k in range(0 if not t_all else 1, n + 1):
            f = k / n
            t_all.append(t0 + f * (t1 - t0))
            left.append(l0 + f * (l1 - l0))
            right.append(r0 + f * (r1 - r0))
        index.append(len(t_all) - 1)
    return np.array(left), np.array(right), index


@pytest.mark.parametrize("config", [FIG7, FIG9])
@pytest.mark.parametrize("rate_hz", [7.0, 200.0])
def test_predict_matches_closed_form_at_keyframes(config, rate_hz):
    theory = odomcov.theory(config)
    left, right, index = per_sample_travel(theory["path"], rate_hz)
    out = odomcov.predict(left, right, theory["wheelbase"], theory["k_left"], theory["k_right"])
    assert out["pose"].shape == (len(left), 3)
    assert out["cov"].shape == (len(left), 3, 3)
    for i, k in zip(index, theory["keyframes"]):
        cov, expected = out["cov"][i], k["cov"]
        scale = max(np.abs(expected).max(), 1e-300)
        assert np.abs(cov - expected).max() <= 1e-9 * scale or i == 0
        assert np.allclose(out["pose"][i], k["pose"], rtol=0, atol=1e-12)
        assert np.array_equal(cov, cov.T)


def test_predict_with_effects_uses_the_engine():
    left = np.linspace(0, 4, 401)
    right = np.linspace(0, 4, 401)
    plain = odomcov.predict(left, right, 0.5, 1e-3, 1e-3)
    eff = odomcov.predict(left, right, 0.5, 1e-3, 1e-3, effects=[{"wheel_diameter_ratio": {"Ed": 1.01}}])
    # unequal diameters turn a straight encoder path: a heading mean of about (Ed-1)/(Ed+1) * 2 L / B
    heading_mean = eff["mean"][-1, 2]
    assert heading_mean == pytest.approx(2 * 0.01 / 2.01 * 4 / 0.5, rel=1e-6)
    assert np.abs(plain["mean"]).max() == 0
    with pytest.raises(ValueError):
        odomcov.predict(left, right, 0.5, 1e-3, 1e-3, effects=[{"wheel_diamter_ratio": {"Ed": 1.0}}])


def test_predict_takes_every_effect_the_configs_take():
    # The effects go through the configs' own parser: a custom effect written as the built-in
    # turn_dependent_wheelbase gives its numbers bit for bit, and errors name the key.
    t = np.linspace(0, 1, 201)
    left, right = 2.0 * t, 2.0 * t + 0.6 * np.sin(3 * t)
    builtin = odomcov.predict(left, right, 0.5, 1e-3, 1e-3,
                              effects=[{"turn_dependent_wheelbase": {"Eb_arc": 1.01, "Eb_spin": 1.03}}])
    custom = odomcov.predict(left, right, 0.5, 1e-3, 1e-3, effects=[{"custom": {
        "name": "tdw", "parameters": {"Eb_arc": 1.01, "Eb_spin": 1.03},
        "wheelbase_factor": "Eb_arc + (Eb_spin - Eb_arc) * r"}}])
    assert np.array_equal(builtin["mean"], custom["mean"]) and np.array_equal(builtin["cov"], custom["cov"])
    assert np.abs(builtin["mean"]).max() > 0
    with pytest.raises(ValueError, match=r"effects\[0\]\.custom\.parameters"):
        odomcov.predict(left, right, 0.5, 1e-3, 1e-3,
                        effects=[{"custom": {"name": "x", "parameters": [1], "scale": "1"}}])


def test_predict_takes_sample_times_for_speed_effects():
    # A speed-dependent scale needs each sample's duration: without t the speed is unknown and
    # the expression is not finite (ValueError); with t the slow and the fast halves differ.
    t = np.linspace(0, 10, 501)
    left = right = np.where(t < 5, 0.1 * t, 0.5 + 0.5 * (t - 5))  # 0.1 m/s, then 0.5 m/s
    speed = [{"custom": {"name": "speed_scale", "parameters": {"a": 0.02}, "scale": "1 + a * (v - 0.1)"}}]
    with pytest.raises(ValueError, match="nan"):
        odomcov.predict(left, right, 0.5, 1e-3, 1e-3, effects=speed)
    out = odomcov.predict(left, right, 0.5, 1e-3, 1e-3, effects=speed, t=t)
    # the scale is 1 at 0.1 m/s and 1.008 at 0.5 m/s over the 2.5 m of the second half
    assert out["mean"][250, 0] == pytest.approx(0.0, abs=1e-12)
    assert out["mean"][-1, 0] == pytest.approx(0.008 * 2.5, rel=1e-9)
    with pytest.raises(ValueError, match="increase"):
        odomcov.predict(left, right, 0.5, 1e-3, 1e-3, effects=speed, t=t[::-1])


def test_step_api():
    odo = odomcov.OdometryCovariance(0.5, 1e-3, 2e-3)
    s = odo.step(1.0, 1.2)
    assert s.J_out_in.shape == (3, 3) and s.J_out_wheels.shape == (3, 2)
    assert np.allclose(odo.cov, s.Q)  # the start is exactly known
    d, a = 1.1, 0.2 / 0.5
    assert np.allclose(s.pose, odomcov.arc_displacement(d, a))


def test_simulate_is_thread_invariant():
    a = odomcov.simulate(FIG7, runs=2000, seed=5, threads=1)
    b = odomcov.simulate(FIG7, runs=2000, seed=5, threads=2)
    assert np.array_equal(a["cov"], b["cov"]) and np.array_equal(a["mean"], b["mean"])
    e = odomcov.simulate(FIG7, runs=50, seed=5, threads=2, errors=True)
    assert e["errors"].shape == (50, 3)


def test_suite_commands(tmp_path):
    suite = odomcov.load_suite(os.path.join(ROOT, "tests", "data", "suites", "good_logs.yaml"))
    c = odomcov.compare(suite)
    assert [e["name"] for e in c["experiments"]] == suite.experiments
    assert c["verdict"] in ("consistent", "inconsistent", "untestable")
    f = odomcov.fit(suite, ["k_left"])
    assert "k_left" in f["parameters"] and f["log_likelihood_after"] >= f["log_likelihood_before"] - 1e-9
    with pytest.raises(ValueError):
        odomcov.fit(suite, ["k_lft"])
    d = odomcov.diagnose(suite)
    # The honest verdict: explained exactly when the final model is consistent, and otherwise
    # what the misfit lines up with.
    assert d["explained"] == (d["after"]["verdict"] == "consistent")
    assert d["explained"] or "residuals" in d
    assert all(c["verdict"] in ("adopted", "mimic", "stopped", "not significant", "not judged")
               for c in d["candidates"])
    with pytest.raises(ValueError):
        odomcov.load_suite(os.path.join(ROOT, "tests", "data", "suites", "nan.yaml"))


def test_degenerate_fits_say_no_standard_error_rather_than_nan():
    # Ten runs with no heavy tails: the bumps candidate's rate fits at 0, where the likelihood
    # gives no standard error; its explanation says so in words (it printed "+/- nan").
    suite = odomcov.load_suite(os.path.join(ROOT, "tests", "data", "suites", "bumps_rate_zero.yaml"))
    d = odomcov.diagnose(suite)
    bumps = next(c for c in d["candidates"] if c["effect"] == "bumps")
    assert "rate sigma^2 = 0 m (no standard error; " in bumps["explanation"]
    assert all("nan" not in c["explanation"] for c in d["candidates"])


def test_calibrate_gives_calibrate_json():
    # A small logged suite (one experiment of two runs: nothing to cross-validate): the keys of
    # calibrate.json, its own runs as held-out runs inside its training domain, bad arguments.
    suite = odomcov.load_suite(os.path.join(ROOT, "tests", "data", "suites", "good_logs.yaml"))
    c = odomcov.calibrate(suite, rounds=2)
    for key in ("rounds", "named", "explained", "candidates_cv", "confounded", "next_experiments",
                "model", "diff_drive", "stand_ins"):
        assert key in c, key
    assert c["explained"] == (c["after"]["verdict"] == "consistent")
    if c["explained"]:
        assert c["stand_ins"] == []  # looked for only when compare rejects the final model
    assert "domain:" in c["model"]["yaml"]
    assert c["diff_drive_yaml"].startswith("# diff_drive_controller parameters")
    held = odomcov.calibrate(suite, rounds=1, holdout=suite)
    assert set(held["holdout"]) >= {"nees_mean", "verdict", "by_kind", "extrapolation"}
    assert held["holdout"]["extrapolation"] == []  # its own runs lie in its training domain
    # the same runs in and out of sample: the same NEES per kind, one kind
    assert len(held["after"]["by_kind"]) == 1
    assert held["after"]["by_kind"] == pytest.approx(held["holdout"]["by_kind"], rel=1e-12)
    # the model's effects refitted on the held-out runs: none to refit when nothing was named
    assert "refitted" in held["holdout"]
    assert (held["holdout"]["refitted"] is None) == (held["named"] == [])
    # ... and predicted from the training runs' posterior: three NEES means per run, one kind
    pred = held["holdout"]["predictive"]
    assert all(pred[k] > 0 for k in ("plugin_nees_mean", "sized_nees_mean", "nees_mean"))
    assert len(pred["sized_by_kind"]) == 1
    with pytest.raises(ValueError):
        odomcov.calibrate(suite, rounds=0)
    with pytest.raises(ValueError):
        odomcov.calibrate(suite, candidates=[{"custom": {"name": "x", "parameters": {"a": 0}, "scale": "1 + b"}}])
def test_predict_takes_the_languages_new_keys():
    # lateral, noise and random (a per-run parameter with its sd) through the configs' own
    # parser, and the start heading for `heading`: a slip to the left of 4 mm per metre on a
    # straight line ends 4 mm per metre to the left; a slope (lateral = -g cos(heading)) gives
    # the same at heading0 = pi and the opposite at 0; the per-run scale adds (sd L)^2 along x.
    t = np.linspace(0, 10, 501)
    left = right = 0.5 * t  # 5 m at 0.5 m/s
    drift = odomcov.predict(left, right, 0.4, 1e-3, 1e-3,
                            effects=[{"custom": {"name": "drift", "parameters": {"d": 0.004}, "lateral": "d"}}])
    assert drift["mean"][-1, 1] == pytest.approx(0.004 * 5.0, rel=1e-12)
    slope = [{"custom": {"name": "slope", "parameters": {"g": 0.004}, "lateral": "-g * cos(heading)"}}]
    assert odomcov.predict(left, right, 0.4, 1e-3, 1e-3, effects=slope, heading0=np.pi)["mean"][-1, 1] == \
        pytest.approx(0.02, rel=1e-12)
    assert odomcov.predict(left, right, 0.4, 1e-3, 1e-3, effects=slope)["mean"][-1, 1] == pytest.approx(-0.02, rel=1e-12)
    plain = odomcov.predict(left, right, 0.4, 1e-3, 1e-3)
    noisy = odomcov.predict(left, right, 0.4, 1e-3, 1e-3, t=t,
                            effects=[{"custom": {"name": "n", "parameters": {"c": 3.0}, "noise": "1 + c * v"}}])
    assert noisy["cov"][-1, 0, 0] == pytest.approx(2.5 * plain["cov"][-1, 0, 0], rel=1e-9)
    per_run = odomcov.predict(left, right, 0.4, 1e-3, 1e-3, effects=[{"custom": {
        "name": "load", "parameters": {"e": 0.0}, "random": {"e": 0.002}, "scale": "1 + e"}}])
    assert per_run["cov"][-1, 0, 0] - plain["cov"][-1, 0, 0] == pytest.approx((0.002 * 5.0) ** 2, rel=1e-9)
    with pytest.raises(ValueError, match=r"effects\[0\]\.custom\.random\.e: the sd must be >= 0"):
        odomcov.predict(left, right, 0.4, 1e-3, 1e-3, effects=[{"custom": {
            "name": "load", "parameters": {"e": 0.0}, "random": {"e": -1}, "scale": "1 + e"}}])
