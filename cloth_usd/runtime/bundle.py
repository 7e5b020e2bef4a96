"""Model bundles: the exported models of one garment category, with a hashed manifest.

A bundle is a folder::

    <bundle>/manifest.json   format_version, name, category, tiers, opset, files {name: sha256},
                             models {tier: {file, inputs, outputs, config}; coarse also
                             base: body | skinned}, fit {file, ...},
                             training_data {manifest_sha256, description, and optionally
                             poses and bodies: the joint angles and shapes trained on},
                             metrics {...}
    <bundle>/coarse.onnx     the coarse generator (inputs: runtime.io.COARSE_INPUTS)
    <bundle>/detail.onnx     the detail generator with its parser (optional)
    <bundle>/fit.npz         the fit attribute's factor-analysis model (FitModel.save)

A garment's own bundle (``cloth-usd train-garment``, :mod:`cloth_usd.nn.garment_model`) adds
``garment {vertices, faces_sha256}`` to the manifest: its models take ``pose`` and ``betas``
(runtime.io.GARMENT_INPUTS) and serve that garment's triangles alone.

:func:`load_bundle` checks every listed file's sha256 before anything is used; the
bundle's identity (recorded in every cache it bakes) is its name and the sha256 of its
``manifest.json``, which in turn pins every file. Sessions are made lazily, once per
bundle and tier.
"""

from __future__ import annotations

import hashlib
import json
import logging
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Mapping

import numpy as np

from ..core.files import file_sha256, models_dir
from ..core.fit import FitModel
from ..core.garment_inputs import faces_sha256
from ..core.heading import Heading
from ..core.limits import betas_range_from_record, pose_range_from_record
from ..core.pipeline import CoarseBase, CoarseFeatures, CoarseForm
from ..core.scene import Category, Tier
from ..errors import ArgumentError, BundleError, ClothUsdError
from .io import COARSE_INPUTS, DETAIL_INPUTS, GARMENT_INPUTS, OUTPUT
from .session import ModelSession

__all__ = ["FORMAT_VERSION", "MANIFEST", "DEFAULTS", "SPINNING_TIERS", "GarmentIdentity", "ModelBundle", "load_bundle",
           "find_bundle", "write_bundle", "default_bundle_dir"]

log = logging.getLogger(__name__)

#: The manifest layout this runtime reads.
FORMAT_VERSION = 1
#: The manifest's file name inside a bundle folder.
MANIFEST = "manifest.json"
_INPUTS = {Tier.COARSE: COARSE_INPUTS, Tier.DETAIL: DETAIL_INPUTS}
#: The tiers whose onnxruntime threads spin for more work after a run (:class:`ModelSession`'s
#: ``spin``). The detail tier's run is followed by the post-process's strain limit and push on the
#: CPU, and its threads spinning beside them slowed the tier: on two cores with two threads (the
#: detail session spinning and not, alternated eight times in one process, the coarse one spinning)
#: `tshirt-v6` on a 4041-vertex shirt took a median 44.1 ms a frame spinning and 42.0 not,
#: `sample-tshirt-own` on its shirt 15.5 and 14.2. The coarse tier lost by not spinning (15.5 against
#: 16.1 ms, alternated three times), its model's many small steps waiting for the threads to wake.
SPINNING_TIERS = (Tier.COARSE,)


@dataclass(frozen=True)
class GarmentIdentity:
    """The one garment a garment's own bundle serves (the manifest's ``garment``)."""

    vertices: int
    """N."""
    faces_sha256: str
    """sha256 of its (M, 3) triangles as int64 (:func:`cloth_usd.core.garment_inputs.faces_sha256`)."""

    def serves(self, num_vertices: int, faces: np.ndarray) -> bool:
        """Whether a garment of ``num_vertices`` vertices and these (M, 3) triangles is this one."""
        return int(num_vertices) == self.vertices and faces_sha256(faces) == self.faces_sha256

    def to_json(self) -> dict:
        return {"vertices": int(self.vertices), "faces_sha256": str(self.faces_sha256)}
_FILES = {Tier.COARSE: "coarse.onnx", Tier.DETAIL: "detail.onnx"}
_FIT = "fit.npz"
_REST = "rest.npz"


def default_bundle_dir() -> Path:
    """The shipped bundles: ``models/bundles`` (see :func:`cloth_usd.core.files.models_dir`)."""
    return models_dir() / "bundles"


