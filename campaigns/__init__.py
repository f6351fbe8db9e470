"""Campaign files shipped with cdpr-twin (installed as cdpr_twin.campaigns)."""
