"""Training on a tiny factory data set: features, overfitting, runs, resume, export."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="training needs torch (pip install 'cloth-usd[train]')")

from train_data import TINY_TRAIN, one_thread, tiny_dataset, tiny_runs, tiny_trained_bundle  # noqa: E402,F401

from cloth_usd.core.pipeline import CoarseForm, run_tiers  # noqa: E402
from cloth_usd.core.scene import Tier  # noqa: E402
from cloth_usd.errors import ArgumentError  # noqa: E402
from cloth_usd.datagen.dataset import laplacian_smooth  # noqa: E402
from cloth_usd.nn.data import (  # noqa: E402
    TAUBIN_MU,
    CoarseTarget,
    Split,
    Statistics,
    coarse_example,
    detail_example,
    load_dataset,
    plan_batches,
    with_coarse_target,
)
from cloth_usd.nn.train import (  # noqa: E402
    TrainConfig,
    _apply_statistics,
    _Examples,
    _forward,
    _statistics,
    build_model,
    load_run,
    torch_coarse_fn,
    torch_detail_fn,
    train,
)

pytestmark = pytest.mark.slow
QUICK = TrainConfig(**TINY_TRAIN)


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    path = tiny_dataset(tmp_path_factory)
    return path, load_dataset(path, (Split.TRAIN, Split.VAL))


def test_a_data_set_loads_only_the_named_sequences(data):
    """load_dataset(sequences=...) reads the named sequences alone (a render of one frame, a repeat's
    twin), each with the simulator's penetration per frame; a name the folder lacks loads nothing."""
    path, ds = data
    clip = ds.clips[0]
    one = load_dataset(path, sequences=[clip.name])
    assert [c.name for c in one.clips] == [clip.name]
    np.testing.assert_array_equal(one.clips[0].positions, clip.positions)
    assert one.clips[0].penetration.shape == (clip.num_frames,)
    assert load_dataset(path, sequences=["no such sequence"]).clips == ()


def test_training_inputs_are_the_runtime_inputs(data):
    """The features train.py builds are, bit for bit, those run_tiers feeds the models at inference."""
    _, ds = data
    clip, frames = ds.split(Split.VAL)[0], np.arange(3)
    torch.manual_seed(0)
    coarse, detail = build_model("coarse", QUICK).eval(), build_model("detail", QUICK).eval()
    seen = {}
    c_fn, d_fn = torch_coarse_fn(coarse), torch_detail_fn(detail)

    def record_coarse(feats, graph):
        seen["coarse"] = feats
        return c_fn(feats, graph)

    def record_detail(feats, attrs, graph):
        seen["detail"], seen["attrs"] = feats, attrs
        return d_fn(feats, attrs, graph)

    run_tiers(ds.body, clip.pair, clip.poses[frames], clip.transl[frames], record_coarse, record_detail)
    ex = coarse_example(ds.body, clip, frames)
    np.testing.assert_array_equal(ex.features, seen["coarse"])
    dx = detail_example(clip, frames, ex.posed, ex.base + c_fn(ex.features, clip.pair.graph))
    np.testing.assert_array_equal(dx.features, seen["detail"])
    np.testing.assert_array_equal(dx.attributes, seen["attrs"])
    np.testing.assert_allclose(ex.target + ex.base, clip.coarse[frames], atol=1e-6)


@pytest.mark.parametrize("tier", ["coarse", "detail"])
def test_loss_falls_when_overfitting_one_batch(data, tier):
    _, ds = data
    clips = ds.split(Split.TRAIN)
    config = TrainConfig(**{**TINY_TRAIN, "batch": 2, "stat_frames": 2, "coarse_input": "target", "prefetch": 0})
    torch.manual_seed(0)
    model = build_model(tier, config)
    examples = _Examples(Tier(tier), ds.body, clips, config, None, torch.device("cpu"))
    _apply_statistics(model, _statistics(examples, clips, config))
    (clip, f, a, _, t), = examples.iterate(plan_batches(clips, config.batch)[:1])
    target = torch.from_numpy(t).float()
    optimizer = torch.optim.Adam(model.parameters(), lr=1e-2)
    losses = []
    for _ in range(20):
        loss = (((_forward(model, examples.tensors, clip, f, a) - target) / model.output_scale) ** 2).mean()
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        losses.append(float(loss.detach()))
    # measured: coarse 1.08 -> 0.50, detail 1.07 -> 0.68 (a tiny model, 20 steps)
    assert losses[-1] < 0.75 * losses[0], losses
    assert np.mean(losses[-5:]) < np.mean(losses[:5]), losses


