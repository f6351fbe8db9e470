"""Compatibility module: the study lives in :mod:`cdpr_twin.study`.

``from cdpr_twin.reproduce import reproduce, analyse, make_figures`` keeps working.
"""

from cdpr_twin.study import (
    FINDINGS,
    Finding,
    RunSpec,
    Scenarios,
    accuracy_at_p1,
    analyse,
    evaluate,
    make_figures,
    plan,
    reproduce,
    run_study,
    write_report,
)

__all__ = [
    "FINDINGS",
    "Finding",
    "RunSpec",
    "Scenarios",
    "accuracy_at_p1",
    "analyse",
    "evaluate",
    "make_figures",
    "plan",
    "reproduce",
    "run_study",
    "write_report",
]
