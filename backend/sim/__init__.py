"""Simulation adapter: the only code that imports mujoco or viser."""
