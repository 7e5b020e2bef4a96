"""Build a corpus of malformed inputs for ``cloth-usd`` (issue #6).

Each case lives in its own folder ``OUT/<name>/`` (inputs, and where its output would
go); the cases that only break an argument or the body model share a clean copy of
the walk sample in ``OUT/_shared/``. Every case must end in one
``cloth-usd: error: ...`` line on stderr, exit code 2, and no file written.

Run it as a script to look at the corpus::

    python tests/malformed/make_corpus.py /tmp/corpus

or import :func:`build_corpus`. ``Case.argv`` is relative to the corpus folder, so run
``cloth_usd.cli.main(case.argv)`` with that folder as the working directory.
"""

from __future__ import annotations

import hashlib
import json
import os
import pickle
import shutil
import sys
from pathlib import Path
from typing import Callable, NamedTuple

import numpy as np
from pxr import Sdf, Usd, UsdGeom, UsdSkel, Vt

from cloth_usd.core.smpl import NUM_JOINTS, PARENTS

__all__ = ["Case", "build_corpus", "SAMPLE", "SHARED"]

SAMPLE = Path(__file__).resolve().parents[2] / "samples" / "walk_tshirt" / "scene.usda"
BUNDLE = Path(__file__).resolve().parents[2] / "models" / "bundles" / "tshirt-v3"
SHARED = "_shared"
SKEL = "/Character/Skeleton"
SHIRT = "/Character/Tshirt"
MOTION = "/Character/Skeleton/Motion"


class Case(NamedTuple):
    """One malformed input."""

    name: str
    """Unique case name; also its folder under the corpus root."""
    argv: list[str]
    """Arguments for ``cloth_usd.cli.main``, paths relative to the corpus root."""
    expect: tuple[str, ...]
    """Substrings the one error line must contain (file name, prim path, reason)."""
    must_not_exist: tuple[str, ...] = ()
    """Paths (relative to the corpus root) that must not appear, e.g. a pickle's marker."""
    known_bug: str = ""
    """Non-empty when cloth_usd still mishandles the case: where and how (an xfail)."""


# ------------------------------------------------------------------------- stages


def _skel(stage: Usd.Stage) -> UsdSkel.Skeleton:
    return UsdSkel.Skeleton(stage.GetPrimAtPath(SKEL))


def _joints(stage: Usd.Stage) -> list[str]:
    return [str(j) for j in _skel(stage).GetJointsAttr().Get()]


def _set_joints(stage: Usd.Stage, joints: list[str]) -> None:
    _skel(stage).GetJointsAttr().Set(joints)


def _rename_component(old: str, new: str) -> Callable[[Usd.Stage], None]:
    """Rename one joint everywhere it appears as a path component (the joint goes missing)."""
    def edit(stage):
        _set_joints(stage, ["/".join(new if c == old else c for c in j.split("/")) for j in _joints(stage)])
    return edit


def _drop_joint(name: str) -> Callable[[Usd.Stage], None]:
    """Remove a leaf joint and its rest/bind matrices (a 23-joint skeleton)."""
    def edit(stage):
        skel = _skel(stage)
        joints = _joints(stage)
        i = next(k for k, j in enumerate(joints) if j.split("/")[-1] == name)
        skel.GetJointsAttr().Set(joints[:i] + joints[i + 1:])
        for attr in (skel.GetRestTransformsAttr(), skel.GetBindTransformsAttr()):
            value = attr.Get()
            if value is not None:
                attr.Set(Vt.Matrix4dArray(list(value)[:i] + list(value)[i + 1:]))
    return edit


def _move_joint(old_prefix: str, new_prefix: str) -> Callable[[Usd.Stage], None]:
    """Re-hang a joint (and its subtree) under another parent: a hierarchy breach."""
    def edit(stage):
        joints = []
        for j in _joints(stage):
            if j == old_prefix or j.startswith(old_prefix + "/"):
                j = new_prefix + j[len(old_prefix):]
            joints.append(j)
        _set_joints(stage, joints)
    return edit


def _swap_leaf(a: str, b: str) -> Callable[[Usd.Stage], None]:
    def edit(stage):
        swap = {a: b, b: a}
        _set_joints(stage, ["/".join(swap.get(c, c) for c in j.split("/")) for j in _joints(stage)])
    return edit


def _duplicate_joint(stage):
    joints = _joints(stage)
    neck = next(j for j in joints if j.endswith("/neck"))
    _set_joints(stage, joints + [neck + "/left_wrist"])


def _pelvis_last(stage):
    joints = _joints(stage)
    _set_joints(stage, joints[1:] + joints[:1])


def _empty_joints(stage):
    _set_joints(stage, [])


def _no_joints_attr(stage):
    stage.GetPrimAtPath(SKEL).RemoveProperty("joints")


