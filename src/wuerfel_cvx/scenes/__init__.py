"""Scenes: the bodies and the table, read from TOML, built in, or generated."""
