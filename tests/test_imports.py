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
