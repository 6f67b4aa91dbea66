"""Offline simulation experiments driving the learning core."""
