"""smd fragility: lognormal fragility curves by maximum likelihood (Baker 2015), from collapse intensities or from
multiple-stripe counts, against independent likelihood maximizations, with their profile-likelihood intervals
covering known lognormals at their stated rate."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.optimize import minimize_scalar, root
from scipy.stats import binom, lognorm, norm

from smdcli.analysis.fragility import CHI2_95, from_collapse_intensities, from_stripes

IM = np.array([0.2, 0.4, 0.6, 0.8, 1.0, 1.2, 1.5, 2.0])
RUNS = np.full(8, 40)
COLLAPSES = np.array([0, 4, 7, 25, 30, 34, 36, 40])


def log_likelihood(log_theta: float, beta: float, im=IM, runs=RUNS, collapses=COLLAPSES) -> float:
    """The binomial log-likelihood written out with scipy.stats (not smd's code)."""
    p = norm.cdf((np.log(im) - log_theta) / beta)
    return float(binom.logpmf(collapses, runs, p).sum())


def test_stripes_agree_with_the_score_equations_solved_independently():
    """The multiple-stripe MLE against the root of the likelihood's score in (ln theta, ln beta), written with
    scipy.stats' normal pdf and survival function: theta and beta to 1e-8 (measured equal to the last digit), the
    log-likelihood (binomial constants added) to 1e-12."""
    fitted = from_stripes(IM, RUNS, COLLAPSES)

    def score(p):
        log_theta, log_beta = p
        beta = np.exp(log_beta)
        u = (np.log(IM) - log_theta) / beta
        s = COLLAPSES * norm.pdf(u) / norm.cdf(u) - (RUNS - COLLAPSES) * norm.pdf(u) / norm.sf(u)
        return [np.sum(-s / beta), np.sum(-s * u)]
    found = root(score, [0.0, np.log(0.6)], tol=1e-14)
    assert found.success
    assert fitted.theta == pytest.approx(np.exp(found.x[0]), rel=1e-8)
    assert fitted.beta == pytest.approx(np.exp(found.x[1]), rel=1e-8)
    constants = float(np.sum(np.log([__import__("math").comb(int(n), int(z)) for n, z in zip(RUNS, COLLAPSES)])))
    assert fitted.log_likelihood + constants == pytest.approx(log_likelihood(*found.x[:1], np.exp(found.x[1])),
                                                              rel=1e-12)


def test_stripes_interval_ends_are_where_the_profile_likelihood_drops_by_the_chi_square_point():
    """At each end of theta's and beta's intervals, twice the log-likelihood maximized over the other parameter
    (scipy's bounded Brent on the scipy.stats likelihood) is 3.841 below its maximum, to 1e-6."""
    fitted = from_stripes(IM, RUNS, COLLAPSES)
    best = log_likelihood(np.log(fitted.theta), fitted.beta)
    for theta in fitted.theta_95:
        other = minimize_scalar(lambda b: -log_likelihood(np.log(theta), b), bounds=(0.01, 3.0), method="bounded",
                                options={"xatol": 1e-12})
        assert 2 * (best + other.fun) == pytest.approx(CHI2_95, rel=1e-6)
    for beta in fitted.beta_95:
        other = minimize_scalar(lambda m: -log_likelihood(m, beta), bounds=(-3.0, 3.0), method="bounded",
                                options={"xatol": 1e-12})
        assert 2 * (best + other.fun) == pytest.approx(CHI2_95, rel=1e-6)
    assert fitted.theta_95[0] < fitted.theta < fitted.theta_95[1] and fitted.beta_95[0] < fitted.beta < fitted.beta_95[1]


def test_collapse_intensities_agree_with_scipy_s_lognormal_fit_and_closed_form_intervals():
    """A lognormal sample of collapse intensities: theta and beta against scipy.stats.lognorm.fit (location 0), to
    1e-8; the intervals' ends where the profile likelihood, written out here, drops by 3.841, to 1e-9."""
    sample = np.exp(np.random.default_rng(7).normal(np.log(0.9), 0.35, 25))
    fitted = from_collapse_intensities(sample)
    shape, _, scale = lognorm.fit(sample, floc=0)
    assert fitted.theta == pytest.approx(scale, rel=1e-8) and fitted.beta == pytest.approx(shape, rel=1e-8)
    x, n = np.log(sample), len(sample)

    def profile(log_theta, beta=None):  # maximized over beta where beta is None
        spread = np.mean((x - log_theta) ** 2) if beta is None else beta ** 2
        return -n / 2 * np.log(spread) - np.sum((x - log_theta) ** 2) / (2 * spread)
    best = profile(np.log(fitted.theta))
    for theta in fitted.theta_95:
        assert 2 * (best - profile(np.log(theta))) == pytest.approx(CHI2_95, rel=1e-9)
    for beta in fitted.beta_95:
        assert 2 * (best - profile(np.log(fitted.theta), beta)) == pytest.approx(CHI2_95, rel=1e-9)


def test_known_lognormals_are_recovered_within_their_stated_intervals_at_about_the_stated_rate():
    """Counts simulated from theta = 0.8, beta = 0.4 (8 stripes of 40 runs, 100 seeds) and collapse intensities
    from the same lognormal (25 records, 400 seeds): each interval covers the true value in 88 % to 99.5 % of the
    fits (95 % stated; three binomial standard deviations of 100 or 400 trials; measured 97 % and 95 % for the
    stripes, 94.75 % and 93.25 % for the intensities)."""
    truth = (0.8, 0.4)
    covered = np.zeros(2)
    for seed in range(100):
        counts = np.random.default_rng(seed).binomial(RUNS, norm.cdf(np.log(IM / truth[0]) / truth[1]))
        fitted = from_stripes(IM, RUNS, counts)
        covered += [fitted.theta_95[0] <= truth[0] <= fitted.theta_95[1], fitted.beta_95[0] <= truth[1] <= fitted.beta_95[1]]
    assert (0.88 <= covered / 100).all() and (covered / 100 <= 0.995).all(), covered
    covered = np.zeros(2)
    for seed in range(400):
        fitted = from_collapse_intensities(np.exp(np.random.default_rng(seed).normal(np.log(truth[0]), truth[1], 25)))
        covered += [fitted.theta_95[0] <= truth[0] <= fitted.theta_95[1], fitted.beta_95[0] <= truth[1] <= fitted.beta_95[1]]
    assert (0.92 <= covered / 400).all() and (covered / 400 <= 0.98).all(), covered


def test_the_command_fits_counts_or_an_ida_result_and_refuses_bad_data_in_one_line(cli, tmp_path):
    """smd fragility COUNTS.csv writes OUT/<stem>_fragility.h5 with /fragility/theta, beta, theta_95, beta_95 (the
    Python fit's); an HDF5 file with /collapse_im (an IDA result) is fitted as collapse intensities; a counts file
    with a bad line, or with collapses rising as a step (no finite dispersion), is exit 2 in one line naming it,
    nothing written."""
    import h5py

    counts = tmp_path / "counts.csv"
    counts.write_text("im,runs,collapses\n" + "".join(f"{a},{n},{z}\n" for a, n, z in zip(IM, RUNS, COLLAPSES)))
    ran = cli("fragility", counts, "-o", tmp_path / "out", "--json", "--no-plots")
    assert ran.exit_code == 0, ran.output
    data = json.loads(ran.output)
    fitted = from_stripes(IM, RUNS, COLLAPSES)
    with h5py.File(tmp_path / "out" / "counts_fragility.h5") as f:
        assert f["fragility/theta"][()] == fitted.theta and f["fragility/beta"][()] == fitted.beta
        assert f["fragility/theta_95"][()].tolist() == list(fitted.theta_95)
        assert f["fragility/beta_95"][()].tolist() == list(fitted.beta_95)
    assert data["theta"] == fitted.theta
    result = tmp_path / "campaign_ida.h5"
    sample = np.exp(np.random.default_rng(3).normal(0.0, 0.3, 12))
    with h5py.File(result, "w") as f:
        f.create_dataset("collapse_im", data=np.append(sample, np.nan))  # a record that never collapsed
        f.attrs["im_units"] = "m/s^2"
    ran = cli("fragility", result, "-o", tmp_path / "out2", "--json", "--no-plots")
    assert json.loads(ran.output)["theta"] == pytest.approx(from_collapse_intensities(sample).theta, rel=1e-15)
    for text, message in (("im,runs,collapses\n0.5,10,2\n0.7,10,x\n", "line 3: expected three numbers"),
                          ("im,runs,collapses\n0.5,10,12\n0.7,10,3\n", "line 2: expected whole runs"),
                          ("im,runs\n0.5,10\n", "line 1: expected the header"),
                          ("im,runs,collapses\n0.5,10,0\n0.7,10,10\n", "no maximum at a finite dispersion")):
        bad = tmp_path / "bad.csv"
        bad.write_text(text)
        ran = cli("fragility", bad, "-o", tmp_path / "none")
        assert ran.exit_code == 2 and message in ran.output and len(ran.output.strip().splitlines()) == 1, ran.output
        assert not (tmp_path / "none").exists()
