"""Scenario files: key schema and reference, key parsing, spec, TOML loading, the controller factory,
validation."""
