"""``tespike score``: PSNR-mu and SSIM-mu equal independent computations; refusals are one line."""

import json

import numpy as np
import pytest
import torch
from scipy.ndimage import gaussian_filter
from skimage.metrics import structural_similarity

from tespike.cosim.cli import main
from tespike.recon.scenes import make_scene
from tests.cli import assert_refused, run_tespike


@pytest.fixture(autouse=True)
def one_torch_thread():
    """One torch thread: on the shared 2-core machine two threads contend badly."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


def independent_psnr_ssim_mu(estimate, reference, mu=5000.0):
    """docs/metrics.md by hand: divide by each reference frame's peak, clip to [0, 1], mu-law."""
    psnr, ssim = [], []
    for e, r in zip(estimate.astype(np.float64), reference.astype(np.float64)):
        peak = r.max()
        te = np.log(1 + mu * np.clip(e / peak, 0, 1)) / np.log(1 + mu)
        tr = np.log(1 + mu * np.clip(r / peak, 0, 1)) / np.log(1 + mu)
        psnr.append(10 * np.log10(1 / np.mean((te - tr) ** 2)))
        ssim.append(structural_similarity(tr, te, gaussian_weights=True, sigma=1.5,
                                          use_sample_covariance=False, data_range=1))
    return np.array(psnr), np.array(ssim)


def write_pair(tmp_path, estimate, reference, names=("R.npy", "I.npy")):
    np.save(tmp_path / names[0], estimate)
    np.save(tmp_path / names[1], reference)
    return tmp_path / names[0], tmp_path / names[1]


def score_json(capsys, estimate_path, reference_path, *extra):
    code = main(["score", "--reference", str(reference_path), "--estimate", str(estimate_path), "--json",
                 *extra])
    out = capsys.readouterr()
    assert code == 0, out.err
    return json.loads(out.out), out.err


def test_psnr_ssim_mu_equal_independent_computation(tmp_path, capsys, rng):
    reference = (10 ** rng.uniform(-4, 0.5, size=(5, 24, 40))).astype(np.float32)
    estimate = (reference * rng.lognormal(0.05, 0.3, reference.shape)).astype(np.float32)
    r_path, i_path = write_pair(tmp_path, estimate, reference)
    result, _ = score_json(capsys, r_path, i_path, "--frames", "1:4", "--metrics", "psnr_mu,ssim_mu")
    psnr, ssim = independent_psnr_ssim_mu(estimate[1:4], reference[1:4])
    assert result["frames"] == [1, 4]
    assert np.allclose(result["per_frame"]["psnr_mu"], psnr, rtol=1e-10)
    assert np.allclose(result["per_frame"]["ssim_mu"], ssim, rtol=1e-9)
    assert result["mean"]["psnr_mu"] == pytest.approx(psnr.mean(), rel=1e-10)
    assert set(result["per_frame"]) == {"psnr_mu", "ssim_mu"}


def test_every_metric_orders_distortions(tmp_path, capsys, rng):
    reference = make_scene("city", frames=3, height=64, width=96).astype(np.float64)
    noise = rng.standard_normal(reference.shape)
    distortions = {"slight": reference * (1 + 0.02 * noise), "strong": reference * (1 + 0.2 * noise),
                   "blur": gaussian_filter(reference, (0, 3, 3))}
    np.save(tmp_path / "I.npy", reference)
    means = {}
    for name, estimate in distortions.items():
        np.save(tmp_path / f"{name}.npy", estimate)
        result, _ = score_json(capsys, tmp_path / f"{name}.npy", tmp_path / "I.npy")
        means[name] = result["mean"]
        assert len(result["per_frame"]["hdr_vqm"]) == 3 and "hdr_vqm" in result["sequence"]
    result, _ = score_json(capsys, tmp_path / "I.npy", tmp_path / "I.npy")
    means["identical"] = result["mean"]
    assert means["identical"]["psnr_mu"] == "inf" and means["identical"]["hdr_vqm"] == 0
    order = ["identical", "slight", "strong", "blur"]
    for key, higher in (("ssim_mu", True), ("psnr_pu21", True), ("hdr_vqm", False), ("fovvideovdp", True)):
        values = [float(means[name][key]) for name in order]
        steps = np.diff(values) if not higher else -np.diff(values)
        assert np.all(steps > 0), (key, values)
    assert result["columns"]["fovvideovdp"]["label"].startswith("FovVideoVDP (JOD")
    assert result["columns"]["hdr_vqm"]["higher_is_better"] is False


