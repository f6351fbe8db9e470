"""The Rerun viewer's default layout of a run's recording (sent with ``recording.rrd``)."""

from __future__ import annotations


def default_blueprint():
    """The default layout: 3D scene, camera image, deviations and tensions over time."""
    import rerun.blueprint as rrb

    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(origin="world", name="ACROBOT"),
            rrb.Vertical(
                rrb.Spatial2DView(origin="world/platform/cam", name="onboard camera"),
                rrb.TimeSeriesView(origin="deviation", name="estimate − truth"),
                rrb.TimeSeriesView(origin="tension", name="tensions [N]"),
            ),
            column_shares=[3, 2],
        ),
        collapse_panels=True,
    )
