"""Scenario files shipped with cdpr-twin (installed as cdpr_twin.scenarios)."""
