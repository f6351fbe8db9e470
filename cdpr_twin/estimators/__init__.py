"""The six moving-platform pose estimators of the paper (§III), and those beyond it, by name.

>>> from cdpr_twin.plugins import make_estimator
>>> est = make_estimator("model_elastic_pulley", geometry)
>>> est.reset(T_base_platform0)
>>> estimate = est.update(measurement)

The registry (:mod:`cdpr_twin.plugins`) lists the built-in estimators as data and imports each
module when the estimator is first asked for; more are registered from outside the package (a
scenario file's ``plugins`` list, or an installed package's entry point).
"""

PAPER_ESTIMATORS = (
    "control",
    "image",
    "model_simple",
    "model_elastic",
    "model_pulley",
    "model_elastic_pulley",
)
"""The paper's six estimators, in its order (Est. 1 … Est. 6)."""
EXTRA_ESTIMATORS = ("fused",)
"""Estimators beyond the paper that a paper scenario runs: Est. 7, the fused filter."""
