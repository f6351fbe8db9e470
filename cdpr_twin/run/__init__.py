"""A run: the control loop, its metrics, its summary, and stops (Ctrl-C, SIGTERM).

``from cdpr_twin import run`` gives this package, and the package can be called as
:func:`cdpr_twin.run.runner.run` is: ``run(scenario, out_dir=…)``. A package and a function
cannot share the name ``cdpr_twin.run`` otherwise — the import system sets the parent's attribute
to the package whenever one of its modules is imported first — so the package answers the call
itself, and ``cdpr_twin.run.runner`` and the other modules stay reachable by attribute.
"""

import sys
import types
from typing import Any


class _CallablePackage(types.ModuleType):
    """This package's type: a module that runs a scenario when called."""

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        """Run a scenario: :func:`cdpr_twin.run.runner.run`, same arguments and result."""
        from cdpr_twin.run.runner import run

        return run(*args, **kwargs)


sys.modules[__name__].__class__ = _CallablePackage
