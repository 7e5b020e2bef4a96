"""cloth-usd evaluate: the report of a trained bundle and two ablation runs on the tiny data set."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from script_module import ROOT, load_script

from cloth_usd.evaluate import HIST_BIN_MM, ErrorStats, body_label, shirt_labels


def _train_data():
    """tests/nn/train_data.py (shared with the training tests) as a module."""
    return load_script("train_data", ROOT / "tests" / "nn" / "train_data.py")


def test_error_stats_bins_and_quantiles():
    s = ErrorStats()
    s.add(np.array([0.0, 0.1, 0.16, 0.31, 1000.0]))
    assert s.count == 5 and s.overflow == 1
    assert s.mean == pytest.approx(1000.57 / 5)
    assert list(s.counts[:3]) == [2, 1, 1]
    assert s.quantile(0.5) == pytest.approx(1.5 * HIST_BIN_MM)
    assert np.isnan(ErrorStats().mean)
    far = ErrorStats()  # quantiles past the histogram's end are the errors themselves, not the largest one
    far.add(np.r_[np.zeros(10), np.arange(200.0, 1000.0, 10.0)])
    assert far.quantile(0.5) == pytest.approx(np.quantile(np.r_[np.zeros(10), np.arange(200.0, 1000.0, 10.0)], 0.5,
                                                          method="inverted_cdf"))
    assert far.quantile(1.0) == 990.0 and far.quantile(0.1) == pytest.approx(0.5 * HIST_BIN_MM)


def test_histogram_plot_with_most_errors_past_its_end(tmp_path):
    """A garment far from Newton (a skirt that swings 10 cm away) puts the 99th percentile past the
    histogram's end; the plot draws up to that end (it raised a size mismatch before)."""
    from cloth_usd.evaluate import HIST_MAX_MM, _plot

    far, near = ErrorStats(), ErrorStats()
    far.add(np.linspace(0.0, 3 * HIST_MAX_MM, 1000))
    near.add(np.linspace(0.0, 20.0, 1000))
    _plot({"all": {"skinning": far, "detail": near}}, ["all"], {"all": "all"}, ["skinning", "detail"], tmp_path)
    assert (tmp_path / "histograms.png").stat().st_size > 0 and (tmp_path / "means.png").stat().st_size > 0


def test_labels_come_from_metadata_or_body_and_hem():
    assert body_label({"body": "medium_fat"}) == "fat"
    assert body_label({"body": "slim"}) == "slim"
    assert body_label({"body": "slim", "body_label": "thin"}) == "thin"
    metas = [{"shirt": 0, "shirt_params": {"hem": 0.02}}, {"shirt": 1, "shirt_params": {"hem": -0.14}},
             {"shirt": 8, "shirt_params": {"hem": -0.05}}]
    assert shirt_labels(metas) == {0: "short", 1: "long", 8: "shirt8"}
    assert shirt_labels([{"shirt": 2, "shirt_params": {"hem": -0.06}}]) == {2: "shirt2"}
    assert shirt_labels([{"shirt": 3, "shirt_label": "long"}]) == {3: "long"}


