"""Read an official SMPL ``.pkl`` without executing pickle code or importing chumpy.

The official files are Python 2 pickles holding numpy arrays, a ``scipy.sparse``
CSC matrix (``J_regressor``) and chumpy ``Ch`` objects (``shapedirs``, sometimes
``v_template``). :class:`RestrictedUnpickler` resolves only a fixed allow-list of
globals; chumpy and scipy classes are replaced by inert records of their state, which
:func:`load_smpl_pickle` turns into plain arrays. Anything else in the stream (``os.system``,
``builtins.eval``, ...) is refused before it can run.
"""

from __future__ import annotations

import codecs
import copyreg
import pickle
from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse

from ..errors import BodyModelError

__all__ = ["load_smpl_pickle", "RestrictedUnpickler"]


class _Record:
    """Inert stand-in for an allowed foreign class: it only keeps its pickled state."""

    kind = "record"

    def __setstate__(self, state: Any) -> None:
        self.state = state


class _ChumpyRecord(_Record):
    kind = "chumpy"


class _SparseRecord(_Record):
    kind = "sparse"


# numpy's own reconstruct helpers, taken from its reduce protocol so that neither the
# deprecated ``numpy.core`` nor the private ``numpy._core`` path has to be imported.
_RECONSTRUCT = np.ndarray.__reduce__(np.zeros(1))[0]
_SCALAR = np.float64(0).__reduce__()[0]
_ALLOWED = {
    ("numpy.core.multiarray", "_reconstruct"): _RECONSTRUCT,
    ("numpy._core.multiarray", "_reconstruct"): _RECONSTRUCT,
    ("numpy.core.multiarray", "scalar"): _SCALAR,
    ("numpy._core.multiarray", "scalar"): _SCALAR,
    ("numpy", "ndarray"): np.ndarray,
    ("numpy", "dtype"): np.dtype,
    ("copy_reg", "_reconstructor"): copyreg._reconstructor,
    ("copyreg", "_reconstructor"): copyreg._reconstructor,
    ("__builtin__", "object"): object,
    ("builtins", "object"): object,
    ("__builtin__", "set"): set,
    ("builtins", "set"): set,
    ("_codecs", "encode"): codecs.encode,  # protocol-2 pickles written by Python 3 encode bytes so
}


class RestrictedUnpickler(pickle.Unpickler):
    """An unpickler that knows numpy arrays, chumpy ``Ch`` and scipy CSC/CSR records only."""

    def find_class(self, module: str, name: str) -> Any:
        if (module, name) in _ALLOWED:
            return _ALLOWED[(module, name)]
        if module.split(".")[0] == "chumpy":
            return _ChumpyRecord
        if module.startswith("scipy.sparse") and name in ("csc_matrix", "csr_matrix"):
            return _SparseRecord
        raise pickle.UnpicklingError(f"global '{module}.{name}' is not allowed in a body model file")


def _to_array(value: Any, key: str, path: Path) -> Any:
    """Turn records into arrays; leave arrays, strings and numbers as they are."""
    if isinstance(value, _ChumpyRecord):
        state = value.state if isinstance(value.state, dict) else {}
        if "x" not in state:
            raise BodyModelError(f"{path}: key '{key}' is a chumpy object without an 'x' array")
        return np.asarray(state["x"])
    if isinstance(value, _SparseRecord):
        s = value.state
        try:
            shape = tuple(s.get("_shape") or s.get("shape"))
            cls = scipy.sparse.csc_matrix if "indptr" in s and len(s["indptr"]) == shape[1] + 1 \
                else scipy.sparse.csr_matrix
            return cls((s["data"], s["indices"], s["indptr"]), shape=shape).toarray()
        except (KeyError, TypeError, ValueError) as exc:
            raise BodyModelError(f"{path}: key '{key}' is a malformed sparse matrix ({exc})") from exc
    return value


def load_smpl_pickle(path: str | Path) -> dict[str, Any]:
    """Load an official SMPL ``.pkl`` into a dict of numpy arrays, running no pickle code.

    Raises :class:`BodyModelError` naming the file when it is unreadable, not a pickle,
    or holds anything outside the allow-list.
    """
    path = Path(path)
    try:
        with path.open("rb") as fh:
            data = RestrictedUnpickler(fh, encoding="latin1").load()
    except OSError as exc:
        raise BodyModelError(f"{path}: cannot read body model file ({exc.strerror})") from exc
    except (pickle.UnpicklingError, EOFError, AttributeError, ValueError, TypeError,
            IndexError, ImportError) as exc:
        raise BodyModelError(f"{path}: not a loadable SMPL pickle ({exc})") from exc
    if not isinstance(data, dict):
        raise BodyModelError(f"{path}: expected a dict of SMPL arrays, found {type(data).__name__}")
    return {str(k): _to_array(v, str(k), path) for k, v in data.items()}
