"""The export package keeps to the layers: importing it pulls in no pxr (the USD reading
is imported when a conversion runs), torch or onnxruntime."""

from __future__ import annotations

import subprocess
import sys


def test_export_imports_no_heavy_backend():
    code = ("import sys, cloth_usd.export, cloth_usd.export.preview; "
            "print(','.join(m for m in ('pxr', 'torch', 'onnxruntime', 'OpenEXR') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""
