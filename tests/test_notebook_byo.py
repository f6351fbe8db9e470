"""`notebooks/bring_your_own_estimator.ipynb` executes: its estimator, written and registered in
the notebook, runs beside the paper's six on the open-loop scenario and is plotted.

The notebook runs the scenario for 5 s here (``CDPR_TWIN_DURATION``; the paper's 25 s by
default) with the camera, so that its estimator's input (``image``) runs too.
"""

from pathlib import Path

import numpy as np
import pytest

from cdpr_twin.estimators import PAPER_ESTIMATORS
from cdpr_twin.recording.timeseries import Timeseries

ROOT = Path(__file__).resolve().parent.parent
NOTEBOOK = ROOT / "notebooks" / "bring_your_own_estimator.ipynb"


@pytest.mark.slow
def test_the_bring_your_own_estimator_notebook_executes(tmp_path, monkeypatch):
    import nbformat
    from nbclient import NotebookClient

    nb = nbformat.read(NOTEBOOK, as_version=4)
    assert all(not c.get("outputs") for c in nb.cells if c.cell_type == "code")  # committed bare
    monkeypatch.setenv("CDPR_TWIN_DURATION", "5")
    monkeypatch.setenv("CDPR_TWIN_OUT", str(tmp_path / "run"))
    NotebookClient(
        nb,
        timeout=600,
        kernel_name="python3",
        resources={"metadata": {"path": str(NOTEBOOK.parent)}},
    ).execute()
    outputs = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])]
    assert not [o for o in outputs if o["output_type"] == "error"]
    assert len([o for o in outputs if "image/png" in o.get("data", {})]) == 1  # the plot
    tables = [o["data"]["text/markdown"] for o in outputs if "text/markdown" in o.get("data", {})]
    assert len(tables) == 1 and "**complementary**" in tables[0]
    ts = Timeseries.load(tmp_path / "run" / "timeseries.csv")
    names = ts.estimator_names  # the scenario's (the paper's six, and more) and the notebook's
    assert names[-1] == "complementary" and set(PAPER_ESTIMATORS) <= set(names)
    assert ts.t[-1] == pytest.approx(5.0)
    # it predicts with the command and corrects toward the image: smoother than the image
    steps = {n: np.abs(np.diff(ts.deviation(n)[0])).mean() for n in ("image", "complementary")}
    assert steps["complementary"] < 0.5 * steps["image"], steps
    for name in ts.estimator_names:
        assert f"| {name} |" in tables[0] or name == "complementary"