def test_table_on_stdout(tmp_path, rng):
    reference = rng.uniform(0.01, 1.0, (3, 16, 20))
    r_path, i_path = write_pair(tmp_path, reference * 1.1, reference)
    result = run_tespike("score", "--reference", i_path, "--estimate", r_path, "--metrics", "psnr_mu,hdr_vqm")
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert lines[0].split()[0] == "frame" and "PSNR-mu" in lines[0] and "HDR-VQM" in lines[0]
    assert [line.split()[0] for line in lines[1:]] == ["0", "1", "2", "mean", "sequence"]
    psnr, _ = independent_psnr_ssim_mu(reference[:1] * 1.1, reference[:1])
    assert float(lines[1].split()[1]) == pytest.approx(psnr[0], abs=1e-4)
    assert result.stderr == ""


def test_negative_estimate_is_scored_with_a_warning(tmp_path, capsys, rng):
    reference = rng.uniform(0.01, 1.0, (2, 16, 16))
    estimate = reference.copy()
    estimate[0, 0, 0] = -0.5
    r_path, i_path = write_pair(tmp_path, estimate, reference)
    result, _ = score_json(capsys, r_path, i_path, "--metrics", "psnr_mu")
    assert result["per_frame"]["psnr_mu"][1] == "inf" and result["per_frame"]["psnr_mu"][0] != "inf"
    # one line, naming the file, never Python's two-line warning with its source path
    done = run_tespike("score", "--reference", i_path, "--estimate", r_path, "--metrics", "psnr_mu")
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 0 and len(lines) == 1, done.stderr
    assert lines[0].startswith("tespike score: warning: estimate") and str(r_path) in lines[0]
    assert "1 negative light values" in lines[0] and ".py:" not in lines[0]


def test_refusals(tmp_path, rng):
    reference = rng.uniform(0.01, 1.0, (4, 16, 16))
    r_path, i_path = write_pair(tmp_path, reference, reference)

    def refused(*words, reference_path=i_path, estimate_path=r_path, extra=()):
        assert_refused(run_tespike("score", "--reference", reference_path, "--estimate", estimate_path,
                                   *extra), *words)

    np.save(tmp_path / "short.npy", reference[:, 1:])
    refused("shape", str(tmp_path / "short.npy"), estimate_path=tmp_path / "short.npy")
    # the refusal named neither the flag nor the unknown name ("metrics ['psnr_mu', 'bogus']: ...")
    refused("--metrics 'psnr_mu,bogus': 'bogus' is no metric (choose from psnr_mu", extra=("--metrics", "psnr_mu,bogus"))
    refused("--metrics ',': names no metric", extra=("--metrics", ","))
    bad = reference.copy()
    bad[2, 3, 4] = np.nan
    np.save(tmp_path / "nan.npy", bad)
    refused("estimate", "non-finite", str(tmp_path / "nan.npy"), estimate_path=tmp_path / "nan.npy")
    np.save(tmp_path / "int.npy", reference.astype(np.int32))
    refused("estimate file", str(tmp_path / "int.npy"), "not a float type", estimate_path=tmp_path / "int.npy")
    np.save(tmp_path / "4d.npy", reference[None])
    refused("estimate file", str(tmp_path / "4d.npy"), "(K, H, W)", estimate_path=tmp_path / "4d.npy")
    refused("reference", "non-finite", reference_path=tmp_path / "nan.npy")
    np.save(tmp_path / "neg.npy", reference - 0.5)
    refused("reference", str(tmp_path / "neg.npy"), "negative", reference_path=tmp_path / "neg.npy")
    np.save(tmp_path / "zero.npy", np.zeros_like(reference))
    refused("all zero", reference_path=tmp_path / "zero.npy")
    zero_frame = reference.copy()
    zero_frame[1] = 0
    np.save(tmp_path / "zero1.npy", zero_frame)
    refused("reference frame 1 is all zero", reference_path=tmp_path / "zero1.npy")
    refused("reference frame 1 is all zero", reference_path=tmp_path / "zero1.npy", extra=("--frames", "1:3"))
    assert run_tespike("score", "--reference", tmp_path / "zero1.npy", "--estimate", r_path,
                       "--metrics", "psnr_pu21").returncode == 0
    np.save(tmp_path / "int.npy", (reference * 100).astype(np.int32))
    refused("float", estimate_path=tmp_path / "int.npy")
    (tmp_path / "junk.npy").write_bytes(b"not an npy file")
    refused("junk.npy", estimate_path=tmp_path / "junk.npy")
    refused("missing.npy", reference_path=tmp_path / "missing.npy")
    for spec in ("3:3", "0:5", "x", "1:2:3", "-1:2"):
        refused("--frames", extra=("--frames", spec))
    refused("metrics", extra=("--metrics", "psnr_mu,hdr_vdp3"))
    refused("--json", extra=("--json", "--quiet"))          # (exit 0 and no output at all)


