"""The generators trained on the garment's physics: planned sequences, lower energy, runs, export."""

from __future__ import annotations

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="training needs torch (pip install 'cloth-usd[train]')")

from train_data import TINY, one_thread  # noqa: E402,F401 (one_thread: an autouse fixture)

from cloth_usd.core.heading import Heading, root_yaw  # noqa: E402
from cloth_usd.core.pipeline import CoarseBase, CoarseFeatures  # noqa: E402
from cloth_usd.errors import ArgumentError  # noqa: E402
from cloth_usd.nn.data import Split  # noqa: E402
from cloth_usd.nn.physics_train import _energy, _statistics, _Tier, physics_set, train_physics  # noqa: E402
from cloth_usd.core.scene import Tier  # noqa: E402
from cloth_usd.nn.train import Objective, TrainConfig, _Tensors, build_model, load_run  # noqa: E402

pytestmark = pytest.mark.slow
PHYSICS = TrainConfig(objective="physics", coarse_base="skinned", width=0.0625, epochs=2, batch=3, max_batches=2,
                      stat_frames=3, bending_scale=10.0, lr=2e-3)


@pytest.fixture(scope="module")
def config_path(tmp_path_factory):
    path = tmp_path_factory.mktemp("physics") / "tiny.json"
    path.write_text(json.dumps({**TINY, "garment_vertices": 300, "max_frames": 4}))
    return path


@pytest.fixture(scope="module")
def planned(config_path):
    return physics_set(config_path, splits=(Split.TRAIN, Split.VAL), bending_scale=10.0)


def test_the_config_is_planned_not_simulated_with_the_heading_taken_out(planned, config_path):
    assert {c.split for c in planned.clips} == {Split.TRAIN, Split.VAL}
    assert all(c.num_frames == 4 and c.rest.positions.shape[0] == c.pair.num_vertices for c in planned.clips)
    np.testing.assert_allclose(root_yaw(np.concatenate([c.poses for c in planned.clips])), 0.0, atol=1e-12)
    world = physics_set(config_path, heading=Heading.WORLD, splits=(Split.TRAIN,))
    for w, c in zip(world.clips, planned.split(Split.TRAIN)):
        np.testing.assert_allclose(c.poses[:, 3:], w.poses[:, 3:])  # only the root loses its heading
    assert planned.material.bend_stiffness == pytest.approx(10.0 * world.material.bend_stiffness)
    wide = physics_set(config_path, splits=(Split.TRAIN,), contact_margin=0.008)  # TrainConfig.contact_margin
    assert wide.material.contact_margin == 0.008 != world.material.contact_margin
    assert wide.material.cubic_contact_weight == pytest.approx(wide.material.contact_stiffness / 0.008)
    with pytest.raises(ArgumentError, match="contact_margin=0"):
        TrainConfig(contact_margin=0)


def test_training_finds_a_garment_of_lower_energy_than_skinning(planned):
    """Overfitting one batch: the model's garment ends below the skinned garment's energy."""
    clip = planned.split(Split.TRAIN)[0]
    frames = np.arange(clip.num_frames)
    step = _Tier(Tier.COARSE, _body(), CoarseBase.SKINNED, _Tensors(torch.device("cpu")))
    inp = step.inputs(clip, frames)
    torch.manual_seed(0)
    model = build_model(Tier.COARSE, PHYSICS)
    _statistics(model, step, [clip], PHYSICS)
    opt = torch.optim.Adam(model.parameters(), lr=2e-3)
    e_skinned = float(_energy(clip, torch.from_numpy(inp.base), inp, planned.material).mean())

    def energy():
        return _energy(clip, step.forward(model, clip, inp), inp, planned.material).mean()

    first = float(energy().detach())
    for _ in range(60):
        loss = energy()
        opt.zero_grad()
        loss.backward()
        opt.step()
    last = float(energy().detach())
    assert last < first and last < e_skinned, (first, last, e_skinned)


def test_a_physics_run_loads_and_exports_a_bundle_that_bakes(config_path, tmp_path):
    from cloth_usd.nn.export import export_bundle
    from cloth_usd.runtime.bundle import load_bundle

    result = train_physics(config_path, tmp_path / "run", PHYSICS, device="cpu")
    assert len(result.history) == 2 and all(np.isfinite(r.train_loss) and np.isfinite(r.val_loss)
                                            for r in result.history)
    for name in ("run.json", "best.pt", "checkpoint.pt", "history.csv", "curve.png", "fit.npz"):
        assert (tmp_path / "run" / name).is_file(), name
    run = load_run(tmp_path / "run")
    assert run.config.objective is Objective.PHYSICS and run.info["data"]["kind"] == "physics"
    out = export_bundle(tmp_path / "run", None, config_path, tmp_path / "bundle", name="physics-test")
    bundle = load_bundle(out)
    assert bundle.form.heading is Heading.CANONICAL and bundle.form.base is CoarseBase.SKINNED
    assert bundle.manifest["metrics"]["export_parity"]["coarse_max_m"] < 1e-4
    # the joint angles of the config's training motions, each once, which a bake checks a shot against
    from cloth_usd.core.limits import pose_range
    from cloth_usd.datagen.factory import load_config, train_poses

    poses = train_poses(load_config(config_path))
    assert bundle.manifest["training_data"]["poses"]["frames"] == len(poses)
    np.testing.assert_allclose(bundle.pose_limits, pose_range(poses), atol=np.deg2rad(0.006))
    from cloth_usd.datagen.factory import train_betas

    betas = train_betas(load_config(config_path))  # and the bodies it was trained on
    assert bundle.manifest["training_data"]["bodies"]["count"] == len(betas)
    np.testing.assert_allclose(bundle.betas_limits, np.stack([betas.min(0), betas.max(0)], axis=1))
    with pytest.raises(ArgumentError, match="a run exists there"):
        train_physics(config_path, tmp_path / "run", PHYSICS, device="cpu")


