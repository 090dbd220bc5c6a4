"""Metrics, prediction modes and data diagnostics shared by every model."""