@dataclass(eq=False)
class ModelBundle:
    """A verified model bundle; sessions are loaded on first use and kept."""

    path: Path
    """The bundle folder."""
    name: str
    category: Category
    tiers: tuple[Tier, ...]
    """Learned tiers the bundle can run (coarse, and detail when it ships detail.onnx)."""
    sha256: str
    """sha256 of ``manifest.json``: the bundle's identity."""
    manifest: Mapping[str, Any]
    """The parsed manifest."""
    fit: FitModel
    """The fit attribute's factor-analysis model."""
    form: CoarseForm = CoarseForm()
    """How the models were trained, so how they are run: the manifest's ``models.coarse.base``
    (what the coarse displacement is added to; bundles without the field: ``body``,
    docs/method.md's), ``models.coarse.heading`` (the frame the models see the body in;
    without it ``world``, as tshirt-v1..v3 were trained) and ``models.coarse.features`` (the
    coarse model's node features; without it ``body``, as tshirt-v1..v5 were trained)."""
    pose_limits: np.ndarray | None = None
    """(J, 3, 2) [rad] the range of joint angles the models were trained on (the manifest's
    ``training_data.poses``, :func:`~cloth_usd.core.limits.pose_range_record`); None for a
    bundle that records none (then :data:`~cloth_usd.core.limits.JOINT_LIMITS`, the range of
    the procedural training motions, stands in)."""
    betas_limits: np.ndarray | None = None
    """(B, 2) the range of shape coefficients of the bodies the models were trained on (the
    manifest's ``training_data.bodies``, :func:`~cloth_usd.core.limits.betas_range_record`);
    None for a bundle that records none (then ``|beta| <= BETA_LIMIT`` stands in)."""
    garment: GarmentIdentity | None = None
    """The one garment a garment's own bundle serves (its models take the pose and the shape,
    :data:`~cloth_usd.runtime.io.GARMENT_INPUTS`); None: a category's bundle (any topology)."""
    detail_adds_coarse: bool = False
    """True when the detail file's output is added to the coarse file's (the manifest's
    ``models.detail.adds`` is ``coarse``; a garment's own bundle); False: it is the whole."""
    garment_rest: tuple[np.ndarray, np.ndarray] | None = None
    """A garment's own bundle: ``(rest points (N, 3) [m], canonical body frame, betas (10,))``, the
    garment on its own body as it was trained (the manifest's ``garment.rest`` file); None when
    the bundle records none (a category's bundle, or one exported before it was recorded)."""
    _sessions: dict = field(default_factory=dict, repr=False)

    def trained_rest(self, betas: np.ndarray) -> np.ndarray | None:
        """(N, 3) the rest garment this garment's own bundle was trained on, when ``betas`` is
        the body it was trained on (equal to 1e-5, a missing coefficient zero); None for another
        body, or when the bundle records no rest (:attr:`garment_rest`)."""
        if self.garment_rest is None:
            return None
        rest, trained = self.garment_rest
        betas = np.asarray(betas, dtype=np.float64).ravel()
        n = max(len(betas), len(trained))
        same = np.allclose(np.pad(betas, (0, n - len(betas))), np.pad(trained, (0, n - len(trained))), atol=1e-5)
        return rest if same else None

    def model_path(self, tier: Tier) -> Path:
        """The ONNX file of ``tier``."""
        return self.path / self.manifest["models"][tier.value]["file"]

    def session(self, tier: Tier | str, *, prefer_gpu: bool = True) -> ModelSession:
        """The (cached) onnxruntime session of ``tier`` (its threads spinning after a run only for
        :data:`SPINNING_TIERS`); raises BundleError if not shipped."""
        tier = Tier(tier)
        if tier not in self.tiers:
            raise BundleError(f"{self.path}: bundle '{self.name}' has no '{tier.value}' model "
                              f"(tiers: {', '.join(t.value for t in self.tiers)})")
        if tier not in self._sessions:
            path = self.model_path(tier)
            try:
                session = ModelSession(path, prefer_gpu=prefer_gpu, spin=tier in SPINNING_TIERS)
            except ClothUsdError:
                raise
            except Exception as exc:  # onnxruntime's errors (InvalidProtobuf, Fail, ...) derive from Exception only
                reason = " ".join(str(exc).split())[:300]
                raise BundleError(f"{self.path}: bundle file {path.name} is not a loadable ONNX model "
                                  f"({reason}); the bundle is corrupt, reinstall it") from exc
            expected = list(self.manifest["models"][tier.value].get("inputs", ()))
            if sorted(session.input_names) != sorted(expected):
                raise BundleError(f"{self.path}: bundle file {path.name} takes inputs "
                                  f"{list(session.input_names)}, but the manifest lists {expected}; "
                                  "the bundle is corrupt, reinstall it")
            self._sessions[tier] = session
        return self._sessions[tier]