def _attr(path: str, name: str, type_name, value, *, uniform: bool = False):
    def edit(stage):
        prim = stage.GetPrimAtPath(path)
        prim.RemoveProperty(name)
        variability = Sdf.VariabilityUniform if uniform else Sdf.VariabilityVarying
        prim.CreateAttribute(name, type_name, custom=True, variability=variability).Set(value)
    return edit


def _remove(path: str, name: str):
    def edit(stage):
        stage.GetPrimAtPath(path).RemoveProperty(name)
    return edit


def _body_targets(*targets: str):
    def edit(stage):
        stage.GetPrimAtPath(SHIRT).GetRelationship("cloth:body").SetTargets([Sdf.Path(t) for t in targets])
    return edit


def _second_mesh_target(stage):
    UsdGeom.Mesh.Define(stage, "/Character/Hat")
    _body_targets("/Character/Hat")(stage)


def _points_edit(fn):
    def edit(stage):
        attr = UsdGeom.Mesh(stage.GetPrimAtPath(SHIRT)).GetPointsAttr()
        pts = np.array(attr.Get(), dtype=np.float32)
        attr.Set(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(fn(pts), dtype=np.float32)))
    return edit


def _set_pt(row: int, col: int, value: float):
    def fn(pts):
        pts[row, col] = value
        return pts
    return fn


def _time_sampled_points(stage):
    attr = UsdGeom.Mesh(stage.GetPrimAtPath(SHIRT)).GetPointsAttr()
    pts = attr.Get()
    attr.Clear()
    attr.Set(pts, 1001.0)
    attr.Set(pts, 1002.0)


def _topology(counts=None, indices=None):
    def edit(stage):
        mesh = UsdGeom.Mesh(stage.GetPrimAtPath(SHIRT))
        c = np.array(mesh.GetFaceVertexCountsAttr().Get(), dtype=np.int32)
        i = np.array(mesh.GetFaceVertexIndicesAttr().Get(), dtype=np.int32)
        if counts is not None:
            c = counts(c)
            mesh.GetFaceVertexCountsAttr().Set(Vt.IntArray.FromNumpy(np.ascontiguousarray(c, np.int32)))
        if indices is not None:
            i = indices(i)
            mesh.GetFaceVertexIndicesAttr().Set(Vt.IntArray.FromNumpy(np.ascontiguousarray(i, np.int32)))
    return edit


def _with(arr: np.ndarray, pos: int, value: int) -> np.ndarray:
    arr = arr.copy()
    arr[pos] = value
    return arr


def _anim_nan_rotation(stage):
    anim = UsdSkel.Animation(stage.GetPrimAtPath(MOTION))
    attr = anim.GetRotationsAttr()
    rots = attr.Get(1010.0)
    q = np.array(rots, dtype=np.float32)  # (J, 4), (real, i, j, k)
    q[4] = np.nan
    attr.Set(Vt.QuatfArray.FromNumpy(q), 1010.0)


def _anim_short_rotations(stage):
    anim = UsdSkel.Animation(stage.GetPrimAtPath(MOTION))
    attr = anim.GetRotationsAttr()
    for t in attr.GetTimeSamples():
        attr.Set(Vt.QuatfArray(list(attr.Get(t))[:5]), t)


def _nan_rest(stage):
    skel = _skel(stage)
    for attr in (skel.GetRestTransformsAttr(), skel.GetBindTransformsAttr()):
        value = attr.Get()
        if value is not None:
            m = np.array(value)
            m[3, 3, 0] = np.nan
            attr.Set(Vt.Matrix4dArray.FromNumpy(m))


def _anim_time_key(key: float):
    """A rotations time sample at a key that is not a finite time code."""
    def edit(stage):
        attr = UsdSkel.Animation(stage.GetPrimAtPath(MOTION)).GetRotationsAttr()
        stage.GetRootLayer().SetTimeSample(attr.GetPath(), key, attr.Get(1001.0))  # USD drops a NaN key
    return edit


def _layer_info(key: str, value: float):
    def edit(stage):
        stage.GetRootLayer().pseudoRoot.SetInfo(key, value)
    return edit


def _no_time_codes(stage):
    layer = stage.GetRootLayer()
    layer.ClearStartTimeCode()
    layer.ClearEndTimeCode()


def _empty_range(stage):
    stage.SetStartTimeCode(1010)
    stage.SetEndTimeCode(1001)


def _no_garments(stage):
    stage.RemovePrim(SHIRT)


def _up_axis(value: str):
    def edit(stage):
        stage.GetRootLayer().pseudoRoot.SetInfo("upAxis", value)
    return edit


def _meters_per_unit(value: float):
    def edit(stage):
        stage.GetRootLayer().pseudoRoot.SetInfo("metersPerUnit", value)
    return edit


