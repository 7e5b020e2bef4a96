"""Helpers of the export tests: a tiny hand-built garment animation and a tiny skinned
body, and the Khronos glTF-Validator (npm, installed by scripts/setup_web.sh)."""

from __future__ import annotations

import json
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np
import pytest

from cloth_usd.core.animation import MeshAnimation, SkinnedAnimation, axis_angle_to_quaternion

ROOT = Path(__file__).resolve().parents[2]
WEB = ROOT / "web"


def grid_animation(t: int = 24, side: int = 6, *, uvs: bool = True, seed: int = 0) -> MeshAnimation:
    """A side x side cloth patch (1 m) that waves in 3 modes and drifts along x."""
    rng = np.random.default_rng(seed)
    u, v = np.meshgrid(np.linspace(0, 1, side), np.linspace(0, 1, side))
    rest = np.stack([u.ravel(), 1.0 + 0.5 * v.ravel(), np.zeros(side * side)], axis=1)
    phase = np.linspace(0, 2 * np.pi, t)[:, None]
    wave = (0.05 * np.sin(phase + 3 * u.ravel()) + 0.02 * np.cos(2 * phase) * v.ravel()
            + 0.01 * np.sin(3 * phase) * u.ravel() * v.ravel())
    points = np.repeat(rest[None], t, axis=0)
    points[..., 2] += wave
    points[..., 0] += np.linspace(0, 0.3, t)[:, None]
    points += rng.normal(0, 1e-6, points.shape)
    i = np.arange(side - 1)
    a = (i[:, None] * side + i[None, :]).ravel()
    tris = np.concatenate([np.stack([a, a + 1, a + side + 1], 1), np.stack([a, a + side + 1, a + side], 1)])
    return MeshAnimation(name="/Char/Patch", points=points, triangles=tris.astype(np.int64),
                         times=np.arange(t) / 24.0, time_codes=1001.0 + np.arange(t), fps=24.0,
                         uvs=np.stack([u.ravel(), v.ravel()], 1) if uvs else None)


def chain_body(t: int = 24) -> SkinnedAnimation:
    """Three joints in a chain, a 4-vertex strip skinned to them, bending over time."""
    joints = np.array([[0.0, 1.0, 0.0], [0.0, 1.5, 0.0], [0.0, 2.0, 0.0]])
    verts = np.array([[-0.1, 1.0, 0.0], [0.1, 1.0, 0.0], [-0.1, 2.0, 0.0], [0.1, 2.0, 0.0]])
    weights = np.array([[1.0, 0, 0], [0.7, 0.3, 0], [0, 0.4, 0.6], [0, 0, 1.0]])
    angle = np.linspace(0, 1.0, t)
    aa = np.zeros((t, 3, 3))
    aa[:, 1, 2] = angle
    aa[:, 0, 1] = 0.5 * angle
    return SkinnedAnimation(name="/Char/Skel", rest_vertices=verts, triangles=np.array([[0, 1, 3], [0, 3, 2]]),
                            weights=weights, rest_joints=joints, parents=np.array([-1, 0, 1]),
                            joint_names=("root", "mid", "tip"), rotations=axis_angle_to_quaternion(aa),
                            root_translation=joints[0] + np.stack([np.linspace(0, 0.2, t), 0 * angle, 0 * angle], 1),
                            times=np.arange(t) / 24.0)


def validator_ready() -> bool:
    return shutil.which("node") is not None and (WEB / "node_modules" / "gltf-validator").is_dir()


def validate(*paths: Path) -> list[dict]:
    """The Khronos glTF-Validator's report of each file (skips when it is not installed)."""
    if not validator_ready():
        pytest.skip("gltf-validator is not installed (bash scripts/setup_web.sh)")
    out = subprocess.run(["node", str(WEB / "validate.mjs"), *map(str, paths)], capture_output=True, text=True,
                         timeout=120)
    reports = [json.loads(line) for line in out.stdout.splitlines() if line.startswith("{")]
    assert len(reports) == len(paths), out.stderr
    return reports