@pytest.mark.slow
def test_evaluate_writes_report_with_every_tier(tmp_path_factory, tmp_path):
    torch = pytest.importorskip("torch", reason="training the ablations needs torch")
    pytest.importorskip("onnxruntime", reason="the learned tiers need onnxruntime")
    from cloth_usd.cli import main
    from cloth_usd.nn.data import Split, load_dataset
    from cloth_usd.nn.train import TrainConfig, train

    helpers = _train_data()
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        bundle = helpers.tiny_trained_bundle(tmp_path_factory)
        data, coarse, _ = helpers.tiny_runs(tmp_path_factory)
        quick = {**helpers.TINY_TRAIN, "epochs": 1, "max_batches": 2}
        ds = load_dataset(data, (Split.TRAIN, Split.VAL), max_frames=quick["max_frames"])
        for name, switch in (("no-dec", {"decompose": False}), ("no-parser", {"use_parser": False})):
            train("detail", data, tmp_path / name, TrainConfig(**quick, **switch), coarse_run=coarse, device="cpu",
                  dataset=ds)
        out = tmp_path / "report"
        assert main(["evaluate", "--data", str(data), "--bundle", str(bundle), "--ablation-runs",
                     str(tmp_path / "no-dec"), str(tmp_path / "no-parser"), "-o", str(out), "--max-frames", "3"]) == 0
    finally:
        torch.set_num_threads(threads)
    metrics = json.loads((out / "metrics.json").read_text())
    tiers = ["skinning", "coarse", "detail", "detail (no decomposition)", "detail (no parser)"]
    assert metrics["tiers"] == tiers
    assert metrics["data"]["same_as_training"] is True
    assert metrics["bundle"]["coarse_base"] == "body"  # the tiny runs train METHOD.md's form
    assert all(a["coarse_matches_bundle"] for a in metrics["ablations"].values())
    keys = [r["key"] for r in metrics["rows"]]
    assert keys == ["test_body", "test_garment", "test_motion", "all"]
    assert metrics["left_the_body"] == []  # the stand-in's garment stays on the body
    for row in metrics["rows"]:
        assert all(0 < row["mean_mm"][t] < 100 for t in tiers), row
    hist = np.load(out / "histograms.npz")
    assert hist["all|detail"].sum() == metrics["rows"][-1]["vertex_frames"]
    report = (out / "report.md").read_text()
    for text in ["unseen bodies (all)", "unseen shirts (all)", "unseen motions (all)", "(I M_b)", *tiers]:
        assert text in report
    assert (out / "histograms.png").stat().st_size > 0 and (out / "means.png").stat().st_size > 0


def test_test_sequences_whose_garment_left_the_body_are_named(tmp_path_factory):
    """A test set made before the factory's bare-body check can hold frames where Newton's garment came off
    the body; evaluate names those sequences (most bare first), and none where the garment stays on."""
    import dataclasses

    from cloth_usd.evaluate import _left_the_body
    from cloth_usd.nn.data import Split, load_dataset

    data = load_dataset(_train_data().tiny_dataset(tmp_path_factory), (Split.TEST_MOTION, Split.TEST_BODY))
    clips = data.clips
    assert len(clips) >= 2 and _left_the_body(data.body, clips) == []  # the stand-in is skinning plus ripples
    off = clips[0].positions.copy()
    off[2:] += np.float32([0.0, 0.0, 0.15])  # slid 15 cm forward off the body from frame 2
    worse = clips[1].positions + np.float32([0.0, 0.0, 0.3])  # every frame, further
    moved = [dataclasses.replace(clips[0], positions=off), dataclasses.replace(clips[1], positions=worse)]
    left = _left_the_body(data.body, [*moved, *clips[2:]])
    assert [r["sequence"] for r in left] == [clips[1].name, clips[0].name]
    assert left[1]["frames"] == off.shape[0] - 2 and left[1]["of"] == off.shape[0] and left[1]["frame"] >= 2
    assert left[0]["frames"] == left[0]["of"] and left[0]["max_bare"] > left[1]["max_bare"] > 0.1


def test_ablation_labels_say_what_differs():
    pytest.importorskip("torch")
    from types import SimpleNamespace

    from cloth_usd.evaluate import _ablation_label
    from cloth_usd.core.scene import Tier
    from cloth_usd.nn.train import TrainConfig

    def run(tier, **config):
        return SimpleNamespace(tier=Tier(tier), config=TrainConfig(**config), path=Path("runs/x"))

    assert _ablation_label(run("detail", use_parser=False)) == "detail (no parser)"
    assert _ablation_label(run("detail")) == "detail (run x)"
    assert _ablation_label(run("coarse")) == "coarse (body base, Laplacian target)"  # METHOD.md's form
    assert _ablation_label(run("coarse", coarse_base="skinned", coarse_target="taubin", decompose=False)) == \
        "coarse (no decomposition, skinned base, Taubin target)"