def test_big_endian_and_fortran_files_score_like_native(tmp_path, capsys, rng):
    reference = rng.uniform(0.01, 1.0, (2, 16, 20))
    estimate = reference * rng.lognormal(0, 0.1, reference.shape)
    native = score_json(capsys, *write_pair(tmp_path, estimate, reference))[0]
    other = score_json(capsys, *write_pair(tmp_path, np.asfortranarray(estimate.astype(">f4")),
                                           reference.astype(">f8"), names=("Rb.npy", "Ib.npy")))[0]
    for key in native["per_frame"]:
        assert np.allclose(other["per_frame"][key], native["per_frame"][key], rtol=1e-5), key


def test_long_double_files_score_like_float64(tmp_path, capsys, rng):
    """A long-double .npy passed the float check and then failed in torch (no such type): a traceback."""
    reference = rng.uniform(0.01, 1.0, (2, 16, 20))
    estimate = reference * rng.lognormal(0, 0.1, reference.shape)
    native = score_json(capsys, *write_pair(tmp_path, estimate, reference))[0]
    long = score_json(capsys, *write_pair(tmp_path, estimate.astype(np.longdouble), reference.astype(np.longdouble),
                                          names=("Rl.npy", "Il.npy")))[0]
    for key in native["per_frame"]:
        assert np.allclose(long["per_frame"][key], native["per_frame"][key], rtol=1e-12), key
    # a long double beyond float64's range is finite: named as such, not as the inf it becomes
    huge = estimate.astype(np.longdouble)
    huge[0, 0, 0] = np.longdouble("1e4000")
    if np.isfinite(huge[0, 0, 0]):                      # (where the long double is wider than float64)
        np.save(tmp_path / "Rh.npy", huge)
        assert main(["score", "--reference", str(tmp_path / "Il.npy"), "--estimate", str(tmp_path / "Rh.npy")]) == 2
        assert capsys.readouterr().err.strip() == (f"tespike score: error: estimate file {str(tmp_path / 'Rh.npy')!r} "
                                                   "holds a value (1e+4000) beyond float64's range, in which light "
                                                   "is scored")


@pytest.mark.parametrize("reference, options, words", [
    (None, {"display": "sim2"}, r"^display = 'sim2': must be an HdrDisplay"),
    (None, {"device": "gpu9"}, r"^device = 'gpu9': not a usable torch device"),
    (None, {"metrics": 3}, r"^metrics 3: must be a name or a sequence of names \(strings\)$"),
    (np.ones((0, 4, 4)), {}, r"^estimate and reference \(0, 4, 4\) hold no pixel to score$"),
    (np.full((1, 4, 4), np.nan), {}, r"^the reference holds non-finite values \(NaN or infinity\): it is no light$"),
    (-np.ones((1, 4, 4)), {}, r"^the reference holds negative light \(down to -1\): it is no light$"),
    (np.zeros((1, 4, 4)), {}, r"^the reference is all zero"),
], ids=["display-name", "device", "metrics-number", "no-frames", "nan-reference", "negative-reference",
        "zero-reference"])
def test_the_library_score_refuses_what_it_cannot_score_in_one_line(reference, options, words):
    """The library's ``score`` took a display's name (an AttributeError), a device torch cannot use
    (its RuntimeError), ``metrics=3`` (not iterable), zero frames (NaN means and a warning), and said
    "all zero" of a NaN or negative reference."""
    from tespike.golden.errors import InputError
    from tespike.recon.score import score
    reference = np.full((1, 4, 4), 0.5) if reference is None else reference
    with pytest.raises(InputError, match=words):
        score(np.ones_like(reference), reference, **{"metrics": ["psnr_mu"], **options})
