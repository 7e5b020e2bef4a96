"""``cloth-usd doctor``: check body model files and the runtime, and say exactly what is wrong."""

from __future__ import annotations

import importlib.util
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from .core.body import BodyModel, load_body_model, posed_vertices, shape_body
from .errors import ClothUsdError

__all__ = ["Check", "run_checks"]


@dataclass(frozen=True)
class Check:
    """One finding."""

    name: str
    ok: bool
    detail: str


def _body_checks(body: BodyModel) -> list[Check]:
    checks = []
    v_shaped, joints = shape_body(body, np.zeros(body.num_betas))
    height = float(np.ptp(v_shaped[:, 1]))
    checks.append(Check("rest height", 1.2 <= height <= 2.3,
                        f"{height:.3f} m (expected an adult, 1.2-2.3 m, Y-up, metres)"))
    reg_sums = body.J_regressor.sum(axis=1)
    checks.append(Check("joint regressor", bool(np.allclose(reg_sums, 1.0, atol=1e-3)),
                        f"row sums {reg_sums.min():.4f}..{reg_sums.max():.4f} (expected 1)"))
    # T-pose: wrists level with the shoulders and far out to the sides.
    drop = float(np.max(np.abs(joints[[20, 21], 1] - joints[[16, 17], 1])))
    checks.append(Check("T-pose rest", drop < 0.12 and joints[20, 0] > joints[21, 0],
                        f"wrists {drop * 100:.1f} cm from shoulder height; left wrist at "
                        f"x={joints[20, 0]:+.2f} m (expected the T-pose, body's left at +X)"))
    tri = v_shaped[body.faces]
    volume = float(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6.0)
    checks.append(Check("face winding", volume > 0,
                        f"signed volume {volume * 1000:.1f} litres (expected positive: outward normals)"))
    rng = np.random.default_rng(0)
    pose = rng.normal(0.0, 0.3, size=(1, 72))
    verts = posed_vertices(body, rng.normal(size=body.num_betas), pose)
    checks.append(Check("posed body", bool(np.all(np.isfinite(verts))), "random pose and shape give finite vertices"))
    return checks


def _smplx_check(body: BodyModel) -> Check:
    if importlib.util.find_spec("smplx") is None or importlib.util.find_spec("torch") is None:
        return Check("smplx", True, "not installed (only training needs it)")
    import torch

    from .body_torch import to_smplx

    rng = np.random.default_rng(1)
    betas, pose = rng.normal(size=body.num_betas), rng.normal(0.0, 0.3, size=72)
    model = to_smplx(body)
    with torch.no_grad():
        out = model(betas=torch.tensor(betas[None], dtype=torch.float32),
                    global_orient=torch.tensor(pose[None, :3], dtype=torch.float32),
                    body_pose=torch.tensor(pose[None, 3:], dtype=torch.float32))
    ours = posed_vertices(body, betas, pose[None])[0]
    err = float(np.abs(out.vertices[0].numpy() - ours).max())
    return Check("smplx", err < 1e-4, f"smplx.SMPL loads it; max difference to numpy LBS {err * 1000:.4f} mm")


def _dependency_checks() -> list[Check]:
    pxr = importlib.util.find_spec("pxr") is not None
    ort = importlib.util.find_spec("onnxruntime") is not None
    return [
        Check("pxr", pxr, "usd-core" + ("" if pxr else ": not installed (pip install usd-core)")),
        Check("onnxruntime", True, "installed" if ort else
              "not installed: the skinning tier works; coarse and detail need pip install 'cloth-usd[runtime]'"),
    ]


def run_checks(body_model: str | Path | None = None, *, gender: str = "neutral",
               progress: Callable[[Check], None] | None = None) -> list[Check]:
    """Run every check; a body model that fails to load is one failed check naming why."""
    checks: list[Check] = []

    def add(check: Check) -> None:
        checks.append(check)
        if progress:
            progress(check)

    for c in _dependency_checks():
        add(c)
    try:
        body = load_body_model(body_model, gender=gender)
    except ClothUsdError as exc:
        add(Check("body model", False, str(exc)))
        return checks
    add(Check("body model", True, f"{body.source}: {body.num_vertices} vertices, "
                                  f"{body.faces.shape[0]} faces, {body.num_betas} betas, "
                                  f"pose correctives {'yes' if body.posedirs is not None else 'none'}"))
    for c in _body_checks(body):
        add(c)
    add(_smplx_check(body))
    return checks