#: name -> (edit, expected substrings besides the file name)
STAGE_EDITS: dict[str, tuple[Callable[[Usd.Stage], None], tuple[str, ...]]] = {
    # joints missing (renamed everywhere, so the subtree stays consistent)
    **{f"missing_joint_{n}": (_rename_component(n, n + "_x"), (SKEL, n, "lacks SMPL joint"))
       for n in ("pelvis", "left_hip", "spine3", "neck", "left_elbow", "right_hand", "head")},
    "skeleton_23_joints": (_drop_joint("right_hand"), (SKEL, "right_hand", "lacks SMPL joint")),
    "duplicate_joint": (_duplicate_joint, (SKEL, "left_wrist", "appears twice")),
    "hierarchy_knee_under_other_hip": (
        _move_joint("pelvis/left_hip/left_knee", "pelvis/right_hip/left_knee"), (SKEL, "left_knee", "SMPL")),
    "hierarchy_head_under_spine3": (
        _move_joint("pelvis/spine1/spine2/spine3/neck/head", "pelvis/spine1/spine2/spine3/head"),
        (SKEL, "'head'", "expects neck")),
    "hierarchy_spine1_is_a_root": (_move_joint("pelvis/spine1", "spine1"), (SKEL, "spine1", "root")),
    "hierarchy_hips_swapped": (_swap_leaf("left_hip", "right_hip"), (SKEL, "knee", "SMPL expects")),
    "hierarchy_pelvis_after_children": (_pelvis_last, (SKEL, "topology")),
    "joints_attribute_empty": (_empty_joints, (SKEL, "lacks SMPL joint", "pelvis")),
    "joints_attribute_missing": (_no_joints_attr, (SKEL, "lacks SMPL joint")),
    "rest_transforms_nan": (_nan_rest, (SKEL, "not finite")),
    "animation_nan_rotation": (_anim_nan_rotation, (SKEL, "1010")),
    "animation_minus_inf_time_key": (_anim_time_key(float("-inf")), (SKEL, "Motion.rotations", "-inf")),
    "animation_too_few_rotations": (_anim_short_rotations, (SKEL, "one value per joint")),
    # shape and gender
    "betas_11_values": (_attr(SKEL, "smpl:betas", Sdf.ValueTypeNames.FloatArray, Vt.FloatArray([0.1] * 11)),
                        (SKEL, "smpl:betas", "11")),
    "betas_nan": (_attr(SKEL, "smpl:betas", Sdf.ValueTypeNames.FloatArray,
                        Vt.FloatArray([0.1, float("nan"), 0.0])), (SKEL, "smpl:betas[1]", "finite")),
    "betas_huge": (_attr(SKEL, "smpl:betas", Sdf.ValueTypeNames.FloatArray, Vt.FloatArray([1e30])),
                   (SKEL, "smpl:betas[0]", "1e+30", "10")),
    "betas_inf": (_attr(SKEL, "smpl:betas", Sdf.ValueTypeNames.DoubleArray,
                        Vt.DoubleArray([float("inf")])), (SKEL, "smpl:betas[0]")),
    "betas_strings": (_attr(SKEL, "smpl:betas", Sdf.ValueTypeNames.StringArray,
                            Vt.StringArray(["tall", "thin"])), (SKEL, "smpl:betas")),
    "gender_bad": (_attr(SKEL, "smpl:gender", Sdf.ValueTypeNames.Token, "robot", uniform=True),
                   (SKEL, "smpl:gender", "'robot'", "neutral, female, male")),
    # garment relationship
    "garment_no_body": (_remove(SHIRT, "cloth:body"), (SHIRT, "no cloth:body")),
    "garment_two_bodies": (_body_targets(SKEL, "/Character"), (SHIRT, "2 targets")),
    "garment_body_is_itself": (_body_targets(SHIRT), (SHIRT, "Mesh, not a UsdSkel Skeleton")),
    "garment_body_is_other_mesh": (_second_mesh_target, (SHIRT, "/Character/Hat", "not a UsdSkel Skeleton")),
    "garment_body_missing_prim": (_body_targets("/Nobody/Skeleton"), (SHIRT, "/Nobody/Skeleton", "does not exist")),
    "garment_body_is_skelroot": (_body_targets("/Character"), (SHIRT, "SkelRoot")),
    # garment tokens
    "category_bad": (_attr(SHIRT, "cloth:category", Sdf.ValueTypeNames.Token, "hat", uniform=True),
                     (SHIRT, "cloth:category", "'hat'", "tshirt, dress, trousers")),
    "category_empty": (_attr(SHIRT, "cloth:category", Sdf.ValueTypeNames.Token, "", uniform=True),
                       (SHIRT, "cloth:category")),
    "category_int": (_attr(SHIRT, "cloth:category", Sdf.ValueTypeNames.Int, 3), (SHIRT, "cloth:category")),
    "tier_bad": (_attr(SHIRT, "cloth:tier", Sdf.ValueTypeNames.Token, "ultra", uniform=True),
                 (SHIRT, "cloth:tier", "'ultra'", "skinning, coarse, detail")),
    "garment_disabled": (_attr(SHIRT, "cloth:enabled", Sdf.ValueTypeNames.Bool, False), ("no enabled garment",)),
    # garment geometry
    "points_nan": (_points_edit(_set_pt(7, 1, np.nan)), (SHIRT, "points[7]", "NaN")),
    "points_inf": (_points_edit(_set_pt(0, 2, np.inf)), (SHIRT, "points[0]", "not finite")),
    "points_empty": (_points_edit(lambda p: p[:0]), (SHIRT, "no points")),
    "points_time_sampled_only": (_time_sampled_points, (SHIRT, "default")),
    "indices_out_of_range": (_topology(indices=lambda i: _with(i, 5, 10 ** 6)), (SHIRT, "1000000", "outside")),
    "indices_negative": (_topology(indices=lambda i: _with(i, 0, -1)), (SHIRT, "-1", "outside")),
    "counts_has_a_2": (_topology(counts=lambda c: np.concatenate([c[:3], [2, 1], c[4:]])),
                       (SHIRT, "face 3 has 2 vertices")),
    "counts_indices_mismatch": (_topology(indices=lambda i: i[:-1]), (SHIRT, "faceVertexCounts sum to")),
    "counts_empty": (_topology(counts=lambda c: c[:0]), (SHIRT, "no faceVertexCounts")),
    # stage metadata
    "frame_range_empty": (_empty_range, ("empty frame range",)),
    "frame_range_unauthored": (_no_time_codes, ("startTimeCode", "--frames")),
    "no_garments": (_no_garments, ("no enabled garment",)),
    "up_axis_x": (_up_axis("X"), ("upAxis", "'X'")),
    "meters_per_unit_zero": (_meters_per_unit(0.0), ("metersPerUnit",)),
    "meters_per_unit_negative": (_meters_per_unit(-1.0), ("metersPerUnit",)),
    "time_codes_per_second_zero": (_layer_info("timeCodesPerSecond", 0.0), ("timeCodesPerSecond is 0", "positive")),
    "time_codes_per_second_negative": (_layer_info("timeCodesPerSecond", -24.0), ("timeCodesPerSecond is -24",)),
    "frames_per_second_zero": (_layer_info("framesPerSecond", 0.0), ("framesPerSecond",)),
}


