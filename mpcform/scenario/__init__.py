"""Scenario files: key schema, spec, TOML loading, the controller factory, validation."""
