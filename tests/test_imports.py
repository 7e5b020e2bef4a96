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
    assert "torch" not in _loaded_after("import cloth_usd.baker, cloth_usd.usd.write, cloth_usd.cli")