def _edited_stage(folder: Path, edit: Callable[[Usd.Stage], None]) -> Path:
    path = folder / "scene.usda"
    shutil.copyfile(SAMPLE, path)
    stage = Usd.Stage.Open(str(path))
    edit(stage)
    stage.GetRootLayer().Save()
    return path


# ------------------------------------------------------------------ body models


def _tiny_body(num_v: int = 12) -> dict[str, np.ndarray]:
    """A valid SMPL-layout body with few vertices, to break one key at a time."""
    rng = np.random.default_rng(0)
    weights = rng.random((num_v, NUM_JOINTS))
    reg = rng.random((NUM_JOINTS, num_v))
    return {
        "v_template": rng.normal(size=(num_v, 3)),
        "shapedirs": rng.normal(0.0, 0.01, size=(num_v, 3, 10)),
        "posedirs": np.zeros((num_v, 3, 207)),
        "J_regressor": reg / reg.sum(axis=1, keepdims=True),
        "weights": weights / weights.sum(axis=1, keepdims=True),
        "kintree_table": np.stack([np.where(PARENTS < 0, 4294967295, PARENTS), np.arange(NUM_JOINTS)]),
        "f": np.array([[i, (i + 1) % num_v, (i + 2) % num_v] for i in range(num_v)]),
    }


def _edit_body(**changes) -> dict:
    body = _tiny_body()
    for k, v in changes.items():
        if v is None:
            body.pop(k)
        else:
            body[k] = v
    return body


class _Evil:
    """Pickles as ``os.system(cmd)``: must never run."""

    def __init__(self, cmd: str) -> None:
        self.cmd = cmd

    def __reduce__(self):
        import os
        return (os.system, (self.cmd,))


class _Eval:
    def __init__(self, code: str) -> None:
        self.code = code

    def __reduce__(self):
        import builtins
        return (builtins.eval, (self.code,))