#: The ranges a bundle may record of what it was trained on (``training_data.<key>``), and
#: how each is read.
_RECORDS = {"poses": pose_range_from_record, "bodies": betas_range_from_record}


def _training_records(training: Any) -> dict[str, np.ndarray]:
    """The ranges ``training_data`` records, read (:data:`_RECORDS`); raises ValueError naming
    the one that is broken."""
    found = {}
    for key, read in _RECORDS.items():
        if isinstance(training, Mapping) and key in training:
            try:
                found[key] = read(training[key])
            except ValueError as exc:
                raise ValueError(f"training_data.{key}: {exc}") from None
    return found


def _field(manifest: Mapping[str, Any], key: str, kind: type, where: Path) -> Any:
    if key not in manifest or not isinstance(manifest[key], kind):
        raise BundleError(f"{where}: manifest field '{key}' is missing or not a {kind.__name__}")
    return manifest[key]


def load_bundle(path: str | Path) -> ModelBundle:
    """Read and verify a bundle folder.

    Raises:
        BundleError: naming the folder and the file at fault, when the manifest is
            missing or malformed, its format_version or category is unknown, or a listed
            file is missing or fails its sha256 check.
    """
    folder = Path(path)
    mpath = folder / MANIFEST
    if not mpath.is_file():
        raise BundleError(f"{folder}: not a model bundle (no {MANIFEST})")
    try:
        raw = mpath.read_bytes()
        manifest = json.loads(raw)
    except (OSError, ValueError) as exc:
        raise BundleError(f"{mpath}: unreadable manifest ({exc})") from exc
    if not isinstance(manifest, dict):
        raise BundleError(f"{mpath}: the manifest is not a JSON object")
    version = manifest.get("format_version")
    if version != FORMAT_VERSION:
        raise BundleError(f"{mpath}: format_version {version!r} is not supported "
                          f"(this cloth-usd reads {FORMAT_VERSION}); update cloth-usd or the bundle")
    name = _field(manifest, "name", str, mpath)
    try:
        category = Category(_field(manifest, "category", str, mpath))
    except ValueError:
        valid = ", ".join(c.value for c in Category)
        raise BundleError(f"{mpath}: unknown category '{manifest['category']}' (valid: {valid})") from None
    files = _field(manifest, "files", dict, mpath)
    models = _field(manifest, "models", dict, mpath)
    try:
        tiers = tuple(Tier(t) for t in _field(manifest, "tiers", list, mpath))
    except ValueError:
        raise BundleError(f"{mpath}: unknown tier in {manifest['tiers']} (valid: coarse, detail)") from None
    if Tier.COARSE not in tiers or Tier.SKINNING in tiers:
        raise BundleError(f"{mpath}: 'tiers' must list coarse (and optionally detail), got {manifest['tiers']}")
    for tier in tiers:
        entry = models.get(tier.value)
        if not isinstance(entry, dict) or entry.get("file") not in files:
            raise BundleError(f"{mpath}: models.{tier.value} must name a file listed in 'files'")
        inputs = GARMENT_INPUTS if "garment" in manifest else _INPUTS[tier]
        if tuple(entry.get("inputs", ())) != inputs or list(entry.get("outputs", ())) != [OUTPUT]:
            raise BundleError(f"{mpath}: models.{tier.value} inputs/outputs {entry.get('inputs')} -> "
                              f"{entry.get('outputs')} do not match this runtime's "
                              f"{list(inputs)} -> ['{OUTPUT}']")
    base = models[Tier.COARSE.value].get("base", CoarseBase.BODY.value)
    if base not in {b.value for b in CoarseBase}:
        raise BundleError(f"{mpath}: models.coarse.base {base!r} is not one of "
                          f"{', '.join(b.value for b in CoarseBase)}")
    heading = models[Tier.COARSE.value].get("heading", Heading.WORLD.value)
    if heading not in {h.value for h in Heading}:
        raise BundleError(f"{mpath}: models.coarse.heading {heading!r} is not one of "
                          f"{', '.join(h.value for h in Heading)}")
    features = models[Tier.COARSE.value].get("features", CoarseFeatures.BODY.value)
    if features not in {f.value for f in CoarseFeatures}:
        raise BundleError(f"{mpath}: models.coarse.features {features!r} is not one of "
                          f"{', '.join(f.value for f in CoarseFeatures)} (a newer bundle? update cloth-usd)")
    adds = models.get(Tier.DETAIL.value, {}).get("adds") if Tier.DETAIL in tiers else None
    if adds not in (None, "coarse") or (adds is not None and "garment" not in manifest):
        raise BundleError(f"{mpath}: models.detail.adds {adds!r} is not understood (a garment's own bundle may "
                          "say 'coarse'; a newer bundle? update cloth-usd)")
    garment = None
    if "garment" in manifest:
        entry = manifest["garment"]
        if not (isinstance(entry, dict) and isinstance(entry.get("vertices"), int) and entry["vertices"] > 0
                and isinstance(entry.get("faces_sha256"), str)):
            raise BundleError(f"{mpath}: manifest field 'garment' must be {{vertices: int > 0, faces_sha256: str}}")
        garment = GarmentIdentity(entry["vertices"], entry["faces_sha256"])
        if entry.get("rest") is not None and entry["rest"] not in files:
            raise BundleError(f"{mpath}: garment.rest must name a file listed in 'files'")
    try:
        records = _training_records(manifest.get("training_data"))
    except ValueError as exc:
        raise BundleError(f"{mpath}: {exc}") from None
    fit_file = _field(manifest, "fit", dict, mpath).get("file")
    if fit_file not in files:
        raise BundleError(f"{mpath}: fit.file must name a file listed in 'files'")
    for rel, digest in files.items():
        f = folder / rel
        if Path(rel).is_absolute() or ".." in Path(rel).parts:
            raise BundleError(f"{mpath}: file '{rel}' must be a plain relative name inside the bundle")
        if not f.is_file():
            raise BundleError(f"{folder}: bundle file {rel} is missing")
        got = file_sha256(f)
        if got != digest:
            raise BundleError(f"{folder}: bundle file {rel} fails its sha256 check (manifest "
                              f"{str(digest)[:12]}..., file {got[:12]}...); the bundle is corrupt or "
                              "was edited, reinstall it")
    try:
        fit = FitModel.load(folder / fit_file)
    except (OSError, ValueError) as exc:
        raise BundleError(f"{folder}: bundle file {fit_file} is not a fit model ({exc})") from exc
    rest = None
    if garment is not None and manifest["garment"].get("rest") is not None:
        rest_file = manifest["garment"]["rest"]
        try:
            with np.load(folder / rest_file, allow_pickle=False) as z:
                rest = (np.asarray(z["vertices"], dtype=np.float64), np.asarray(z["betas"], dtype=np.float64))
        except (OSError, KeyError, ValueError) as exc:
            raise BundleError(f"{folder}: bundle file {rest_file} is not a garment rest ({exc})") from exc
        if rest[0].shape != (garment.vertices, 3):
            raise BundleError(f"{folder}: bundle file {rest_file} holds {rest[0].shape} points, the garment has "
                              f"{garment.vertices}")
    return ModelBundle(path=folder, name=name, category=category, tiers=tiers,
                       sha256=hashlib.sha256(raw).hexdigest(), manifest=manifest, fit=fit,
                       form=CoarseForm(base, heading, features), pose_limits=records.get("poses"),
                       betas_limits=records.get("bodies"), garment=garment, detail_adds_coarse=adds == "coarse",
                       garment_rest=rest)