def test_runs_write_checkpoints_history_curve_and_statistics(tmp_path_factory):
    data, coarse_dir, detail_dir = tiny_runs(tmp_path_factory)
    for run_dir, tier in ((coarse_dir, "coarse"), (detail_dir, "detail")):
        for name in ("run.json", "stats.npz", "checkpoint.pt", "best.pt", "history.json", "curve.png"):
            assert (run_dir / name).is_file(), name
        rows = list(csv.DictReader((run_dir / "history.csv").open()))
        assert [int(r["epoch"]) for r in rows] == [0, 1]
        assert all(np.isfinite(float(r[k])) for r in rows for k in ("train_loss", "val_loss", "val_mm"))
        run = load_run(run_dir)
        stats = Statistics.load(run_dir / "stats.npz")
        np.testing.assert_allclose(run.model.input_mean.numpy(), stats.input_mean, rtol=1e-6)
        np.testing.assert_allclose(run.model.output_scale.numpy(), stats.output_scale, rtol=1e-6)
        info = json.loads((run_dir / "run.json").read_text())
        assert info["tier"] == tier and len(info["data"]["manifest_sha256"]) == 64
    detail = load_run(detail_dir)
    np.testing.assert_allclose(detail.model.parser.input_std.numpy(),
                               Statistics.load(detail_dir / "stats.npz").attribute_std, rtol=1e-6)
    assert detail.info["coarse_run"]["best_sha256"]


def test_only_the_learned_tiers_train_or_build(tmp_path):
    for bad in ("skinning", Tier.SKINNING, "wrinkles"):
        with pytest.raises(ArgumentError, match=r"not a trainable tier \(valid: coarse, detail\)"):
            train(bad, tmp_path / "data", tmp_path / "run", QUICK, device="cpu")
        with pytest.raises(ArgumentError, match="valid: coarse, detail"):
            build_model(bad, QUICK)
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "run.json").write_text(json.dumps({"format": 1, "tier": "skinning", "config": {}}))
    with pytest.raises(ArgumentError, match=r"run\.json: tier 'skinning': not a trainable tier"):
        load_run(tmp_path / "run")


def test_resume_continues_bit_identically(data, tmp_path):
    path, ds = data
    straight = train("coarse", path, tmp_path / "a", QUICK, device="cpu", dataset=ds)
    one = TrainConfig(**{**QUICK.to_json(), "epochs": 1})
    train("coarse", path, tmp_path / "b", one, device="cpu", dataset=ds)
    with pytest.raises(ArgumentError, match="pass --resume"):
        train("coarse", path, tmp_path / "b", QUICK, device="cpu", dataset=ds)
    other = TrainConfig(**{**QUICK.to_json(), "lr": 1e-2})
    with pytest.raises(ArgumentError, match="only epochs may change"):
        train("coarse", path, tmp_path / "b", other, device="cpu", dataset=ds, resume=True)
    resumed = train("coarse", path, tmp_path / "b", QUICK, device="cpu", dataset=ds, resume=True)
    assert [r.train_loss for r in resumed.history] == [r.train_loss for r in straight.history]
    assert [r.val_loss for r in resumed.history] == [r.val_loss for r in straight.history]
    a, b = straight.model.state_dict(), resumed.model.state_dict()
    assert a.keys() == b.keys()
    assert all(torch.equal(a[k], b[k]) for k in a)
    sa = torch.load(tmp_path / "a" / "checkpoint.pt", weights_only=True)["optimizer"]["state"]
    sb = torch.load(tmp_path / "b" / "checkpoint.pt", weights_only=True)["optimizer"]["state"]
    assert all(torch.equal(sa[k]["exp_avg_sq"], sb[k]["exp_avg_sq"]) for k in sa)


