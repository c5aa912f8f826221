"""Test doubles and drivers used by the tests and benchmarks only (never installed)."""