def _body_files(folder: Path, marker: Path) -> dict[str, tuple[str, tuple[str, ...], tuple[str, ...]]]:
    """Write the body model files; name -> (file relative to folder, expected, must_not_exist)."""
    out: dict[str, tuple[str, tuple[str, ...], tuple[str, ...]]] = {}

    def npz(name: str, arrays: dict, expect: tuple[str, ...]) -> None:
        np.savez(folder / f"{name}.npz", **arrays)
        out[f"body_{name}"] = (f"{name}.npz", expect, ())

    def raw(name: str, data: bytes, expect: tuple[str, ...]) -> None:
        (folder / name).write_bytes(data)
        out["body_" + name.replace(".", "_")] = (name, expect, ())

    out["body_missing"] = ("no_such_body.npz", ("no_such_body.npz", "not found"), ())
    raw("empty.npz", b"", ("empty.npz",))
    raw("garbage.npz", bytes(range(256)) * 8, ("garbage.npz", "not a readable .npz"))
    raw("empty.pkl", b"", ("empty.pkl", "pickle"))
    raw("body.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", ("body.obj", "unknown body model format"))
    npz("missing_weights", _edit_body(weights=None), ("missing_weights.npz", "missing key 'weights'"))
    npz("missing_kintree", _edit_body(kintree_table=None), ("missing_kintree.npz", "kintree_table"))
    npz("wrong_shape_shapedirs", _edit_body(shapedirs=np.zeros((12, 10))),
        ("wrong_shape_shapedirs.npz", "'shapedirs'"))
    npz("wrong_shape_posedirs", _edit_body(posedirs=np.zeros((12, 3, 200))),
        ("wrong_shape_posedirs.npz", "'posedirs'", "207"))
    npz("wrong_shape_regressor", _edit_body(J_regressor=np.full((23, 12), 1 / 12)),
        ("wrong_shape_regressor.npz", "'J_regressor'"))
    npz("nan_template", _edit_body(v_template=np.full((12, 3), np.nan)), ("nan_template.npz", "NaN"))
    npz("faces_out_of_range", _edit_body(f=np.array([[0, 1, 99]])), ("faces_out_of_range.npz", "'f'"))
    npz("faces_empty", _edit_body(f=np.zeros((0, 3), dtype=np.int64)), ("faces_empty.npz", "'f'"))
    npz("kintree_1d", _edit_body(kintree_table=np.arange(24)), ("kintree_1d.npz", "kintree_table"))
    npz("kintree_strings", _edit_body(kintree_table=np.array([["a"] * 24, ["b"] * 24])),
        ("kintree_strings.npz", "kintree_table"))
    npz("string_template", _edit_body(v_template=np.array([["x", "y", "z"]] * 12)),
        ("string_template.npz", "'v_template'"))
    objects = _edit_body()
    objects["weights"] = np.array([objects["weights"], "x"], dtype=object)
    npz("object_arrays", objects, ("object_arrays.npz", "Python objects"))

    official = {k: v for k, v in _tiny_body().items()}
    evil = dict(official, bs_style=_Evil(f"touch {marker}"))
    (folder / "evil.pkl").write_bytes(pickle.dumps(evil, protocol=2))
    out["body_pickle_os_system"] = ("evil.pkl", ("evil.pkl", "not allowed"), ())
    (folder / "eval.pkl").write_bytes(pickle.dumps(dict(official, x=_Eval(f"open({str(marker)!r}, 'w')")),
                                                   protocol=2))
    out["body_pickle_eval"] = ("eval.pkl", ("eval.pkl", "not allowed"), ())
    (folder / "list.pkl").write_bytes(pickle.dumps([official["v_template"]], protocol=2))
    out["body_pickle_list"] = ("list.pkl", ("list.pkl", "expected a dict"), ())
    whole = pickle.dumps(official, protocol=2)
    (folder / "truncated.pkl").write_bytes(whole[: len(whole) // 2])
    out["body_pickle_truncated"] = ("truncated.pkl", ("truncated.pkl", "not a loadable SMPL pickle"), ())
    (folder / "weights_string.pkl").write_bytes(pickle.dumps(dict(official, weights="heavy"), protocol=2))
    out["body_pickle_string_value"] = ("weights_string.pkl", ("weights_string.pkl", "'weights'"), ())
    npz("two_shape_components", _edit_body(shapedirs=np.zeros((12, 3, 2))),
        ("two_shape_components.npz", "smpl:betas[2]", "only 2 shape components"))
    (folder / "empty_folder").mkdir()
    out["body_folder_without_models"] = ("empty_folder", ("empty_folder", "SMPL_NEUTRAL"), ())
    return out


# ------------------------------------------------------------------------ corpus


def build_corpus(out_dir: str | Path) -> list[Case]:
    """Write every malformed input under ``out_dir`` (created) and list the cases."""
    root = Path(out_dir)
    root.mkdir(parents=True, exist_ok=True)
    cases: list[Case] = []

    def folder(name: str) -> Path:
        f = root / name
        f.mkdir()
        return f

    folder(SHARED)
    good = f"{SHARED}/scene.usda"
    shutil.copyfile(SAMPLE, root / good)

    def bake(name: str, scene: str, *extra: str, output: str | None = None) -> list[str]:
        return ["bake", scene, "-o", output or f"{name}/cache.usdc", "--no-progress", *extra]

    # --- files that are not USD stages
    f = folder("truncated_usdc")
    full = Sdf.Layer.FindOrOpen(str(SAMPLE))
    full.Export(str(f / "whole.usdc"))
    data = (f / "whole.usdc").read_bytes()
    (f / "whole.usdc").unlink()
    (f / "scene.usdc").write_bytes(data[: len(data) // 2])
    cases.append(Case("truncated_usdc", bake("truncated_usdc", "truncated_usdc/scene.usdc"),
                      ("scene.usdc", "cannot open as a USD stage")))
    f = folder("usdc_header_only")
    (f / "scene.usdc").write_bytes(data[:88])
    cases.append(Case("usdc_header_only", bake("usdc_header_only", "usdc_header_only/scene.usdc"),
                      ("scene.usdc",)))
    f = folder("garbage_usda")
    (f / "scene.usda").write_bytes(np.random.default_rng(1).integers(0, 256, 4096, dtype=np.uint8).tobytes())
    cases.append(Case("garbage_usda", bake("garbage_usda", "garbage_usda/scene.usda"),
                      ("scene.usda", "cannot open as a USD stage")))
    f = folder("garbage_usda_inspect")
    (f / "scene.usda").write_bytes(b"\x00\xff" * 100)
    cases.append(Case("garbage_usda_inspect", ["inspect", "garbage_usda_inspect/scene.usda"], ("scene.usda",)))
    f = folder("empty_usda")
    (f / "scene.usda").write_bytes(b"")
    cases.append(Case("empty_usda", bake("empty_usda", "empty_usda/scene.usda"), ("scene.usda",)))
    f = folder("directory_as_scene")
    (f / "scene.usda").mkdir()
    cases.append(Case("directory_as_scene", bake("directory_as_scene", "directory_as_scene/scene.usda"),
                      ("scene.usda", "is a folder")))
    f = folder("symlink_loop_scene")
    os.symlink("other.usda", f / "scene.usda")
    os.symlink("scene.usda", f / "other.usda")
    cases.append(Case("symlink_loop_scene", bake("symlink_loop_scene", "symlink_loop_scene/scene.usda"),
                      ("scene.usda", "symbolic link loop")))
    f = folder("broken_symlink_scene")
    os.symlink("gone.usda", f / "scene.usda")
    cases.append(Case("broken_symlink_scene", bake("broken_symlink_scene", "broken_symlink_scene/scene.usda"),
                      ("scene.usda", "broken symbolic link", "gone.usda")))
    f = folder("non_utf8_usda")
    text = SAMPLE.read_bytes().replace(b'def Mesh "Tshirt"', b'def Mesh "T\xe9\xff\xfeshirt"', 1)
    (f / "scene.usda").write_bytes(text)
    cases.append(Case("non_utf8_usda", bake("non_utf8_usda", "non_utf8_usda/scene.usda"), ("scene.usda",)))
    f = folder("text_with_usdc_extension")
    shutil.copyfile(SAMPLE, f / "scene.usdc")
    cases.append(Case("text_with_usdc_extension",
                      bake("text_with_usdc_extension", "text_with_usdc_extension/scene.usdc"), ("scene.usdc",)))
    f = folder("unknown_scene_extension")
    shutil.copyfile(SAMPLE, f / "scene.txt")
    cases.append(Case("unknown_scene_extension",
                      bake("unknown_scene_extension", "unknown_scene_extension/scene.txt"), ("scene.txt",)))
    folder("missing_scene")
    cases.append(Case("missing_scene", bake("missing_scene", "missing_scene/scene.usda"),
                      ("missing_scene/scene.usda", "no such file")))
    folder("missing_scene_inspect")
    cases.append(Case("missing_scene_inspect", ["inspect", "missing_scene_inspect/nothing.usda"],
                      ("nothing.usda", "no such file")))

    # --- layers a stage composes that are missing or broken (USD only warns and drops them)
    def layered(name: str, sublayers: list[str], *, files: dict[str, bytes] | None = None,
                reference: str | None = None) -> None:
        f = folder(name)
        shutil.copyfile(SAMPLE, f / "base.usda")
        for rel, data in (files or {}).items():
            (f / rel).write_bytes(data)
        paths = ", ".join(f"@{p}@" for p in sublayers + ["base.usda"])
        body = f'def Xform "Extra" (references = @{reference}@</Extra>) {{}}\n' if reference else ""
        (f / "scene.usda").write_text(f"#usda 1.0\n(\n    subLayers = [{paths}]\n)\n{body}")

    layered("sublayer_missing", ["motion.usda"])
    cases.append(Case("sublayer_missing", bake("sublayer_missing", "sublayer_missing/scene.usda"),
                      ("scene.usda", "sublayer @motion.usda@", "does not exist")))
    layered("sublayer_empty_file", ["motion.usda"], files={"motion.usda": b""})
    cases.append(Case("sublayer_empty_file", bake("sublayer_empty_file", "sublayer_empty_file/scene.usda"),
                      ("scene.usda", "sublayer @motion.usda@", "cannot be opened")))
    layered("sublayer_missing_inspect", ["motion.usda"])
    cases.append(Case("sublayer_missing_inspect", ["inspect", "sublayer_missing_inspect/scene.usda"],
                      ("scene.usda", "@motion.usda@", "does not exist")))
    layered("reference_missing", [], reference="props.usda")
    cases.append(Case("reference_missing", bake("reference_missing", "reference_missing/scene.usda"),
                      ("scene.usda", "@props.usda@", "does not exist")))
    layered("nested_sublayer_missing", ["mid.usda"],
            files={"mid.usda": b"#usda 1.0\n(\n    subLayers = [@deep/anim.usda@]\n)\n"})
    cases.append(Case("nested_sublayer_missing",
                      bake("nested_sublayer_missing", "nested_sublayer_missing/scene.usda"),
                      ("scene.usda", "@deep/anim.usda@", "mid.usda", "does not exist")))

    # A NaN time-sample key, which USD's API will not author: written as text.
    f = folder("animation_nan_time_key")
    text = SAMPLE.read_text()
    first = text.index("rotations.timeSamples")
    first = text.index("1001:", first)
    (f / "scene.usda").write_text(text[:first] + "nan:" + text[first + len("1001:"):])
    cases.append(Case("animation_nan_time_key", bake("animation_nan_time_key", "animation_nan_time_key/scene.usda"),
                      ("scene.usda", SKEL, "Motion.rotations", "nan", "not a finite")))

    # --- stages that break the scene contract
    for name, (edit, expect) in STAGE_EDITS.items():
        _edited_stage(folder(name), edit)
        cases.append(Case(name, bake(name, f"{name}/scene.usda", "--shot", f"{name}/shot.usda"),
                          ("scene.usda", *expect)))
    # A later-tier request on the garment itself: the message names the prim but not the file
    # (baker._resolve_tier has no file name to give), so the file is not asked for here.
    name = "tier_detail_authored"
    _edited_stage(folder(name), _attr(SHIRT, "cloth:tier", Sdf.ValueTypeNames.Token, "detail", uniform=True))
    (root / name / "no_bundles").mkdir()  # a models folder without a T-shirt bundle
    cases.append(Case(name, bake(name, f"{name}/scene.usda", "--models", f"{name}/no_bundles"),
                      (f"{name}/scene.usda", SHIRT, "tier 'detail'", "model bundle")))

    # --- arguments
    def arg_case(name: str, extra: list[str], expect: tuple[str, ...], *, output: str | None = None) -> None:
        folder(name)
        cases.append(Case(name, bake(name, good, *extra, output=output), expect))

    arg_case("tier_unknown", ["--tier", "ultra"], ("--tier 'ultra'", "skinning, coarse, detail"))
    for tier in ("detail", "coarse"):  # with a models folder that holds no T-shirt bundle
        arg_case(f"tier_{tier}", ["--tier", tier, "--models", f"tier_{tier}/no_bundles"],
                 (SHIRT, f"tier '{tier}'", "model bundle"))
        (root / f"tier_{tier}" / "no_bundles").mkdir()
    arg_case("tier_empty", ["--tier", ""], ("--tier ''",))
    arg_case("frames_too_many", ["--frames", "1001:1000001000"],
             ("--frames 1001:1000001000", "GiB", "--chunk-frames"))
    arg_case("frames_negative_step_reason", ["--frames", "1001:1010:-2"],
             ("--frames '1001:1010:-2'", "STEP must be positive"))
    for label, text in (("words", "abc"), ("reversed", "1050:1001"), ("zero_step", "1001:1010:0"),
                        ("negative_step", "1001:1010:-1"), ("empty", ""), ("dots", "1.2.3:1005"),
                        ("exponent", "1e3:2e3"), ("three_colons", "1:2:3:4"), ("only_start", "1001")):
        arg_case(f"frames_{label}", ["--frames", text], (f"--frames '{text}'",))
    arg_case("garment_is_skeleton", ["--garment", SKEL], (f"--garment {SKEL}", "no garment", SHIRT))
    arg_case("garment_missing", ["--garment", "/Nope"], ("--garment /Nope", "no garment"))
    arg_case("output_folder_missing", [], ("no_such_dir", "does not exist"),
             output="output_folder_missing/no_such_dir/cache.usdc")
    arg_case("output_bad_extension", [], ("cache.abc", ".usdc, .usda or .usd"),
             output="output_bad_extension/cache.abc")
    arg_case("output_no_extension", [], ("cache", ".usdc, .usda or .usd"), output="output_no_extension/cache")
    arg_case("output_is_source", ["--force"], ("scene.usda", "source"), output=good)
    arg_case("shot_is_source", ["--force", "--shot", good], ("scene.usda", "source"))
    arg_case("shot_is_output", ["--force", "--shot", "shot_is_output/x.usda"], ("--shot", "same file"),
             output="shot_is_output/x.usda")
    arg_case("shot_is_output_dot_slash", ["--force", "--shot", "./shot_is_output_dot_slash/x.usda"],
             ("same file",), output="shot_is_output_dot_slash/x.usda")
    f = folder("shot_is_output_symlink")
    (f / "x.usda").write_bytes(b"#usda 1.0\n")
    os.symlink("x.usda", f / "link.usda")
    cases.append(Case("shot_is_output_symlink", bake("shot_is_output_symlink", good, "--force", "--shot",
                                                     "shot_is_output_symlink/link.usda",
                                                     output="shot_is_output_symlink/x.usda"), ("same file",)))
    arg_case("shot_bad_extension", ["--shot", "shot_bad_extension/shot.png"], ("shot.png", ".usdc, .usda or .usd"))
    f = folder("output_exists")
    (f / "cache.usdc").write_bytes(b"keep me")
    cases.append(Case("output_exists", bake("output_exists", good), ("cache.usdc", "--force")))
    f = folder("output_parent_is_a_file")
    (f / "file").write_bytes(b"not a folder")
    cases.append(Case("output_parent_is_a_file",
                      bake("output_parent_is_a_file", good, output="output_parent_is_a_file/file/cache.usdc"),
                      ("output_parent_is_a_file/file",)))
    f = folder("output_is_a_folder")
    (f / "cache.usdc").mkdir()
    cases.append(Case("output_is_a_folder", bake("output_is_a_folder", good, "--force"), ("cache.usdc", "is a folder")))

    # --- model bundles whose files pass their sha256 check but are not what they say
    def bundle_case(name: str, expect: tuple[str, ...], *, files: dict[str, bytes] | None = None,
                    manifest: bytes | None = None, tier: str = "coarse") -> None:
        f = folder(name)
        shutil.copytree(BUNDLE, f / "models" / "tshirt-v3", ignore=shutil.ignore_patterns("report"))
        b = f / "models" / "tshirt-v3"
        data = json.loads((b / "manifest.json").read_text())
        for rel, content in (files or {}).items():
            (b / rel).write_bytes(content)
            data["files"][rel] = hashlib.sha256(content).hexdigest()
        (b / "manifest.json").write_text(json.dumps(data, indent=2))
        if manifest is not None:
            (b / "manifest.json").write_bytes(manifest)
        cases.append(Case(name, bake(name, good, "--tier", tier, "--models", f"{name}/models"), expect))

    onnx = (BUNDLE / "coarse.onnx").read_bytes()
    rng = np.random.default_rng(2)
    bundle_case("bundle_onnx_random_bytes", ("coarse.onnx", "not a loadable ONNX model"),
                files={"coarse.onnx": rng.integers(0, 256, 4096, dtype=np.uint8).tobytes()})
    bundle_case("bundle_onnx_truncated", ("coarse.onnx", "not a loadable ONNX model"),
                files={"coarse.onnx": onnx[: len(onnx) // 2]})
    bundle_case("bundle_detail_onnx_truncated", ("detail.onnx", "not a loadable ONNX model"), tier="detail",
                files={"detail.onnx": (BUNDLE / "detail.onnx").read_bytes()[:1000]})
    buf = f"{root}/_fit_wrong_shape.npz"
    with np.load(BUNDLE / "fit.npz") as d:
        np.savez(buf, **dict(d, loadings=d["loadings"][:, :, None]))
    bundle_case("bundle_fit_wrong_shape", ("fit.npz", "'loadings'", "shape"),
                files={"fit.npz": Path(buf).read_bytes()})
    Path(buf).unlink()
    bundle_case("bundle_fit_random_bytes", ("fit.npz", "not a fit model"),
                files={"fit.npz": rng.integers(0, 256, 2048, dtype=np.uint8).tobytes()})
    fit = (BUNDLE / "fit.npz").read_bytes()
    bundle_case("bundle_fit_truncated", ("fit.npz", "not a fit model"), files={"fit.npz": fit[: len(fit) // 2]})
    whole = (BUNDLE / "manifest.json").read_bytes()
    bundle_case("bundle_manifest_truncated", ("manifest.json", "unreadable manifest"),
                manifest=whole[: len(whole) // 2])

    # --- body model files
    f = folder("body_models")
    marker = (f / "PWNED").resolve()
    for name, (file, expect, _) in _body_files(f, marker).items():
        folder(name)
        cases.append(Case(name, bake(name, good, "--body-model", f"body_models/{file}"), expect,
                          must_not_exist=("body_models/PWNED",)))

    names = [c.name for c in cases]
    assert len(names) == len(set(names)), "case names must be unique"
    return cases


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 1:
        sys.stderr.write("usage: make_corpus.py OUT_DIR\n")
        return 2
    cases = build_corpus(argv[0])
    for c in cases:
        sys.stdout.write(f"{c.name}: cloth-usd {' '.join(c.argv)}\n")
    sys.stdout.write(f"{len(cases)} cases in {argv[0]}\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
