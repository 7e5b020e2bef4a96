"""Build the Blender extension archive: ``dist/cloth_usd_blender-<version>.zip``.

    python scripts/build_addon.py                        # every platform, one archive
    python scripts/build_addon.py --platform linux-x64   # one platform, a smaller archive
    python scripts/build_addon.py --offline              # only use the wheels cache

The archive is the ``addon/`` package plus, in ``wheels/``, the runtime dependencies
that Blender does not ship, listed in the manifest's ``wheels`` so that Blender
installs them with the extension (Blender 4.2+ extension wheels):

- ``cloth_usd`` itself, built from this checkout (``pip wheel --no-deps .``);
- scipy (platform wheels), tqdm and threadpoolctl (pure Python), pinned below;
- onnxruntime (platform wheels) for the coarse and detail tiers: it imports with numpy
  alone, so its other requirements (protobuf, sympy, ...: model tooling) are left out.

Not bundled, because Blender has them: numpy (1.26.x in Blender 4.2 to 5.0) and
``pxr`` (Blender's own USD build; a second USD from usd-core in the same process would
clash with it). Downloaded wheels are kept in ``build/addon_wheels`` so later builds
work offline. See ``addon/README.md``.
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
import tomllib
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ADDON = ROOT / "addon"

#: Python of Blender 4.2 to 5.0; the platform wheels must match it.
BLENDER_PYTHON = "3.11"

#: Third-party runtime dependencies of cloth_usd that Blender lacks (cloth_usd's
#: pyproject asks scipy>=1.11, tqdm>=4.60, threadpoolctl>=3.1; scipy 1.17 needs numpy>=1.26.4 as
#: Blender has).
#: onnxruntime 1.22 is the newest with a wheel for every platform below (macOS as universal2).
BUNDLED = {"scipy": "1.17.1", "tqdm": "4.70.1", "threadpoolctl": "3.8.0", "onnxruntime": "1.22.0"}

#: Blender platform -> pip ``--platform`` tags to ask for, and the test a wheel's
#: platform tag must pass to serve that platform.
PLATFORMS = {
    "linux-x64": (["manylinux_2_28_x86_64", "manylinux_2_17_x86_64", "manylinux2014_x86_64"],
                  lambda tag: tag.startswith("manylinux") and tag.endswith("x86_64")),
    "windows-x64": (["win_amd64"], lambda tag: tag == "win_amd64"),
    "macos-arm64": (["macosx_14_0_arm64", "macosx_12_0_arm64", "macosx_11_0_arm64"],
                    lambda tag: tag.startswith("macosx") and tag.endswith(("arm64", "universal2"))),
    "macos-x64": (["macosx_10_14_x86_64", "macosx_14_0_x86_64"],
                  lambda tag: tag.startswith("macosx") and tag.endswith(("x86_64", "universal2"))),
}

_EXCLUDE = {"__pycache__", "docs", "README.md"}


def cloth_usd_version() -> str:
    text = (ROOT / "cloth_usd" / "_version.py").read_text(encoding="utf-8")
    return re.search(r'^__version__ = "([^"]+)"', text, re.MULTILINE).group(1)


def wheel_serves(wheel: Path, platform: str) -> bool:
    """Whether a wheel file installs on a Blender platform (pure wheels serve all)."""
    tags = wheel.stem.split("-")[-1].split(".")  # compressed tag sets: a.b.c
    return "any" in tags or any(PLATFORMS[platform][1](tag) for tag in tags)


def _preference(wheel: Path, platform: str) -> tuple[int, str]:
    """Sort key: wheels for the first-listed (oldest, most compatible) pip tag first."""
    tags = PLATFORMS[platform][0]
    return next((i for i, tag in enumerate(tags) if tag in wheel.name), len(tags)), wheel.name


#: The exit status when a pinned wheel is neither in the cache nor downloadable (offline):
#: the one build failure the add-on tests may skip on. Every other failure exits 1.
WHEELS_UNAVAILABLE = 3


def pip(*args: str, status: int = 1) -> None:
    """Run pip quietly; its output is shown only when it fails (exit ``status``)."""
    done = subprocess.run([sys.executable, "-m", "pip", *args], capture_output=True, text=True)
    if done.returncode:
        sys.stderr.write(f"{done.stdout}{done.stderr}build_addon: pip {' '.join(args)} failed\n")
        sys.exit(status)


def build_cloth_usd_wheel(out: Path) -> Path:
    """``pip wheel --no-deps .``; without build isolation when setuptools is here (offline)."""
    isolation = []
    try:
        import setuptools

        if int(setuptools.__version__.split(".")[0]) >= 77:
            isolation = ["--no-build-isolation"]
    except ImportError:
        pass
    pip("wheel", "--no-deps", *isolation, "-w", str(out), str(ROOT))
    return next(out.glob("cloth_usd-*.whl"))


def third_party_wheels(platforms: list[str], cache: Path, offline: bool) -> list[Path]:
    """The pinned wheels for every platform, from the cache or downloaded into it."""
    cache.mkdir(parents=True, exist_ok=True)
    chosen: set[Path] = set()
    for name, version in BUNDLED.items():
        for platform in platforms:
            found = [w for w in cache.glob(f"{name}-{version}-*.whl") if wheel_serves(w, platform)]
            if not found:
                if offline:
                    sys.stderr.write(f"build_addon: no {name}=={version} wheel for {platform} in {cache} "
                                     "(run once without --offline)\n")
                    sys.exit(WHEELS_UNAVAILABLE)
                tags = [a for tag in PLATFORMS[platform][0] for a in ("--platform", tag)]
                pip("download", "--no-deps", "--only-binary=:all:", "--implementation", "cp",
                    "--python-version", BLENDER_PYTHON, *tags, "-d", str(cache), f"{name}=={version}",
                    status=WHEELS_UNAVAILABLE)
                found = [w for w in cache.glob(f"{name}-{version}-*.whl") if wheel_serves(w, platform)]
            chosen.add(min(found, key=lambda w: _preference(w, platform)))
    return sorted(chosen)


def manifest(version: str, platforms: list[str], wheels: list[Path]) -> str:
    """The source manifest with the version set and ``platforms`` and ``wheels`` added."""
    text = (ADDON / "blender_manifest.toml").read_text(encoding="utf-8")
    text = re.sub(r'^version = ".*"$', f'version = "{version}"', text, count=1, flags=re.MULTILINE)
    quoted = ", ".join(f'"{p}"' for p in platforms)
    listing = (f"platforms = [{quoted}]\n"
               "wheels = [\n" + "".join(f'  "./wheels/{w.name}",\n' for w in wheels) + "]\n\n")
    first_table = re.search(r"^\[", text, re.MULTILINE).start()  # top-level keys go before tables
    text = text[:first_table] + listing + text[first_table:]
    parsed = tomllib.loads(text)
    assert parsed["version"] == version and len(parsed["wheels"]) == len(wheels)
    return text


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--platform", action="append", choices=sorted(PLATFORMS),
                        help="platform to bundle wheels for (repeatable; default: all)")
    parser.add_argument("--out", type=Path, default=ROOT / "dist", help="output folder (default: dist)")
    parser.add_argument("--wheels-cache", type=Path, default=ROOT / "build" / "addon_wheels",
                        help="downloaded wheels are kept here (default: build/addon_wheels)")
    parser.add_argument("--offline", action="store_true", help="never download; use the cache only")
    args = parser.parse_args(argv)
    platforms = args.platform or list(PLATFORMS)
    version = cloth_usd_version()
    name = f"cloth_usd_blender-{version}" + ("" if len(platforms) == len(PLATFORMS) else
                                             "-" + "-".join(p.replace("-", "_") for p in platforms))
    args.out.mkdir(parents=True, exist_ok=True)
    archive = args.out / f"{name}.zip"
    with tempfile.TemporaryDirectory() as tmp:
        wheels = [build_cloth_usd_wheel(Path(tmp)), *third_party_wheels(platforms, args.wheels_cache,
                                                                         args.offline)]
        with zipfile.ZipFile(archive, "w", zipfile.ZIP_DEFLATED) as zf:
            zf.writestr("blender_manifest.toml", manifest(version, platforms, wheels))
            for path in sorted(ADDON.rglob("*")):
                rel = path.relative_to(ADDON)
                if path.is_file() and path.name != "blender_manifest.toml" and not _EXCLUDE & set(rel.parts):
                    zf.write(path, rel.as_posix())
            for wheel in wheels:
                zf.write(wheel, f"wheels/{wheel.name}", compress_type=zipfile.ZIP_STORED)
    print(f"{archive} ({archive.stat().st_size / 1e6:.1f} MB; platforms {', '.join(platforms)}; "
          f"wheels {', '.join(w.name for w in wheels)})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