#: In a folder of bundles: ``{"<category>": "<bundle folder>"}``, the bundle tried first for a
#: category (the default); the others follow in name order.
DEFAULTS = "defaults.json"


def _candidates(folder: Path, category: Category, worn: tuple[int, np.ndarray] | None = None) -> list[Path]:
    """The bundle folders to try, in order: ``folder`` itself when it is a bundle; else the
    garment's own bundles that serve ``worn`` ((vertex count, (M, 3) triangles); in name
    order), then the category's bundles (the :data:`DEFAULTS` one first, then name order), a
    garment's own bundle among them only when it serves ``worn``."""
    if (folder / MANIFEST).is_file():
        return [folder]
    found = sorted(p for p in folder.iterdir() if (p / MANIFEST).is_file())
    identities = {p: _identity_of(p) for p in found}
    serving = [p for p in found if identities[p] is not None and worn is not None and identities[p].serves(*worn)]
    found = [p for p in found if identities[p] is None]
    defaults = folder / DEFAULTS
    if defaults.is_file():
        try:
            chosen = json.loads(defaults.read_bytes()).get(category.value)
        except (OSError, ValueError, AttributeError) as exc:
            raise BundleError(f"{defaults}: unreadable ({exc}); expected {{\"<category>\": \"<bundle folder>\"}}") from exc
        if chosen is not None:
            first = folder / str(chosen)
            if first not in identities:
                raise BundleError(f"{defaults}: the default {category.value} bundle {chosen!r} is not a bundle folder "
                                  f"in {folder}")
            if first in found:
                found = [first] + [p for p in found if p != first]
    return serving + found


