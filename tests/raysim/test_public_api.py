"""The package's public functions stay callable however often they are reached.

``raysim.simulate`` is both the public function and a submodule's name: importing the
submodule (as any user code, a test or Sphinx's autodoc does) binds the module to the package
attribute, and a second ``raysim.simulate(scene)`` used to fail with "'module' object is not
callable" (found by the documentation build's tutorials).
"""

from __future__ import annotations

import subprocess
import sys

from tests.cli import ROOT, cli_env

SCRIPT = """
import raysim
scene = raysim.load_scene("paper_go").with_overrides(n_theta=6, n_phi=12)
first = raysim.simulate(scene, method="go")          # imports raysim.simulate
import raysim.simulate as module                     # the submodule is still reachable
second = raysim.simulate(scene, method="go")         # the package attribute is now the module
assert callable(module.simulate) and module.BLOCK_ENGINES
assert (first["intensity"].values == second["intensity"].values).all()
print("ok", first["intensity"].shape)
"""


def test_simulate_is_callable_twice_in_a_fresh_interpreter():
    done = subprocess.run([sys.executable, "-c", SCRIPT], cwd=ROOT, env=cli_env(),
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "ok (6, 12)"


def test_simulate_given_a_path_instead_of_a_scene_says_what_it_takes():
    """raysim.simulate("scene.toml") failed with an AttributeError deep in the mesh code."""
    import pytest

    import raysim
    from raysim.errors import SceneError

    for not_a_scene in ("paper_go", None):
        with pytest.raises(SceneError, match=r"simulate takes a Scene \(raysim.load_scene"):
            raysim.simulate(not_a_scene)
