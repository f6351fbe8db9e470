"""Robot models shipped with cdpr-twin, one directory per robot (installed as cdpr_twin.models)."""