def _identity_of(bundle: Path) -> GarmentIdentity | None:
    """The garment a garment's own bundle serves, from its manifest; None for a category's
    bundle or a manifest that is not readable (:func:`_category_of` names that one)."""
    try:
        entry = json.loads((bundle / MANIFEST).read_bytes()).get("garment")
        return GarmentIdentity(int(entry["vertices"]), str(entry["faces_sha256"])) if entry is not None else None
    except (OSError, ValueError, AttributeError, KeyError, TypeError):
        return None


def _category_of(bundle: Path) -> str | None:
    """The manifest's category; None when it names none. Raises BundleError when the
    manifest is not readable JSON (a truncated copy), naming the file."""
    mpath = bundle / MANIFEST
    try:
        manifest = json.loads(mpath.read_bytes())
    except (OSError, ValueError) as exc:
        raise BundleError(f"{mpath}: unreadable manifest ({exc}); the bundle is corrupt, reinstall it") from exc
    return manifest.get("category") if isinstance(manifest, dict) else None


def find_bundle(category: Category | str, search_dirs: Iterable[str | Path] | None = None, *,
                worn: tuple[int, np.ndarray] | None = None) -> ModelBundle | None:
    """The first bundle for ``category`` in the search folders, verified; None if there is none.

    Args:
        category: garment category.
        search_dirs: folders that are bundles or hold bundle folders (``--models DIR``);
            None for :func:`default_bundle_dir`. In a folder, a garment's own bundle that
            serves ``worn`` is tried first, then the bundle its :data:`DEFAULTS` file names
            for the category, then the others in name order (a garment's own bundle only
            for the garment it serves). A folder that is a bundle is that bundle.
        worn: (vertex count, (M, 3) triangles) of the garment to bake; None: the
            category's bundles alone.
    Raises:
        ArgumentError: a given search folder does not exist.
        BundleError: the matching bundle fails verification, or none matches and a
            candidate's manifest is unreadable (it may be the one wanted).
    """
    category = Category(category)
    given = search_dirs is not None
    dirs = [Path(d) for d in search_dirs] if given else [default_bundle_dir()]
    broken: list[BundleError] = []
    for d in dirs:
        if not d.is_dir():
            if given:
                raise ArgumentError(f"--models {d}: no such folder")
            continue
        for candidate in _candidates(d, category, worn):
            try:
                found = _category_of(candidate)
            except BundleError as exc:  # it may be another category's: an error only if none is found
                broken.append(exc)
                continue
            if found == category.value:
                bundle = load_bundle(candidate)
                log.info("model bundle %s (%s) for %s", bundle.name, bundle.path, category.value)
                return bundle
    if broken:
        raise BundleError(f"no readable model bundle for category '{category.value}': {broken[0]}")
    return None


