"""The Rerun viewer's default layout of a run's recording (sent with ``recording.rrd``)."""

from __future__ import annotations

from pathlib import Path

PALETTE = (
    (31, 119, 180),
    (255, 127, 14),
    (44, 160, 44),
    (214, 39, 40),
    (148, 103, 189),
    (140, 86, 75),
    (227, 119, 194),
    (127, 127, 127),
    (188, 189, 34),
    (23, 190, 207),
)
"""Series colours (RGB), one per estimator in recording order (matplotlib's tab10): each
estimator keeps its colour in both deviation plots, so one legend reads both."""


def robot_label(model_file: Path | None) -> str:
    """A robot's name from its MJCF scene: ``models/acrobot/scene.xml`` → ``ACROBOT``."""
    if model_file is None:
        return "robot"
    return (model_file.parent.name if model_file.stem == "scene" else model_file.stem).upper()


def series_colors(n: int) -> list[tuple[int, int, int]]:
    """``n`` series colours (RGB 0-255), distinct up to 10 and cycling after."""
    return [PALETTE[i % len(PALETTE)] for i in range(n)]


def default_blueprint(robot: str = "robot"):
    """The default layout: 3D scene, camera image, deviations and tensions over time.

    Args:
        robot: the 3D view's title (the robot's name).
    """
    import rerun.blueprint as rrb

    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(origin="world", name=robot),
            rrb.Vertical(
                rrb.Spatial2DView(origin="world/platform/cam", name="onboard camera"),
                rrb.TimeSeriesView(
                    origin="deviation/translation_mm", name="estimate − truth: position [mm]"
                ),
                rrb.TimeSeriesView(
                    origin="deviation/rotation_deg", name="estimate − truth: rotation [°]"
                ),
                rrb.TimeSeriesView(origin="tension", name="tensions [N]"),
                row_shares=[3, 2, 2, 2],
            ),
            column_shares=[3, 2],
        ),
        collapse_panels=True,
    )
