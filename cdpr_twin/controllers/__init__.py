"""Controllers at the control rate, chosen by name: ``open_loop`` (§IV-B) and ``pbvs`` (§IV-C).

The registry (:mod:`cdpr_twin.plugins`), shared with the estimators, lists them as data and
imports each module when the controller is first asked for
(:func:`cdpr_twin.plugins.make_controller`).
"""