def test_the_detail_tier_trains_on_the_coarse_run_and_ships_with_it(config_path, tmp_path):
    from cloth_usd.nn.export import export_bundle
    from cloth_usd.runtime.bundle import load_bundle

    contact = TrainConfig(**{**PHYSICS.to_json(), "coarse_features": "contact"})  # the detail run takes them
    train_physics(config_path, tmp_path / "coarse", contact, device="cpu")
    assert load_run(tmp_path / "coarse").model.config.in_features == 11
    detail_cfg = TrainConfig(**{**PHYSICS.to_json(), "bending_scale": 1.0, "width": 0.125})
    with pytest.raises(ArgumentError, match="detail tier needs --coarse-run"):
        train_physics(config_path, tmp_path / "detail", detail_cfg, tier="detail", device="cpu")
    result = train_physics(config_path, tmp_path / "detail", detail_cfg, tier="detail", coarse_run=tmp_path / "coarse",
                           device="cpu")
    assert all(np.isfinite(r.val_loss) for r in result.history)
    run = load_run(tmp_path / "detail")
    assert run.tier is Tier.DETAIL and run.info["coarse_run"]["path"].endswith("coarse")
    out = export_bundle(tmp_path / "coarse", tmp_path / "detail", config_path, tmp_path / "bundle", name="phys-pair")
    bundle = load_bundle(out)
    assert Tier.DETAIL in bundle.tiers and bundle.manifest["metrics"]["export_parity"]["detail_max_m"] < 1e-4
    assert bundle.form.features is CoarseFeatures.CONTACT
    assert bundle.manifest["models"]["coarse"]["features"] == "contact"


def test_the_supervised_trainer_refuses_the_physics_objective(tmp_path):
    from cloth_usd.nn.train import train

    with pytest.raises(ArgumentError, match="objective 'physics' trains on a data set config"):
        train("coarse", tmp_path, tmp_path / "run", PHYSICS, device="cpu")


def _body():
    from cloth_usd.core.body import load_body_model

    return load_body_model()


@pytest.mark.parametrize("seed", range(4))
def test_a_fresh_model_starts_alive_near_its_base(planned, seed):
    """Every vertex starts with a small positive magnitude, whatever the seed (no dead ReLU)."""
    clip = planned.split(Split.TRAIN)[0]
    step = _Tier(Tier.COARSE, _body(), CoarseBase.SKINNED, _Tensors(torch.device("cpu")))
    inp = step.inputs(clip, np.arange(2))
    torch.manual_seed(seed)
    model = build_model(Tier.COARSE, PHYSICS)
    _statistics(model, step, [clip], PHYSICS)
    with torch.no_grad():
        moved = torch.linalg.vector_norm(step.forward(model, clip, inp) - torch.from_numpy(inp.base), dim=-1)
    assert float(moved.min()) > 1e-4 and float(moved.max()) < 5e-3  # 0.1 to 5 mm


def test_nearest_contact_measures_a_sliding_vertex_against_the_body_under_it(planned):
    """A garment vertex moved along the body, 4 mm off it, is outside the body: the nearest
    contact puts it against the body point under it (almost no contact energy); the associated
    contact still measures it against the body point it left."""
    from cloth_usd.core.postprocess import nearest_vertex
    from cloth_usd.nn.physics_train import ContactPoints, PhysicsOptions

    cloud = np.array([[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]])
    np.testing.assert_array_equal(nearest_vertex(np.array([[[0.9, 0.1, 0.0], [0.1, 0.2, 0.0]]]), cloud), [[1, 0]])
    assert PhysicsOptions().contact is ContactPoints.NEAREST
    assert PhysicsOptions(contact="associated").to_json()["contact"] == "associated"
    with pytest.raises(ArgumentError, match="contact must be one of nearest, associated"):
        PhysicsOptions(contact="closest")

    clip = planned.split(Split.TRAIN)[0]
    step = _Tier(Tier.COARSE, _body(), CoarseBase.SKINNED, _Tensors(torch.device("cpu")))
    inp = step.inputs(clip, np.array([0]))
    body, normals = inp.cloud_points[0], inp.cloud_normals[0]
    garment = inp.base.copy()
    # every garment vertex placed 8 mm outside one body vertex far (> 5 cm) from its associated one
    far = np.linalg.norm(body[:, None] - inp.body_points[0][None], axis=-1) > 0.05
    pick = np.argmax(far, axis=0)
    garment[0] = body[pick] + 0.008 * normals[pick]
    x = torch.from_numpy(garment)
    near = float(_energy(clip, x, inp, planned.material))
    assoc = float(_energy(clip, x, inp, planned.material, contact=ContactPoints.ASSOCIATED))
    from cloth_usd.nn.physics import garment_energy

    free = float(garment_energy(x, clip.rest, planned.material).total)  # no contact term at all
    assert near == pytest.approx(free, rel=1e-3) and assoc > free + 1.0, (near, assoc, free)
