import subprocess
import sys


def _loaded_after(statement: str) -> set[str]:
    code = (f"import sys; {statement}; "
            "print(','.join(m for m in ('pxr', 'torch', 'onnxruntime', 'bpy', 'smplx') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return set(filter(None, out.stdout.strip().split(",")))


def test_core_imports_no_heavy_backend():
    assert _loaded_after("import cloth_usd.core") == set()


def test_package_import_is_cheap():
    assert _loaded_after("import cloth_usd") == set()


def test_bake_path_needs_no_torch():
    assert "torch" not in _loaded_after("import cloth_usd.baking, cloth_usd.batch, cloth_usd.usd.write, cloth_usd.cli")


#: Modules outside cloth_usd/usd that import pxr (none: keep it so).
_PXR_OUTSIDE_USD: set[str] = set()


def test_only_the_usd_package_imports_pxr():
    """pxr is imported (at module level or in a function) only under cloth_usd/usd/."""
    import ast
    from pathlib import Path

    import cloth_usd

    root = Path(cloth_usd.__file__).parent
    found = set()
    for path in root.rglob("*.py"):
        rel = path.relative_to(root)
        if rel.parts[0] == "usd":
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                     else [node.module or ""] if isinstance(node, ast.ImportFrom) and node.level == 0 else [])
            if any(n == "pxr" or n.startswith("pxr.") for n in names):
                found.add(rel.as_posix())
    assert found == _PXR_OUTSIDE_USD, f"pxr imported outside cloth_usd/usd: {sorted(found - _PXR_OUTSIDE_USD)}"


#: Packages the README's first command (``scripts/setup.sh``: the ``runtime`` and ``preview``
#: extras) does not install: the bake must not import any of them, at module level or on its way.
_NOT_INSTALLED_FOR_BAKING = ("trimesh", "newton", "warp", "torch", "smplx", "sklearn", "fast_simplification",
                             "ray", "onnx")


def _cli_without(blocked: tuple[str, ...], *args: str) -> subprocess.CompletedProcess:
    """Run the CLI in a fresh interpreter where importing any of ``blocked`` fails."""
    code = ("import sys\n"
            "class Blocked:  # importing one of them raises ModuleNotFoundError, as if not installed\n"
            "    def find_spec(self, name, path=None, target=None):\n"
            f"        if name.split('.')[0] in {blocked!r}:\n"
            "            raise ModuleNotFoundError(f'No module named {name!r}', name=name)\n"
            "sys.meta_path.insert(0, Blocked())\n"
            "from cloth_usd.cli import main\n"
            f"raise SystemExit(main({list(args)!r}))\n")
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)


def test_the_first_command_bakes_the_sample_without_the_training_and_simulation_extras(tmp_path):
    """The CLI once imported the garment maker (and with it trimesh) for every command: the
    README's first command failed in the environment it makes."""
    from pathlib import Path

    sample = Path(__file__).resolve().parents[1] / "samples" / "walk_tshirt" / "scene.usda"
    done = _cli_without(_NOT_INSTALLED_FOR_BAKING, "bake", str(sample), "-o", str(tmp_path / "c.usdc"),
                        "--frames", "1001:1004", "--tier", "detail", "--no-progress")
    assert done.returncode == 0, done.stderr[-3000:]
    assert (tmp_path / "c.usdc").is_file()


def test_render_without_matplotlib_is_one_line_naming_the_extra(tmp_path):
    from pathlib import Path

    sample = Path(__file__).resolve().parents[1] / "samples" / "walk_tshirt" / "scene.usda"
    done = _cli_without(("matplotlib",), "render", str(sample), "-o", str(tmp_path / "r.png"), "--frames", "1001")
    assert done.returncode == 2 and not (tmp_path / "r.png").exists()
    (line,) = done.stderr.strip().splitlines()
    assert "cloth-usd render draws with matplotlib" in line and "pip install 'cloth-usd[preview]'" in line


def test_a_command_without_its_extra_is_one_line_naming_it(tmp_path):
    from pathlib import Path

    config = Path(__file__).resolve().parents[1] / "configs" / "physics_tshirt_mocap.json"
    done = _cli_without(("torch",), "train", "coarse", "--objective", "physics", "--data", str(config),
                        "-o", str(tmp_path / "run"))
    assert done.returncode == 2, done.stderr[-2000:]
    (line,) = done.stderr.strip().splitlines()
    assert line.startswith("cloth-usd: error: cloth-usd train needs torch, which is not installed: "
                           "pip install 'cloth-usd[train]'"), line
