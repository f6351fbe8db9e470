"""Scenario files (TOML) → a frozen, validated Scenario, and its checks before a run."""
