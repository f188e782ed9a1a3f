"""Workflows that drive a device and keep the database in step with it (move, traverse, demo)."""