def test_taubin_coarse_target_is_trained_on_and_recorded(data, tmp_path):
    path, ds = data
    assert with_coarse_target(ds, "stored") is ds
    taubin = with_coarse_target(ds, CoarseTarget.TAUBIN)
    clip, old = taubin.clips[0], ds.clips[0]
    np.testing.assert_array_equal(clip.positions, old.positions)
    np.testing.assert_allclose(clip.coarse, laplacian_smooth(old.positions, old.pair.faces, mu=TAUBIN_MU))
    assert not np.allclose(clip.coarse, old.coarse, atol=1e-4)
    config = TrainConfig(**{**QUICK.to_json(), "epochs": 1, "coarse_target": "taubin"})
    run = train("coarse", path, tmp_path / "t", config, device="cpu", dataset=ds)
    assert json.loads((tmp_path / "t" / "run.json").read_text())["config"]["coarse_target"] == "taubin"
    ex = _Examples(Tier.COARSE, ds.body, taubin.split(Split.TRAIN), config, None, torch.device("cpu"))
    _, _, _, base, target = next(ex.iterate(plan_batches(taubin.split(Split.TRAIN), 2)))
    np.testing.assert_allclose(base + target, taubin.split(Split.TRAIN)[0].coarse[:2], atol=1e-6)
    assert run.history
    with pytest.raises(ArgumentError, match="coarse_target"):
        TrainConfig.from_mapping({"coarse_target": "gaussian"})


def test_skinned_coarse_base_from_training_to_the_runtime(data, tmp_path):
    """coarse_base = skinned: the coarse target is measured from the skinned garment, the
    detail run adds its coarse run's prediction to the same base, the bundle records it
    and the runtime (onnxruntime) gives what the torch models give through run_tiers."""
    from cloth_usd.core.skinning import skin_garment
    from cloth_usd.nn.export import export_bundle
    from cloth_usd.runtime import LearnedGarment, load_bundle

    path, ds = data
    coarse_cfg = TrainConfig(**{**QUICK.to_json(), "epochs": 1, "coarse_base": "skinned"})
    train("coarse", path, tmp_path / "c", coarse_cfg, device="cpu", dataset=ds)
    train("detail", path, tmp_path / "d", TrainConfig(**{**QUICK.to_json(), "epochs": 1}), device="cpu",
          dataset=ds, coarse_run=tmp_path / "c")
    coarse = load_run(tmp_path / "c")
    clip, frames = ds.split(Split.TRAIN)[0], np.arange(2)
    skinned = skin_garment(clip.pair.binding, clip.poses[:2], clip.transl[:2], ds.body.parents)
    ex = coarse_example(ds.body, clip, frames, "skinned")
    np.testing.assert_allclose(ex.base, skinned, atol=1e-12)
    np.testing.assert_allclose(ex.base + ex.target, clip.coarse[:2], atol=1e-6)
    detail_examples = _Examples(Tier.DETAIL, ds.body, [clip], load_run(tmp_path / "d").config, coarse.model,
                                torch.device("cpu"), coarse.config.coarse_base)
    _, _, _, m_coarse, _ = next(detail_examples.iterate([(0, frames)]))
    np.testing.assert_allclose(m_coarse, skinned + torch_coarse_fn(coarse.model)(ex.features, clip.pair.graph),
                               atol=1e-9)
    bundle = load_bundle(export_bundle(tmp_path / "c", tmp_path / "d", path, tmp_path / "b", name="skinned-base"))
    assert bundle.form.base.value == "skinned"
    val = load_dataset(path, (Split.VAL,), max_frames=3).split(Split.VAL)[0]
    learned = LearnedGarment(bundle, ds.body, val.pair.betas, val.rest_points, val.pair.faces)
    want, _ = run_tiers(ds.body, val.pair, val.poses, val.transl, torch_coarse_fn(coarse.model),
                        torch_detail_fn(load_run(tmp_path / "d").model), form=CoarseForm("skinned"))
    np.testing.assert_allclose(learned.evaluate("detail", val.poses, val.transl).points, want, atol=1e-4, rtol=0)


def test_runs_from_before_coarse_target_resume(data, tmp_path):
    """A run.json written before the coarse_target key existed still resumes."""
    path, ds = data
    one = TrainConfig(**{**QUICK.to_json(), "epochs": 1})
    train("coarse", path, tmp_path / "r", one, device="cpu", dataset=ds)
    info = json.loads((tmp_path / "r" / "run.json").read_text())
    del info["config"]["coarse_target"]
    (tmp_path / "r" / "run.json").write_text(json.dumps(info))
    assert len(train("coarse", path, tmp_path / "r", QUICK, device="cpu", dataset=ds, resume=True).history) == \
        QUICK.epochs


