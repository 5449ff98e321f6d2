"""The compiled kernels' cache is keyed by the kernels' source, not by where a copy of it lies:
a clone and an installed copy share it, and an edit of any kernel module starts a fresh one."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import pytest
from helpers import REPO

# A small kernel (the generator's next number), then how numba's cache served it.
_SCRIPT = """
import json
import numpy as np
from vasc_pipeline import _jit
from vasc_pipeline.model import rng
state = rng.seed_state(7)
value = int(rng.next_u64(state))
stats = rng.next_u64.stats
print(json.dumps({"value": value, "hits": sum(stats.cache_hits.values()), "misses": sum(stats.cache_misses.values()),
                  "dir": str(_jit.kernel_cache_dir()), "module": rng.__file__}))
"""


def _copy(tmp_path, name):
    shutil.copytree(
        REPO / "vasc_pipeline", tmp_path / name / "vasc_pipeline", ignore=shutil.ignore_patterns("__pycache__")
    )
    return tmp_path / name


def _run(root, cache_home) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env.update(PYTHONPATH=str(root), XDG_CACHE_HOME=str(cache_home))
    out = subprocess.run(
        [sys.executable, "-c", _SCRIPT], env=env, cwd=root, capture_output=True, text=True, timeout=300
    )
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert result["module"].startswith(str(root)), result  # the copy under test was imported
    return result


@pytest.mark.skipif(sys.platform != "linux", reason="XDG_CACHE_HOME places the user cache on Linux")
def test_two_copies_of_the_package_share_the_compiled_kernels(tmp_path):
    cache_home = tmp_path / "cache"
    first = _run(_copy(tmp_path, "clone"), cache_home)
    assert first["misses"] == 1 and first["hits"] == 0  # compiled, into the shared cache
    assert first["dir"].startswith(str(cache_home / "vasc_pipeline" / "numba-"))
    assert any((cache_home / "vasc_pipeline").rglob("rng.next_u64-*.nbi"))

    second = _run(_copy(tmp_path, "site-packages"), cache_home)
    assert second == {**first, "hits": 1, "misses": 0, "module": second["module"]}

    edited = _copy(tmp_path, "edited")
    with open(edited / "vasc_pipeline" / "kernel" / "moves.py", "a") as f:
        f.write("\n# an edit of another kernel module\n")
    third = _run(edited, cache_home)
    assert third["dir"] != first["dir"]
    assert third["misses"] == 1 and third["value"] == first["value"]
