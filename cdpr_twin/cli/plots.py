"""Whether the figures' library is installed: ``matplotlib`` comes with the ``plots`` extra.

A plain install runs scenarios and campaigns without it (a campaign's report then says where a
figure would be); ``reproduce`` and ``model workspace``, whose output is figures, refuse to
start without it, in one line saying what to install.
"""

from __future__ import annotations


def missing_plots(command: str) -> str | None:
    """The one-line error of a command that draws figures when matplotlib is not installed."""
    import importlib.util

    if importlib.util.find_spec("matplotlib") is not None:
        return None
    return (
        f"cdpr-twin {command}: error: its figures need matplotlib, which a plain install leaves "
        "out; install it with: pip install 'cdpr-twin[plots]'"
    )
