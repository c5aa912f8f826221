"""Airframe description: the TOML loader and the shipped DS-1 reference airframe."""