def write_bundle(out_dir: str | Path, *, name: str, category: Category | str, coarse_onnx: str | Path,
                 detail_onnx: str | Path | None, fit_npz: str | Path, configs: Mapping[str, Any],
                 training_data: Mapping[str, Any], metrics: Mapping[str, Any], opset: int,
                 force: bool = False, form: CoarseForm = CoarseForm(),
                 garment: GarmentIdentity | None = None, detail_adds_coarse: bool = False,
                 garment_rest: tuple[np.ndarray, np.ndarray] | None = None) -> Path:
    """Copy exported models and the fit model into a new bundle folder and write its manifest.

    Args:
        out_dir: the bundle folder to create (must not exist, or be empty, unless ``force``).
        name: the bundle's name (recorded in every cache it bakes).
        category: garment category.
        coarse_onnx, detail_onnx: exported generators (detail optional).
        fit_npz: a :meth:`FitModel.save` file.
        configs: ``{"coarse": {...}, "detail": {...}}`` the models' configs (JSON-able).
        training_data: ``{"manifest_sha256": ..., "description": ...}``, and ``"poses"`` and
            ``"bodies"``: the training poses' :func:`~cloth_usd.core.limits.pose_range_record`
            and bodies' :func:`~cloth_usd.core.limits.betas_range_record`, checked here.
        metrics: validation metrics (JSON-able), e.g. mean vertex error [mm].
        opset: the ONNX opset of the exported files.
        form: how the models were trained (base, heading, coarse features), recorded in
            ``models.coarse``.
        garment: the one garment a garment's own models serve (their inputs are then
            :data:`~cloth_usd.runtime.io.GARMENT_INPUTS`); None: a category's models.
        detail_adds_coarse: the detail file's output is added to the coarse file's (a
            garment's own bundle only; ``models.detail.adds``).
        garment_rest: a garment's own bundle: (rest points (N, 3), betas (10,)), the garment on
            its own body as trained, written as ``rest.npz`` (``garment.rest``).
    Returns:
        The bundle folder.
    """
    out = Path(out_dir)
    try:
        category = Category(category)
    except ValueError:
        valid = ", ".join(c.value for c in Category)
        raise ArgumentError(f"category '{category}': unknown (valid: {valid})") from None
    if out.exists() and any(out.iterdir()) and not force:
        raise ArgumentError(f"{out}: exists and is not empty (pass force to replace its files)")
    sources = {Tier.COARSE: coarse_onnx, Tier.DETAIL: detail_onnx}
    for tier, src in sources.items():
        if src is not None and not Path(src).is_file():
            raise ArgumentError(f"{src}: {tier.value} model file not found")
    if not Path(fit_npz).is_file():
        raise ArgumentError(f"{fit_npz}: fit model file not found")
    if garment_rest is not None and garment is None:
        raise ArgumentError("garment_rest: only a garment's own bundle records its rest garment")
    if detail_adds_coarse and (garment is None or detail_onnx is None):
        raise ArgumentError("detail_adds_coarse: only a garment's own bundle with a detail model adds its coarse one")
    try:
        _training_records(training_data)
    except ValueError as exc:
        raise ArgumentError(str(exc)) from None
    fit = FitModel.load(fit_npz)
    out.mkdir(parents=True, exist_ok=True)
    files: dict[str, str] = {}
    models: dict[str, Any] = {}
    tiers = []
    for tier, src in sources.items():
        if src is None:
            continue
        shutil.copyfile(src, out / _FILES[tier])
        files[_FILES[tier]] = file_sha256(out / _FILES[tier])
        inputs = GARMENT_INPUTS if garment is not None else _INPUTS[tier]
        models[tier.value] = {"file": _FILES[tier], "inputs": list(inputs), "outputs": [OUTPUT],
                              "config": dict(configs.get(tier.value, {}))}
        if tier is Tier.COARSE:
            models[tier.value].update(base=form.base.value, heading=form.heading.value,
                                      features=form.features.value)
        elif detail_adds_coarse:
            models[tier.value]["adds"] = Tier.COARSE.value
        tiers.append(tier.value)
    shutil.copyfile(fit_npz, out / _FIT)
    files[_FIT] = file_sha256(out / _FIT)
    manifest = {
        "format_version": FORMAT_VERSION,
        "name": name,
        "category": category.value,
        "tiers": tiers,
        "opset": int(opset),
        "files": files,
        "models": models,
        "fit": {"file": _FIT, "anchors": int(fit.anchors.shape[0]), "factors": int(fit.loadings.shape[1])},
        "training_data": dict(training_data),
        "metrics": dict(metrics),
    }
    if garment is not None:
        manifest["garment"] = garment.to_json()
    if garment_rest is not None:
        np.savez(out / _REST, vertices=np.asarray(garment_rest[0], dtype=np.float64),
                 betas=np.asarray(garment_rest[1], dtype=np.float64))
        files[_REST] = file_sha256(out / _REST)
        manifest["garment"]["rest"] = _REST
    (out / MANIFEST).write_text(json.dumps(manifest, indent=2, sort_keys=True) + "\n")
    return out