def _quat_matrix(q: np.ndarray) -> np.ndarray:
    x, y, z, w = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def play_gltf(doc: dict, blob: bytes, frame: int) -> dict[str, np.ndarray]:
    """What a glTF player shows at a sampled frame, by mesh name: (N, 3) world positions.

    Morph targets are weighted by the ``weights`` channel; skinned meshes are posed by
    their joints' ``rotation`` / ``translation`` channels (keys are frames, so no
    interpolation is needed). An independent reading of the file, for the tests.
    """
    from cloth_usd.export.gltf import read_accessor

    nodes = [dict(n) for n in doc["nodes"]]
    for anim in doc.get("animations", []):
        for ch in anim["channels"]:
            sampler = anim["samplers"][ch["sampler"]]
            out = read_accessor(doc, blob, sampler["output"]).astype(np.float64)
            count = read_accessor(doc, blob, sampler["input"]).shape[0]
            node = nodes[ch["target"]["node"]]
            values = out.reshape(count, -1)[frame]
            node[ch["target"]["path"]] = values
    parent = {c: i for i, n in enumerate(nodes) for c in n.get("children", [])}

    def world(i: int) -> np.ndarray:
        local = np.eye(4)
        n = nodes[i]
        if "rotation" in n:
            local[:3, :3] = _quat_matrix(np.asarray(n["rotation"], dtype=np.float64))
        if "translation" in n:
            local[:3, 3] = n["translation"]
        return world(parent[i]) @ local if i in parent else local

    shown = {}
    for i, n in enumerate(nodes):
        if "mesh" not in n:
            continue
        mesh = doc["meshes"][n["mesh"]]
        prim = mesh["primitives"][0]
        pos = read_accessor(doc, blob, prim["attributes"]["POSITION"]).astype(np.float64)
        weights = n.get("weights", mesh.get("weights", []))
        for w, target in zip(weights, prim.get("targets", [])):
            pos = pos + w * read_accessor(doc, blob, target["POSITION"])
        if "skin" in n:
            skin = doc["skins"][n["skin"]]
            inv = read_accessor(doc, blob, skin["inverseBindMatrices"]).reshape(-1, 4, 4).transpose(0, 2, 1)
            mats = np.stack([world(j) @ inv[k] for k, j in enumerate(skin["joints"])])
            joints = read_accessor(doc, blob, prim["attributes"]["JOINTS_0"]).astype(np.int64)
            jw = read_accessor(doc, blob, prim["attributes"]["WEIGHTS_0"]).astype(np.float64)
            homo = np.concatenate([pos, np.ones((pos.shape[0], 1))], axis=1)
            blended = np.einsum("vk,vkij->vij", jw, mats[joints])
            pos = np.einsum("vij,vj->vi", blended, homo)[:, :3]
        else:
            pos = (world(i) @ np.concatenate([pos, np.ones((pos.shape[0], 1))], axis=1).T).T[:, :3]
        shown[mesh["name"]] = pos
    return shown


def skin_reference(body: SkinnedAnimation, frame: int) -> np.ndarray:
    """(V, 3) the body posed by its own definition (SkinnedAnimation's docstring)."""
    j = body.rest_joints.shape[0]
    g = np.zeros((j, 4, 4))
    for i in range(j):
        local = np.eye(4)
        local[:3, :3] = _quat_matrix(body.rotations[frame, i])
        p = body.parents[i]
        local[:3, 3] = body.root_translation[frame] if p < 0 else body.rest_joints[i] - body.rest_joints[p]
        g[i] = local if p < 0 else g[p] @ local
    rel = body.rest_vertices[:, None, :] - body.rest_joints[None]  # (V, J, 3)
    posed = np.einsum("jab,vjb->vja", g[:, :3, :3], rel) + g[None, :, :3, 3]
    return np.einsum("vj,vja->va", body.weights, posed)


#: Debian's chromium, headless, no network, a fresh profile per run; software WebGL
#: (SwiftShader) since there is no GPU: --enable-unsafe-swiftshader opts in to it.
CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--enable-unsafe-swiftshader", "--disable-quic",
                  "--no-first-run", "--disable-background-networking", "--disable-component-update", "--disable-sync",
                  "--enable-logging=stderr", "--v=0")


def chromium(page: Path, work: Path, *, screenshot: Path | None = None, size: str = "960,720",
             budget_ms: int = 4000, fragment: str = "") -> subprocess.CompletedProcess:
    """Run headless chromium on a local page (``fragment``: e.g. ``#frame=3``): the DOM on
    stdout (``--dump-dom``), or a screenshot; console messages are on stderr. Skips when
    chromium is not installed."""
    exe = shutil.which("chromium")
    if exe is None:
        pytest.skip("chromium is not installed (bash scripts/setup_web.sh installs Debian's)")
    profile = Path(tempfile.mkdtemp(prefix="profile-", dir=work))
    what = [f"--screenshot={screenshot}"] if screenshot else ["--dump-dom"]
    return subprocess.run([exe, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", f"--window-size={size}",
                           f"--virtual-time-budget={budget_ms}", *what, page.resolve().as_uri() + fragment],
                          capture_output=True, text=True, timeout=180)


def console_lines(stderr: str) -> list[str]:
    """The page's console messages in chromium's log (the message text only)."""
    import re

    return [m.group(1) for m in re.finditer(r':CONSOLE:\d+\] "(.*)", source: ', stderr)]


def pixel_fractions(png: Path) -> tuple[float, float]:
    """Fractions of a screenshot's pixels in the garment's blue and in the body's skin tone
    (the page's background and grid are grey)."""
    import matplotlib.image

    rgb = matplotlib.image.imread(str(png))[..., :3].astype(np.float64)
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    return float(np.mean((b > r + 0.15) & (b > g + 0.05))), float(np.mean((r > b + 0.1) & (r > 0.35)))
