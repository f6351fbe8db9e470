"""The README's Python examples run as written (a reader pastes them first).

Before: the ``Twin`` example used ``cable_rates`` and ``twist`` without defining them
(``NameError``). Each ```python block runs in a fresh namespace; the Twin example's motion is
then checked against physics: 1 cm/s along the platform's x for 0.04 s moves it ≈ 0.4 mm.
"""

import re
from pathlib import Path

import numpy as np
import pytest

README = (Path(__file__).resolve().parent.parent / "README.md").read_text(encoding="utf-8")
BLOCKS = re.findall(r"^```python\n(.*?)^```", README, flags=re.S | re.M)


def test_the_readme_has_its_examples():
    assert len(BLOCKS) >= 2


@pytest.mark.parametrize("index", range(len(BLOCKS)))
def test_a_readme_example_runs_as_written(index, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    exec(compile(BLOCKS[index], f"README.md python block {index + 1}", "exec"), namespace)
    if "truth" in namespace:  # the Twin example: the measurement and the truth agree
        m, truth, start = (
            namespace["m"],
            namespace["truth"],
            namespace["se3"].pose_from_vector([0.112, -0.032, 0.301, -12, -10, 0]),
        )
        moved = truth[:3, 3] - start[:3, 3]
        along_x = start[:3, :3] @ np.array([1.0, 0.0, 0.0])  # the platform's x in F_b
        # 0.4 mm commanded; measured 0.389 mm along x, 1.5 µm across (the deviations' exit
        # points and the cables' stretch make the nominal Jacobian a little off)
        assert 0.35e-3 < moved @ along_x < 0.41e-3
        assert np.linalg.norm(moved) < 1.01 * (moved @ along_x)
        assert m.tag is not None and not hasattr(m, "T_base_platform")
    if "env" in namespace:
        namespace["env"].close()