def test_exported_bundle_runs_like_the_torch_models(tmp_path_factory):
    from cloth_usd.runtime import LearnedGarment, load_bundle

    data, coarse_dir, detail_dir = tiny_runs(tmp_path_factory)
    bundle = load_bundle(tiny_trained_bundle(tmp_path_factory))
    manifest = bundle.manifest
    ds = load_dataset(data, (Split.VAL,), max_frames=4)
    assert manifest["training_data"]["manifest_sha256"] == ds.manifest_sha256
    assert manifest["metrics"]["export_parity"]["detail_max_m"] <= 1e-4
    assert manifest["models"]["detail"]["config"]["train"]["config"]["width"] == TINY_TRAIN["width"]
    coarse, detail = load_run(coarse_dir).model, load_run(detail_dir).model
    clip = ds.split(Split.VAL)[-1]
    learned = LearnedGarment(bundle, ds.body, clip.pair.betas, clip.rest_points, clip.pair.faces,
                             strain_limit=None, lift=False)  # the models alone, as the torch reference: no
    # strain limit, no lift of the triangles off the body
    np.testing.assert_array_equal(learned.alpha, clip.pair.alpha)
    for tier, fns in (("coarse", (torch_coarse_fn(coarse),)), ("detail", (torch_coarse_fn(coarse),
                                                                          torch_detail_fn(detail)))):
        got = learned.evaluate(tier, clip.poses, clip.transl).points
        want, _ = run_tiers(ds.body, clip.pair, clip.poses, clip.transl, *fns)
        np.testing.assert_allclose(got, want, atol=1e-4, rtol=0)


def test_graph_tensor_cache_pins_its_graphs():
    """Evaluation makes one graph per clip and drops it; a new graph could get a dead one's
    id, and an id-keyed cache would hand it the old garment's tables (seen: an index out of
    bounds in the ablation runs). The cache keeps its graphs alive, so ids stay unique."""
    import gc
    import weakref

    from meshes import grid

    from cloth_usd.core.graph import build_graph
    from cloth_usd.nn.train import _Tensors
    from cloth_usd.runtime.io import COARSE_INPUTS, coarse_inputs

    tensors = _Tensors(torch.device("cpu"))
    refs = []
    for nx in (4, 5, 6, 7):  # garments of different sizes, each graph dropped after use
        faces, pos = grid(nx, 3)
        graph = build_graph(faces, pos)
        nbr = tensors(coarse_inputs(np.zeros((1, len(pos), 7)), graph.table), graph, COARSE_INPUTS)[1]
        assert nbr.shape[0] == len(pos) and int(nbr.max()) < len(pos)
        refs.append(weakref.ref(graph))
        del graph
        gc.collect()
    assert all(r() is not None for r in refs)


def test_export_checks_parity_on_another_data_set_when_only_the_manifest_came_back(tmp_path_factory, capsys):
    """Runs trained where their data set stayed (a GPU lease): --data holds only manifest.json and
    fit.npz, so the parity check needs --parity-data; the bundle records the training data set."""
    import shutil

    from cloth_usd.cli import main
    from cloth_usd.runtime import load_bundle

    data, coarse, detail = tiny_runs(tmp_path_factory)
    came_back = tmp_path_factory.mktemp("came-back")
    for name in ("manifest.json", "fit.npz"):
        shutil.copy(data / name, came_back / name)
    out = tmp_path_factory.mktemp("bundles") / "b"
    args = ["export", "--coarse-run", str(coarse), "--detail-run", str(detail), "--data", str(came_back),
            "-o", str(out), "--name", "parity-elsewhere"]
    assert main(args) == 2  # the manifest names validation shards that are not there
    assert "unreadable shard" in capsys.readouterr().err
    assert main(args + ["--parity-data", str(data)]) == 0
    assert f"on the sequences of {data}" in capsys.readouterr().out
    manifest = load_bundle(out).manifest
    assert manifest["training_data"]["manifest_sha256"] == load_dataset(data, (Split.VAL,)).manifest_sha256
    assert manifest["metrics"]["export_parity"]["sequences"] > len(load_dataset(data, (Split.VAL,)).clips)
